"""The executor: BehaviorTree.CPP v4 tick semantics, a blackboard, clocks and leaves."""

"""btlog: record every moment of a behavior tree's run, and explain any of them.

An executor with BehaviorTree.CPP v4 semantics emits every status change, blackboard
write and tree mutation as an event; a recorder appends them to an MCAP file (the event
store); a read model in DuckDB replays them so that the state at any past moment can be
rebuilt and explained with the algorithms of Han et al. (THRI 2020).
"""

__version__ = "0.1.0"
SCHEMA_VERSION = "1"

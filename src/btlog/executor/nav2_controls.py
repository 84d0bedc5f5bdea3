"""Nav2's control nodes (``nav2_behavior_tree/plugins/control``), each with Nav2's policy.

Nav2 builds on BehaviorTree.CPP v4, so ``halt`` here is BT.CPP's ``ControlNode::halt``:
halt and reset every child, then reset the node itself (reported as →IDLE). Several Nav2
nodes call it from inside their own tick before returning a result, which is why Nav2's
logs show a RecoveryNode going RUNNING→IDLE→SUCCESS within one tick; btlog reproduces it.

What Nav2 takes from ROS (service calls) is read from the blackboard, as documented on
each class.
"""

from __future__ import annotations

from typing import Any

from btlog.executor.behavior import Behavior, ControlBehavior, NodeExecutionError
from btlog.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, Status
from btlog.tree.ports import convert


def _invalid(node: Behavior, child: Behavior, result: Status) -> NodeExecutionError:
    return NodeExecutionError(
        node.node, f"child {child.node.description!r} returned {result.name}, invalid here"
    )


class RecoveryNode(ControlBehavior):
    """Two children: an action and its recovery. The action's SUCCESS succeeds; its FAILURE
    ticks the recovery (at most ``number_of_retries`` times per run), whose SUCCESS retries
    the action in the same tick; a failed recovery fails, a skipped recovery fails without
    counting, a skipped action skips. Every completion halts the node (→IDLE) first."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.retries = 0

    def tick(self) -> Status:
        limit = self.get_input("number_of_retries", "int")
        if len(self.children) != 2:
            raise NodeExecutionError(self.node, "a RecoveryNode must have exactly 2 children")
        self.set_status(RUNNING)
        while self.current < 2 and self.retries <= limit:
            child = self.children[self.current]
            result = child.execute_tick()
            if self.current == 0:
                if result is RUNNING:
                    return RUNNING
                if result is SKIPPED:
                    self.halt()
                    return SKIPPED
                if result is SUCCESS:
                    self.halt_child(1)
                    self.halt()
                    return SUCCESS
                if result is not FAILURE:
                    raise _invalid(self, child, result)
                if self.retries >= limit:
                    self.halt()
                    return FAILURE
                self.halt_child(0)
                self.current = 1
            else:
                if result is RUNNING:
                    return RUNNING
                if result is SKIPPED:
                    self.current = 0
                    self.halt_child(1)
                    return FAILURE
                if result is FAILURE:
                    self.halt()
                    return FAILURE
                if result is not SUCCESS:
                    raise _invalid(self, child, result)
                self.halt_child(1)
                self.retries += 1
                self.current = 0
        self.halt()
        return FAILURE

    def halt(self) -> None:
        super().halt()
        self.retries = 0
        self.current = 0


class PipelineSequence(ControlBehavior):
    """Every tick from the first child: earlier children that are RUNNING keep running
    while later ones are ticked; the tick stops at the furthest RUNNING child reached so
    far. FAILURE halts all and fails; all done halts all and succeeds (SKIPPED if every
    child skipped). It does not set RUNNING before ticking its children."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.last_ticked = 0

    def tick(self) -> Status:
        skipped = 0
        for index, child in enumerate(self.children):
            result = child.execute_tick()
            if result is FAILURE:
                self.reset_children()
                self.last_ticked = 0
                return FAILURE
            if result is SKIPPED:
                skipped += 1
            elif result is RUNNING:
                if index >= self.last_ticked:
                    self.last_ticked = index
                    return RUNNING
            elif result is not SUCCESS:
                raise _invalid(self, child, result)
        self.reset_children()
        self.last_ticked = 0
        return SKIPPED if skipped == len(self.children) else SUCCESS

    def halt(self) -> None:
        super().halt()
        self.last_ticked = 0


class RoundRobin(ControlBehavior):
    """Tick the children in turn, resuming at the one after the last completed child: the
    first SUCCESS halts all and succeeds; FAILURE and SKIPPED move on. With
    ``wrap_around`` the turn wraps to the first child until every child has failed since
    the last success; without it the node stops at the last child and returns FAILURE
    (SKIPPED if all skipped) - even when that last child succeeded, as Nav2 does."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.wrap_around = bool(self.get_input("wrap_around", "bool"))
        self.current = 0
        self.failed = 0

    def tick(self) -> Status:
        count = len(self.children)
        self.set_status(RUNNING)
        skipped = 0
        while self.failed + skipped < count:
            child = self.children[self.current]
            result = child.execute_tick()
            if result is IDLE:
                raise _invalid(self, child, result)
            if result is not RUNNING:
                self.current += 1
                if self.current == count:
                    if self.wrap_around:
                        self.current = 0
                    else:
                        if result is SKIPPED:
                            skipped += 1
                        elif result is FAILURE:
                            self.failed += 1
                        break
            if result is SUCCESS:
                self.failed = 0
                self.reset_children()
                return SUCCESS
            if result is FAILURE:
                self.failed += 1
            elif result is SKIPPED:
                skipped += 1
            else:
                return RUNNING
        all_skipped = skipped == count
        self.halt()
        return SKIPPED if all_skipped else FAILURE

    def halt(self) -> None:
        super().halt()
        self.current = 0
        self.failed = 0


class NonblockingSequence(ControlBehavior):
    """Every tick, tick every child (RUNNING ones included) in order: a FAILURE halts all
    and fails at once; all SUCCESS in the same tick halts all and succeeds; otherwise
    RUNNING. A SKIPPED child is an error, as in Nav2."""

    def tick(self) -> Status:
        all_success = True
        for child in self.children:
            result = child.execute_tick()
            if result is FAILURE:
                self.reset_children()
                return FAILURE
            if result is RUNNING:
                all_success = False
            elif result is not SUCCESS:
                raise _invalid(self, child, result)
        if all_success:
            self.reset_children()
            return SUCCESS
        return RUNNING


class PersistentSequence(ControlBehavior):
    """A sequence whose position lives on the blackboard (the ``current_child_idx`` port,
    read every tick and written after each step), so it survives halts and re-creations.
    FAILURE resets the children and the index to 0; SUCCESS and SKIPPED move on."""

    def tick(self) -> Status:
        count = len(self.children)
        try:
            index = self.get_input("current_child_idx", "int")
        except NodeExecutionError as error:
            raise NodeExecutionError(self.node, f"missing current_child_idx ({error})") from None
        self.set_status(RUNNING)
        while index < count:
            result = self.children[index].execute_tick()
            if result is RUNNING:
                return RUNNING
            if result is FAILURE:
                self.reset_children()
                self.set_output("current_child_idx", 0)
                return FAILURE
            if result is IDLE:
                raise _invalid(self, self.children[index], result)
            index += 1
            self.set_output("current_child_idx", index)
        self.reset_children()
        self.set_output("current_child_idx", 0)
        return SUCCESS


RESUMED, PAUSED, PAUSE_REQUESTED, ON_PAUSE, RESUME_REQUESTED, ON_RESUME = (
    "RESUMED",
    "PAUSED",
    "PAUSE_REQUESTED",
    "ON_PAUSE",
    "RESUME_REQUESTED",
    "ON_RESUME",
)
_CHILD_OF_STATE = {RESUMED: 0, PAUSED: 1, ON_PAUSE: 2, ON_RESUME: 3}
_NEXT_STATE = {PAUSE_REQUESTED: ON_PAUSE, ON_PAUSE: PAUSED, RESUME_REQUESTED: ON_RESUME}
_NEXT_STATE[ON_RESUME] = RESUMED


class PauseResumeController(ControlBehavior):
    """Children: RESUMED (required), then optional PAUSED, ON_PAUSE and ON_RESUME. Ticks the
    child of its state; a pause request (when not PAUSED) resets the children and runs
    ON_PAUSE until it succeeds, then PAUSED; a resume request (when PAUSED) runs ON_RESUME,
    then RESUMED. Only the RESUMED child's SUCCESS succeeds; any FAILURE fails.

    Nav2 receives the requests as service calls; btlog reads them from the blackboard: an
    entry named by ``pause_service_name`` (or ``resume_service_name``) set to true is one
    call, consumed (set back to false) when the controller reads it."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.state = RESUMED

    def _requested(self, port: str) -> bool:
        if not self.has_port(port):
            return False
        key = str(self.get_input(port))
        if not key or not self.blackboard.exists(key):
            return False
        if not convert(self.blackboard.get(key), "bool"):
            return False
        self.blackboard.set(key, False)
        return True

    def _advance(self) -> None:
        self.state = _NEXT_STATE.get(self.state, self.state)

    def tick(self) -> Status:
        if not 1 <= len(self.children) <= 4:
            raise NodeExecutionError(self.node, "needs one to four children")
        if self.status is IDLE:
            self.state = RESUMED
        self.set_status(RUNNING)
        if self._requested("pause_service_name") and self.state != PAUSED:
            self.state = PAUSE_REQUESTED
        if self._requested("resume_service_name") and self.state == PAUSED:
            self.state = RESUME_REQUESTED
        if self.state in (PAUSE_REQUESTED, RESUME_REQUESTED):
            self.reset_children()
            self._advance()
        index = _CHILD_OF_STATE[self.state]
        if index >= len(self.children):
            self._advance()
            return RUNNING
        result = self.children[index].execute_tick()
        if result is RUNNING:
            return RUNNING
        if result is SUCCESS or result is SKIPPED:
            if self.state == RESUMED:
                return SUCCESS
            self._advance()
            return RUNNING
        if result is FAILURE:
            return FAILURE
        raise _invalid(self, self.children[index], result)

    def halt(self) -> None:
        self.state = RESUMED
        super().halt()


NAV2_CONTROLS: dict[str, type[Behavior]] = {
    "RecoveryNode": RecoveryNode,
    "PipelineSequence": PipelineSequence,
    "RoundRobin": RoundRobin,
    "NonblockingSequence": NonblockingSequence,
    "PersistentSequence": PersistentSequence,
    "PauseResumeController": PauseResumeController,
}

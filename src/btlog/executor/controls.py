"""Control nodes, each with BehaviorTree.CPP v4's exact policy.

A control node routes the tick to its children and decides from their results. The
differences that matter to a log: whether the node remembers where it was (Sequence
resumes at the running child; ReactiveSequence starts from the first child every tick
and halts the others), when it resets its children (on completion, all of them, before
its own result is stored), and what it does with SKIPPED children.

The ``wake_up`` flag of the runtime is BT.CPP's wake-up signal: a node that sets it
returns RUNNING early and the executor ticks the root again within the same tick.
"""

from __future__ import annotations

import re
from typing import Any

from btlog.executor.behavior import Behavior, ControlBehavior, NodeExecutionError
from btlog.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, Status


class _InOrder(ControlBehavior):
    """Shared policy of Sequence and Fallback: tick children in order from where it left
    off; the ``decisive`` result resets every child and is returned; the other completed
    result (or SKIPPED) moves to the next child; when all are done, reset and return
    ``exhausted`` (SKIPPED if every child skipped)."""

    decisive: Status
    exhausted: Status
    #: whether ``_wakes_up`` may end a tick early (skips the call per child when not)
    may_wake_up = False

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.index = 0
        self.skipped = 0
        # the policy copied to the instance: CPython 3.11 looks a class attribute up
        # through the whole MRO on every read, an instance attribute at once (hot path)
        self._policy = (self.decisive, self.may_wake_up)

    def tick(self) -> Status:
        if self.status is IDLE:
            self.skipped = 0
        self.set_status(RUNNING)
        children, (decisive, may_wake_up) = self.children, self._policy
        # the index is a local while the children tick (the hot path), stored back before
        # returning or calling what reads it; children change only between ticks
        index, count = self.index, len(children)
        while index < count:
            child = children[index]
            before = child.status
            result = child.execute_tick()
            if result is RUNNING:
                self.index = index
                return RUNNING
            if result is decisive:
                self.index = index
                self._decided()
                return result
            index += 1
            if result is SKIPPED:
                self.skipped += 1
            elif may_wake_up:
                self.index = index
                if self._wakes_up(before):
                    return RUNNING
        return self._finish()

    def _decided(self) -> None:
        """The decisive result: every child is reset and the next tick starts over."""
        self.reset_children()
        self.index = 0

    def _wakes_up(self, before: Status) -> bool:
        """Whether a child that just completed (not decisively) ends this tick early: BT.CPP's
        asynchronous controls signal a wake-up when it went from IDLE to done in this very
        tick and more children remain (called only when ``may_wake_up``)."""
        return self.wake_up_early(before, self.index < len(self.children))

    def _finish(self) -> Status:
        all_skipped = self.skipped == len(self.children)
        self.reset_children()
        self.index = 0
        self.skipped = 0
        return SKIPPED if all_skipped else self.exhausted

    def halt(self) -> None:
        self.index = 0
        self.skipped = 0
        super().halt()

    def insert_child(self, index: int, child: Behavior) -> None:
        """Insert a child; the resume index moves with the child it points at."""
        super().insert_child(index, child)
        if index <= self.index and self.status is RUNNING and index < len(self.children) - 1:
            self.index += 1


class Sequence(_InOrder):
    """Tick children in order from where it left off; FAILURE resets everything and fails;
    all done (SUCCESS or SKIPPED) resets and succeeds (SKIPPED if every child skipped)."""

    decisive = FAILURE
    exhausted = SUCCESS


class SequenceWithMemory(Sequence):
    """Like Sequence, but a FAILURE halts only the children from the failed one on and keeps
    the index, so the next tick retries the failed child; halting keeps the index too.
    A child succeeding from IDLE with more to go signals a wake-up and returns RUNNING."""

    may_wake_up = True

    def _decided(self) -> None:
        for i in range(self.index, len(self.children)):
            self.halt_child(i)

    def halt(self) -> None:
        ControlBehavior.halt(self)


class AsyncSequence(Sequence):
    """A Sequence that yields between children: a child succeeding from IDLE with more to
    go signals a wake-up and returns RUNNING, so the executor ticks the root again at once
    and a reactive parent can interrupt it (BT.CPP's ``SequenceNode(make_async=true)``)."""

    may_wake_up = True


class Fallback(_InOrder):
    """Tick children in order from where it left off; SUCCESS resets everything and
    succeeds; all failed (or skipped) resets and fails (SKIPPED if every child skipped)."""

    decisive = SUCCESS
    exhausted = FAILURE


class AsyncFallback(Fallback):
    """A Fallback that yields between children: a child failing from IDLE with more to go
    signals a wake-up and returns RUNNING (BT.CPP's ``FallbackNode(make_async=true)``)."""

    may_wake_up = True


class TryCatch(ControlBehavior):
    """Children but the last run as a Sequence (the *try* block); when one fails, every
    child is reset and the last child (the *catch*) runs to completion, after which the
    node fails whatever the catch returned. SKIPPED try children count as done (all
    skipped: SKIPPED). With ``catch_on_halt`` true, halting the node while the try block
    runs ticks the catch once (halting it if it is still RUNNING). BT.CPP 4.9."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.index = 0
        self.skipped = 0
        self.in_catch = False

    def tick(self) -> Status:
        children = self.children
        tries = len(children) - 1
        if self.status is IDLE:
            self.skipped = 0
            self.in_catch = False
        self.set_status(RUNNING)
        while not self.in_catch and self.index < tries:
            result = children[self.index].execute_tick()
            if result is RUNNING:
                return RUNNING
            if result is FAILURE:
                self.reset_children()
                self.index = 0
                self.in_catch = True
            else:
                self.index += 1
                self.skipped += result is SKIPPED
        if self.in_catch:
            if children[-1].execute_tick() is RUNNING:
                return RUNNING
            self.reset_children()
            self.index = 0
            self.in_catch = False
            return FAILURE
        all_skipped = self.skipped == tries
        self.reset_children()
        self.index = 0
        self.skipped = 0
        return SKIPPED if all_skipped else SUCCESS

    def halt(self) -> None:
        catch_on_halt = self.has_port("catch_on_halt") and self.get_input("catch_on_halt", "bool")
        if catch_on_halt and not self.in_catch and self.status is not IDLE:
            last = len(self.children) - 1
            for index in range(last):
                self.halt_child(index)
            if self.children[last].execute_tick() is RUNNING:
                self.halt_child(last)
        self.index = 0
        self.skipped = 0
        self.in_catch = False
        super().halt()


class _Reactive(ControlBehavior):
    """Shared policy of the reactive controls: every tick starts from the first child; a
    RUNNING child halts all the others; a SKIPPED child is halted."""

    #: The child result that ends the tick early (FAILURE for the sequence).
    decisive: Status
    #: The result when every child returned the other completed status.
    exhausted: Status

    def tick(self) -> Status:
        all_skipped = True
        self.set_status(RUNNING)
        children = self.children
        for index, child in enumerate(children):
            result = child.execute_tick()
            all_skipped = all_skipped and result is SKIPPED
            if result is RUNNING:
                for other in range(len(children)):
                    if other != index:
                        self.halt_child(other)
                return RUNNING
            if result is self.decisive:
                self.reset_children()
                return result
            if result is SKIPPED:
                self.halt_child(index)
        self.reset_children()
        return SKIPPED if all_skipped else self.exhausted


class ReactiveSequence(_Reactive):
    """Every tick from the first child: FAILURE resets and fails, RUNNING halts the others,
    all succeeded resets and succeeds."""

    decisive = FAILURE
    exhausted = SUCCESS


class ReactiveFallback(_Reactive):
    """Every tick from the first child: SUCCESS resets and succeeds, RUNNING halts the
    others, all failed resets and fails."""

    decisive = SUCCESS
    exhausted = FAILURE


def _threshold(value: int, children: int) -> int:
    """BT.CPP's thresholds: a negative value t means max(N + t + 1, 0)."""
    return max(children + value + 1, 0) if value < 0 else value


class Parallel(ControlBehavior):
    """Tick every child not yet completed; after each child, succeed when ``success_count``
    children succeeded, fail when ``failure_count`` failed or success became impossible
    (halting and resetting all children either way); otherwise RUNNING."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.completed: set[int] = set()
        self.successes = 0
        self.failures = 0

    def _thresholds(self) -> tuple[int, int]:
        ports = self.node.ports
        success = "success_count" if "success_threshold" not in ports else "success_threshold"
        failure = "failure_count" if "failure_threshold" not in ports else "failure_threshold"
        return self.get_input(success, "int"), self.get_input(failure, "int")

    def tick(self) -> Status:
        success_value, failure_value = self._thresholds()
        count = len(self.children)
        required_success = _threshold(success_value, count)
        required_failure = _threshold(failure_value, count)
        if count < required_success:
            raise NodeExecutionError(self.node, "fewer children than success_count")
        if count < required_failure:
            raise NodeExecutionError(self.node, "fewer children than failure_count")
        self.set_status(RUNNING)
        skipped = 0
        for index, child in enumerate(self.children):
            if index not in self.completed:
                result = child.execute_tick()
                if result is SKIPPED:
                    skipped += 1
                elif result is SUCCESS:
                    self.completed.add(index)
                    self.successes += 1
                elif result is FAILURE:
                    self.completed.add(index)
                    self.failures += 1
            if self.successes >= required_success or (
                success_value < 0 and self.successes + skipped >= required_success
            ):
                self._clear()
                self.reset_children()
                return SUCCESS
            if count - self.failures < required_success or self.failures == required_failure:
                self._clear()
                self.reset_children()
                return FAILURE
        return SKIPPED if skipped == count else RUNNING

    def _clear(self) -> None:
        self.completed.clear()
        self.successes = 0
        self.failures = 0

    def halt(self) -> None:
        self._clear()
        super().halt()


class ParallelAll(ControlBehavior):
    """Tick every child until all have completed, then halt them all and fail if at least
    ``max_failures`` failed, else succeed."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.completed: set[int] = set()
        self.failures = 0

    def tick(self) -> Status:
        count = len(self.children)
        max_failures = _threshold(self.get_input("max_failures", "int"), count)
        if count < max_failures:
            raise NodeExecutionError(self.node, "fewer children than max_failures")
        self.set_status(RUNNING)
        skipped = 0
        for index, child in enumerate(self.children):
            if index in self.completed:
                continue
            result = child.execute_tick()
            if result is SUCCESS:
                self.completed.add(index)
            elif result is FAILURE:
                self.completed.add(index)
                self.failures += 1
            elif result is SKIPPED:
                skipped += 1
        if skipped == count:
            return SKIPPED
        if skipped + len(self.completed) >= count:
            for index in range(count):
                self.halt_child(index)
            self.completed.clear()
            result = FAILURE if self.failures >= max_failures else SUCCESS
            self.failures = 0
            return result
        return RUNNING

    def halt(self) -> None:
        self.completed.clear()
        self.failures = 0
        super().halt()


class IfThenElse(ControlBehavior):
    """Tick the condition (child 0) until it completes, then the chosen branch until it
    completes; not reactive. A failed condition with no else branch fails."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.branch = 0

    def tick(self) -> Status:
        self.set_status(RUNNING)
        if self.branch == 0:
            condition = self.children[0].execute_tick()
            if condition is RUNNING:
                return RUNNING
            if condition is SUCCESS:
                self.branch = 1
            elif condition is FAILURE:
                if len(self.children) == 3:
                    self.branch = 2
                else:
                    return FAILURE
        if self.branch > 0:
            result = self.children[self.branch].execute_tick()
            if result is RUNNING:
                return RUNNING
            self.reset_children()
            self.branch = 0
            return result
        raise NodeExecutionError(self.node, "the condition was skipped")

    def halt(self) -> None:
        self.branch = 0
        super().halt()


class WhileDoElse(ControlBehavior):
    """Reactive: every tick the condition; SUCCESS halts the else branch and ticks the do
    branch, FAILURE halts the do branch and ticks the else branch (or fails)."""

    def tick(self) -> Status:
        self.set_status(RUNNING)
        condition = self.children[0].execute_tick()
        if condition is RUNNING:
            return RUNNING
        three = len(self.children) == 3
        result = IDLE
        if condition is SUCCESS:
            if three:
                self.halt_child(2)
            result = self.children[1].execute_tick()
        elif condition is FAILURE:
            if three:
                self.halt_child(1)
                result = self.children[2].execute_tick()
            else:
                result = FAILURE
        if result is RUNNING:
            return RUNNING
        self.reset_children()
        return result


class Switch(ControlBehavior):
    """Tick the child of the first ``case_i`` equal to ``variable`` (compared as strings,
    then integers, then reals), else the last child; a change of case halts the child
    that was running. Unlike other controls it does not set RUNNING before ticking."""

    cases = 2

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.running_child = -1

    def _match(self) -> int:
        if not self.has_port("variable"):
            return self.cases
        try:
            variable = _text(self.get_input("variable", "any"))
        except NodeExecutionError:
            return self.cases
        for index in range(self.cases):
            name = f"case_{index + 1}"
            if self.has_port(name) and _switch_equal(variable, _text(self.get_input(name, "any"))):
                return index
        return self.cases

    def tick(self) -> Status:
        if len(self.children) != self.cases + 1:
            raise NodeExecutionError(self.node, "wrong number of children")
        match = self._match()
        if self.running_child != -1 and self.running_child != match:
            self.halt_child(self.running_child)
        result = self.children[match].execute_tick()
        if result is SKIPPED:
            self.running_child = -1
            return SKIPPED
        if result is RUNNING:
            self.running_child = match
        else:
            self.reset_children()
            self.running_child = -1
        return result

    def halt(self) -> None:
        self.running_child = -1
        super().halt()


def _text(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


_INT = re.compile(r"^[-+]?\d+$")
_REAL = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?$")


def _switch_equal(a: str, b: str) -> bool:
    """BT.CPP's comparison: equal strings, else equal integers, else reals within the
    float epsilon (numbers parsed strictly, as std::from_chars does)."""
    if a == b:
        return True
    if _INT.match(a) and _INT.match(b) and int(a) == int(b):
        return True
    if _REAL.match(a) and _REAL.match(b):
        return abs(float(a) - float(b)) <= 1.1920928955078125e-07
    return False


def switch_class(cases: int) -> type[Switch]:
    """The Switch class for ``cases`` cases (Switch2 … Switch6)."""
    return type(f"Switch{cases}", (Switch,), {"cases": cases, "__doc__": Switch.__doc__})


CONTROLS: dict[str, type[Behavior]] = {
    "Sequence": Sequence,
    "AsyncSequence": AsyncSequence,
    "SequenceWithMemory": SequenceWithMemory,
    "Fallback": Fallback,
    "AsyncFallback": AsyncFallback,
    "TryCatch": TryCatch,
    "ReactiveSequence": ReactiveSequence,
    "ReactiveFallback": ReactiveFallback,
    "Parallel": Parallel,
    "ParallelAll": ParallelAll,
    "IfThenElse": IfThenElse,
    "WhileDoElse": WhileDoElse,
    **{f"Switch{n}": switch_class(n) for n in range(2, 7)},
}

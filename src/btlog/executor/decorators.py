"""Decorators (and SubTree), each with BehaviorTree.CPP v4's exact policy.

A decorator has one child and changes what its result means. BT.CPP's DecoratorNode
resets the child after every tick in which the child completed, which is why a retried
child is seen going FAILURE→IDLE before it starts again. RetryUntilSuccessful and Repeat
loop within one tick while their child completes synchronously; when the child had been
IDLE they instead signal a wake-up and return RUNNING, and the executor re-ticks the root.
"""

from __future__ import annotations

from typing import Any

from btlog.executor.behavior import Behavior, DecoratorBehavior, NodeExecutionError
from btlog.executor.blackboard import EntryWatch
from btlog.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, Status
from btlog.tree.ports import PortValueError, convert, split_queue
from btlog.tree.script import compile_script, truthy


class Inverter(DecoratorBehavior):
    """SUCCESS becomes FAILURE and FAILURE becomes SUCCESS; RUNNING and SKIPPED pass."""

    def tick(self) -> Status:
        self.set_status(RUNNING)
        result = self.child.execute_tick()
        if result is SUCCESS:
            self.reset_child()
            return FAILURE
        if result is FAILURE:
            self.reset_child()
            return SUCCESS
        return result


class ForceSuccess(DecoratorBehavior):
    """A completed child gives SUCCESS; RUNNING and SKIPPED pass."""

    forced = SUCCESS

    def tick(self) -> Status:
        self.set_status(RUNNING)
        result = self.child.execute_tick()
        if result is SUCCESS or result is FAILURE:
            self.reset_child()
            return self.forced
        return result


class ForceFailure(ForceSuccess):
    """A completed child gives FAILURE; RUNNING and SKIPPED pass."""

    forced = FAILURE


class KeepRunningUntilFailure(DecoratorBehavior):
    """SUCCESS resets the child and returns RUNNING; FAILURE fails."""

    def tick(self) -> Status:
        self.set_status(RUNNING)
        result = self.child.execute_tick()
        if result is FAILURE:
            self.reset_child()
            return FAILURE
        if result is SUCCESS:
            self.reset_child()
            return RUNNING
        if result is RUNNING:
            return RUNNING
        return self.status


class _Loop(DecoratorBehavior):
    """Shared loop of Repeat and RetryUntilSuccessful: re-tick the child within the same
    tick while it completes with ``again``, up to the port's limit (-1: no limit)."""

    limit_port: str
    again: Status

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.count = 0

    def tick(self) -> Status:
        limit = self.get_input(self.limit_port, "int")
        loop = self.count < limit or limit == -1
        self.set_status(RUNNING)
        while loop:
            child = self.child
            before = child.status
            result = child.execute_tick()
            if result is self.again:
                self.count += 1
                limit = self.get_input(self.limit_port, "int")
                loop = self.count < limit or limit == -1
                self.reset_child()
                if self.wake_up_early(before, loop):
                    return RUNNING
            elif result is RUNNING:
                return RUNNING
            elif result is SKIPPED:
                self.reset_child()
                return SKIPPED
            else:
                self.count = 0
                self.reset_child()
                return result
        self.count = 0
        return SUCCESS if self.again is SUCCESS else FAILURE

    def halt(self) -> None:
        self.count = 0
        super().halt()


class Repeat(_Loop):
    """Run the child ``num_cycles`` times (-1: forever) while it succeeds; FAILURE fails."""

    limit_port = "num_cycles"
    required_ports = ("num_cycles",)
    again = SUCCESS


class RetryUntilSuccessful(_Loop):
    """Retry the child up to ``num_attempts`` times (-1: forever) while it fails; SUCCESS
    succeeds. ``count`` is the number of failed attempts of the current run."""

    limit_port = "num_attempts"
    required_ports = ("num_attempts",)
    again = FAILURE


class RunOnce(DecoratorBehavior):
    """Tick the child until it completes once; afterwards return SKIPPED (``then_skip``)
    or the remembered result, without ticking it again. Halting does not forget."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.done: Status | None = None

    def tick(self) -> Status:
        then_skip = self.get_input("then_skip", "bool") if self.has_port("then_skip") else True
        if self.done is not None:
            return SKIPPED if then_skip else self.done
        self.set_status(RUNNING)
        result = self.child.execute_tick()
        if result is SUCCESS or result is FAILURE:
            self.done = result
            self.reset_child()
        return result


class Precondition(DecoratorBehavior):
    """While the child is not running, evaluate ``if``: false returns ``else`` (default
    FAILURE) without ticking the child. As in BT.CPP, a halt does not clear the memory that
    the child was running, so the next activation skips the ``if`` check once."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.children_running = False
        self._script = (
            compile_script(self.node.ports["if"].value) if "if" in self.node.ports else None
        )

    def tick(self) -> Status:
        otherwise = self.get_input("else", "status")
        if self._script is None:
            raise NodeExecutionError(self.node, "missing port 'if'")
        if not self.children_running:
            self.children_running = truthy(self._run_script(self._script))
        if not self.children_running:
            return otherwise
        result = self.child.execute_tick()
        if result is SUCCESS or result is FAILURE:
            self.reset_child()
            self.children_running = False
        return result


class _Timed(DecoratorBehavior):
    """A decorator with a deadline on the executor's clock, forgotten when halted."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.deadline: int | None = None

    def halt(self) -> None:
        self.deadline = None
        super().halt()


class Delay(_Timed):
    """RUNNING for ``delay_msec`` (on the executor's clock), then tick the child."""

    required_ports = ("delay_msec",)

    def tick(self) -> Status:
        clock = self.runtime.clock
        if self.deadline is None:
            self.deadline = clock.now_ns() + self.get_input("delay_msec", "unsigned") * 1_000_000
            self.set_status(RUNNING)
        if clock.now_ns() < self.deadline:
            return RUNNING
        result = self.child.execute_tick()
        if result is SUCCESS or result is FAILURE:
            self.deadline = None
            self.reset_child()
        return result


class Timeout(_Timed):
    """Tick the child; if it is still running ``msec`` after the start, halt it and fail."""

    required_ports = ("msec",)

    def tick(self) -> Status:
        clock = self.runtime.clock
        if self.deadline is None:
            msec = self.get_input("msec", "unsigned")
            # As in BT.CPP, msec 0 starts no timer: the child is never timed out.
            self.deadline = clock.now_ns() + msec * 1_000_000 if msec > 0 else -1
            self.set_status(RUNNING)
        elif self.deadline >= 0 and clock.now_ns() >= self.deadline:
            self.deadline = None
            self.reset_child()
            return FAILURE
        result = self.child.execute_tick()
        if result is not RUNNING:
            self.deadline = None
            self.reset_child()
        return result


class _QueueLoop(DecoratorBehavior):
    """LoopInt, LoopDouble, LoopString, LoopBool: each time the child is to start, pop the
    next element of ``queue`` into the output ``value`` and tick the child; the child's
    FAILURE fails, its SUCCESS returns RUNNING (the next element is popped on the next
    tick), and an empty queue returns ``if_empty`` (default SUCCESS) without ticking it.

    A literal queue is ``1;2;3`` (elements of the loop's type, as BT.CPP splits them:
    a trailing ``;`` adds nothing), converted when the node is built. A ``{key}`` queue
    is read when the node starts from IDLE: a list is copied (as BT.CPP copies a
    ``std::vector``), a string is split as a literal; the popped copy is the node's own,
    so the entry itself never changes (BT.CPP pops a ``SharedQueue`` in place, a type
    only C++ code can put on a blackboard)."""

    item_type: str

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.queue: list[Any] | None = None
        self.child_running = False
        key, raw = self._port("queue") if "queue" in self.node.ports else (None, None)
        self._static = None if raw is None or key is not None else self._split(raw)

    def _split(self, text: str) -> list[Any]:
        parts = split_queue(text)
        if self.item_type == "str":
            return parts
        try:
            return [convert(part, self.item_type) for part in parts]
        except PortValueError as error:
            raise NodeExecutionError(self.node, f"port 'queue': {error}") from None

    def _read_queue(self) -> list[Any] | None:
        key, _ = self._port("queue")
        if key is None or not self.blackboard.exists(key):
            return None
        value = self.blackboard.get(key)
        if isinstance(value, str):
            return self._split(value)
        if isinstance(value, list | tuple):
            try:
                return [convert(item, self.item_type) for item in value]
            except PortValueError as error:
                raise NodeExecutionError(self.node, f"port 'queue': {error}") from None
        raise NodeExecutionError(
            self.node, f"port 'queue': entry {key!r} holds neither a list nor a string"
        )

    def tick(self) -> Status:
        popped = False
        if self.status is IDLE:
            self.child_running = False
            self.queue = list(self._static) if self._static is not None else None
        if not self.child_running:
            if self.queue is None and self._static is None and "queue" in self.node.ports:
                self.queue = self._read_queue()
            if self.queue:
                value = self.queue.pop(0)
                popped = True
                if "value" in self.node.ports:
                    self.set_output("value", value)
        if not popped and not self.child_running:
            return self.get_input("if_empty", "status")
        if self.status is IDLE:
            self.set_status(RUNNING)
        result = self.child.execute_tick()
        self.child_running = result is RUNNING
        if result is SUCCESS or result is FAILURE:
            self.reset_child()
        return FAILURE if result is FAILURE else RUNNING

    def halt(self) -> None:
        self.child_running = False
        super().halt()


def loop_class(type_id: str, item_type: str) -> type[_QueueLoop]:
    """The Loop class of one element type (LoopInt: ``int``…)."""
    return type(type_id, (_QueueLoop,), {"item_type": item_type, "__doc__": _QueueLoop.__doc__})


LOOPS = {"LoopInt": "int", "LoopDouble": "double", "LoopString": "str", "LoopBool": "bool"}


class _EntryUpdated(DecoratorBehavior):
    """SkipUnlessUpdated and WaitValueUpdate: tick the child only when the blackboard entry
    named by ``entry`` (``{key}`` or a plain key) was written since this node last looked
    (every write counts, the same value too; a missing entry was not written); otherwise
    return ``not_updated``. A child left RUNNING is ticked on without looking."""

    not_updated: Status
    required_ports = ("entry",)

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.child_running = False
        self.watch = EntryWatch(self.node.ports["entry"].value if self.has_port("entry") else "")

    def tick(self) -> Status:
        if not self.child_running and not self.watch.updated(self.blackboard):
            return self.not_updated
        result = self.child.execute_tick()
        self.child_running = result is RUNNING
        return result

    def halt(self) -> None:
        self.child_running = False
        super().halt()


class SkipUnlessUpdated(_EntryUpdated):
    """Tick the child when ``entry`` was updated since the last look, else SKIPPED."""

    not_updated = SKIPPED


class WaitValueUpdate(_EntryUpdated):
    """Tick the child when ``entry`` was updated since the last look, else RUNNING."""

    not_updated = RUNNING


class PassThrough(DecoratorBehavior):
    """A decorator btlog has no code for (declared by a nodes model or a
    ``<Decorator ID=…>`` tag, its code a plugin): ticks its child, whose result is its own
    (SKIPPED included); a completed child is reset as every decorator resets it."""

    def tick(self) -> Status:
        self.set_status(RUNNING)
        return self.child.execute_tick()


class SubTree(DecoratorBehavior):
    """Tick the subtree's root; RUNNING is set only when starting from IDLE, and the
    SubTree node keeps its result until its parent resets it."""

    def tick(self) -> Status:
        if self.status is IDLE:
            self.set_status(RUNNING)
        result = self.child.execute_tick()
        if result is SUCCESS or result is FAILURE:
            self.reset_child()
        return result


DECORATORS: dict[str, type[Behavior]] = {
    "Inverter": Inverter,
    "ForceSuccess": ForceSuccess,
    "ForceFailure": ForceFailure,
    "KeepRunningUntilFailure": KeepRunningUntilFailure,
    "Repeat": Repeat,
    "RetryUntilSuccessful": RetryUntilSuccessful,
    "RunOnce": RunOnce,
    "Precondition": Precondition,
    "Delay": Delay,
    "Timeout": Timeout,
    "SubTree": SubTree,
    "SkipUnlessUpdated": SkipUnlessUpdated,
    "WaitValueUpdate": WaitValueUpdate,
    **{type_id: loop_class(type_id, item) for type_id, item in LOOPS.items()},
}

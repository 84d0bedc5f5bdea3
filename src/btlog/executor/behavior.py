"""The run-time side of a node: its status, its tick, its halt.

``Behavior`` is BT.CPP's ``TreeNode``: ``execute_tick`` checks the pre-conditions
(``_failureIf``, ``_successIf``, ``_skipIf`` while IDLE; ``_while`` also while RUNNING),
calls the node's own ``tick``, runs the post-conditions on completion and stores the
result, except SKIPPED, which is returned to the parent but never stored. ``set_status``
and ``reset_status`` (the only way back to IDLE) report each real change to the
executor's event feed. Halting follows BT.CPP: a parent halts a RUNNING child and then
resets it, so loggers see RUNNING→IDLE (or SUCCESS/FAILURE→IDLE).

Each node type is one subclass, in ``controls``, ``decorators`` and ``actions``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

from btlog.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, Status
from btlog.tree.model import Node, blackboard_key
from btlog.tree.ports import PortValueError, convert
from btlog.tree.script import MissingVariable, ScriptError, compile_script, truthy

if TYPE_CHECKING:
    from btlog.executor.blackboard import Blackboard
    from btlog.executor.clock import SimClock, WallClock


#: What a missing blackboard entry may be, and how a simulation provides it.
HOST_ENTRY_HINT = (
    "no node wrote it; if the program running the tree sets it, give it under "
    "'blackboard:' in an outcomes file"
)


class Runtime:
    """What every behaviour of one executor shares: the clock, the event feed, the tick.

    ``seq`` numbers the run's events. ``emit_status`` reports a status change (None when
    nobody listens). ``append_row``, set only when the sole subscriber takes status
    changes in batches (``Subscriber.takes_status_batches``), adds a change to the
    executor's batch: the nodes' hottest paths add their own ``changes[prev][new]``
    (``btlog.events.change_rows``), one call less per event than ``emit_status``, and
    leave numbering and timing to the executor, which hands the batch over
    (``Executor.settle``) before ``seq`` or ``tick`` is read or changed.
    """

    __slots__ = ("append_row", "clock", "emit_status", "seq", "tick", "wake_up")

    def __init__(self, clock: SimClock | WallClock) -> None:
        self.clock = clock
        self.tick = 0
        self.seq = 0
        self.wake_up = False
        self.emit_status: Callable[[int, Status, Status], None] | None = None
        self.append_row: Callable[[bytes], None] | None = None


class NodeExecutionError(RuntimeError):
    """A node failed to run (bad port value, script error, an exception in a leaf)."""

    def __init__(self, node: Node, message: str) -> None:
        self.node = node
        where = f"{node.file}:{node.line}: " if node.file else ""
        super().__init__(f"{where}node {node.description!r} (uid {node.uid}): {message}")


class _Conditions:
    """The compiled pre/post-condition scripts of one node."""

    __slots__ = (
        "failure_if",
        "on_failure",
        "on_halted",
        "on_success",
        "post",
        "skip_if",
        "success_if",
        "while_",
    )

    def __init__(self, attributes: dict[str, str]) -> None:
        def compiled(name: str) -> Callable | None:
            code = attributes.get(name)
            return compile_script(code) if code else None

        self.failure_if = compiled("_failureIf")
        self.success_if = compiled("_successIf")
        self.skip_if = compiled("_skipIf")
        self.while_ = compiled("_while")
        self.on_success = compiled("_onSuccess")
        self.on_failure = compiled("_onFailure")
        self.post = compiled("_post")
        self.on_halted = compiled("_onHalted")


_CONDITION_ATTRIBUTES = (
    "_failureIf",
    "_successIf",
    "_skipIf",
    "_while",
    "_onSuccess",
    "_onFailure",
    "_post",
    "_onHalted",
)


class Behavior:
    """A node at run time. Subclasses implement ``tick`` and, if they keep state, ``halt``."""

    #: Port declarations of the type, used by user leaves (name → PortSpec).
    ports: ClassVar[dict] = {}
    #: Ports the node cannot run without (checked when the executor is built).
    required_ports: ClassVar[tuple[str, ...]] = ()
    #: This node's packed status changes, ``[prev][new]`` (``btlog.events.change_rows``),
    #: set by the executor while a subscriber takes status changes in batches.
    changes: tuple[tuple[bytes, ...], ...] = ()

    def __init__(self, node: Node, runtime: Runtime, board: Blackboard) -> None:
        self.node = node
        self.uid = node.uid
        self.runtime = runtime
        self.status: Status = IDLE
        self.children: list[Behavior] = []
        self.blackboard = board.view(node.uid)
        self._port_cache: dict[str, tuple[str | None, str]] = {}
        has_conditions = any(a in node.attributes for a in _CONDITION_ATTRIBUTES)
        self._conditions = _Conditions(node.attributes) if has_conditions else None
        if has_conditions:
            # the scripts run around the node's own tick, so ``execute_tick`` checks nothing
            # for the nodes that have none (the hot path)
            self.tick = self._tick_with_conditions  # type: ignore[method-assign]

    # -- status ------------------------------------------------------------------------
    def set_status(self, new: Status) -> None:
        """Store a new status (never IDLE) and report the change."""
        prev = self.status
        if prev is not new:
            self.status = new
            emit = self.runtime.emit_status
            if emit is not None:
                emit(self.uid, prev, new)

    def reset_status(self) -> None:
        """Back to IDLE, reporting the change if there is one."""
        prev = self.status
        if prev is not IDLE:
            self.status = IDLE
            emit = self.runtime.emit_status
            if emit is not None:
                emit(self.uid, prev, IDLE)

    # -- ticking -----------------------------------------------------------------------
    def execute_tick(self) -> Status:
        """Tick this node as BT.CPP's ``TreeNode::executeTick`` does (the pre- and
        post-conditions, if any, run in ``tick``: see ``_tick_with_conditions``)."""
        new = self.tick()
        prev = self.status
        if new is not prev and new is not SKIPPED:  # set_status, inlined: the hot path
            self.status = new
            runtime = self.runtime
            append = runtime.append_row
            if append is not None:  # the change emit_status would add, without the call
                append(self.changes[prev][new])
            elif runtime.emit_status is not None:
                runtime.emit_status(self.uid, prev, new)
        return new

    def _tick_with_conditions(self) -> Status:
        """The node's ``tick`` when it has conditions: the pre-conditions (which may decide
        the result instead of the node's own tick), then, on completion, ``_onSuccess`` or
        ``_onFailure`` and ``_post``; ``execute_tick`` stores the result."""
        conditions = self._conditions
        assert conditions is not None
        new = self._check_preconditions(conditions)
        if new is None:
            new = type(self).tick(self)
        if new is SUCCESS or new is FAILURE:
            script = conditions.on_success if new is SUCCESS else conditions.on_failure
            if script is not None:
                self._run_script(script)
            if conditions.post is not None:
                self._run_script(conditions.post)
        return new

    def _check_preconditions(self, conditions: _Conditions) -> Status | None:
        status = self.status
        if status is IDLE or status is SKIPPED:
            for script, result in (
                (conditions.failure_if, FAILURE),
                (conditions.success_if, SUCCESS),
                (conditions.skip_if, SKIPPED),
            ):
                if script is not None and truthy(self._run_script(script)):
                    return result
            if conditions.while_ is not None and not truthy(self._run_script(conditions.while_)):
                return SKIPPED
        elif (
            status is RUNNING
            and conditions.while_ is not None
            and not truthy(self._run_script(conditions.while_))
        ):
            self.halt_node()
            return SKIPPED
        return None

    def _run_script(self, script: Callable) -> Any:
        try:
            return script(self.blackboard)
        except MissingVariable as error:
            raise NodeExecutionError(
                self.node, f"script error: {error} ({HOST_ENTRY_HINT}, or a scripting enum)"
            ) from None
        except ScriptError as error:
            raise NodeExecutionError(self.node, f"script error: {error}") from None

    def tick(self) -> Status:
        """The node's own tick; returns its new status."""
        raise NotImplementedError

    # -- halting -----------------------------------------------------------------------
    def halt(self) -> None:
        """Stop and reset. Leaves only reset; controls and decorators override."""
        self.reset_status()

    def halt_node(self) -> None:
        """Halt, then run ``_onHalted`` (BT.CPP's ``haltNode``)."""
        self.halt()
        if self._conditions is not None and self._conditions.on_halted is not None:
            self._run_script(self._conditions.on_halted)

    def wake_up_early(self, child_was: Status, more_to_do: bool) -> bool:
        """BT.CPP's early return: a child that went from IDLE to done in this very tick,
        with more to do, makes its parent return RUNNING and the executor tick again at
        once (True when that happens)."""
        if child_was is IDLE and more_to_do:
            self.runtime.wake_up = True
            return True
        return False

    def halt_child(self, index: int) -> None:
        """Halt child ``index`` if RUNNING, then reset it."""
        child = self.children[index]
        if child.status is RUNNING:
            child.halt_node()
        child.reset_status()

    def reset_children(self) -> None:
        """Halt RUNNING children and reset all of them, in order."""
        runtime = self.runtime
        emit, append = runtime.emit_status, runtime.append_row
        for child in self.children:
            prev = child.status
            if prev is RUNNING:
                child.halt_node()
                child.reset_status()
            elif prev is not IDLE:  # reset_status, inlined: the hot path (as execute_tick)
                child.status = IDLE
                if append is not None:
                    append(child.changes[prev][0])  # to IDLE
                elif emit is not None:
                    emit(child.uid, prev, IDLE)

    # -- ports -------------------------------------------------------------------------
    def _port(self, name: str) -> tuple[str | None, str]:
        cached = self._port_cache.get(name)
        if cached is None:
            port = self.node.ports.get(name)
            if port is None:
                spec = self.ports.get(name)
                if spec is None or spec.default is None:
                    raise NodeExecutionError(self.node, f"port {name!r} is not set")
                raw = spec.default
            else:
                raw = port.value
            key = blackboard_key(raw)
            if key == "=" or (key is None and raw.strip() == "="):
                key = name
            cached = (key, raw)
            self._port_cache[name] = cached
        return cached

    def check_ports(self) -> None:
        """NodeExecutionError (naming file and line) when a required port is not set."""
        for name in self.required_ports:
            if not self.has_port(name):
                raise NodeExecutionError(self.node, f"port {name!r} is not set")

    def has_port(self, name: str) -> bool:
        """True when the port is set in the XML or has a declared default."""
        if name in self.node.ports:
            return True
        spec = self.ports.get(name)
        return spec is not None and spec.default is not None

    def get_input(self, name: str, type_name: str | None = None) -> Any:
        """Read an input port: a literal converted to its type, or a blackboard entry."""
        key, raw = self._port(name)
        if type_name is None:
            spec = self.ports.get(name)
            type_name = spec.type if spec is not None else "str"
        if key is None:
            value: Any = raw
        else:
            try:
                value = self.blackboard.get(key)
            except KeyError:
                raise NodeExecutionError(
                    self.node,
                    f"port {name!r}: blackboard entry {key!r} does not exist ({HOST_ENTRY_HINT})",
                ) from None
        try:
            return convert(value, type_name)
        except PortValueError as error:
            raise NodeExecutionError(self.node, f"port {name!r}: {error}") from None

    def set_output(self, name: str, value: Any) -> None:
        """Write an output port's blackboard entry."""
        key, raw = self._port(name)
        if key is None:
            raise NodeExecutionError(
                self.node, f"output port {name!r} must be a {{key}}, not {raw!r}"
            )
        self.blackboard.set(key, value)

    @property
    def now(self) -> float:
        """The executor's time in seconds since the run started."""
        return self.runtime.clock.now_ns() / 1e9

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.uid} {self.node.name!r} {self.status.name}>"


class ControlBehavior(Behavior):
    """Base of control nodes: ``halt`` resets every child, then the node itself."""

    def halt(self) -> None:
        self.reset_children()
        self.reset_status()

    def insert_child(self, index: int, child: Behavior) -> None:
        """Insert a child while running; subclasses keep their resume index right."""
        self.children.insert(index, child)


class DecoratorBehavior(Behavior):
    """Base of decorators: one child, reset after it completes (BT.CPP's DecoratorNode)."""

    @property
    def child(self) -> Behavior:
        """The only child."""
        return self.children[0]

    def execute_tick(self) -> Status:
        status = Behavior.execute_tick(self)
        child = self.children[0]
        if child.status is SUCCESS or child.status is FAILURE:
            child.reset_status()
        return status

    def reset_child(self) -> None:
        """Halt the child if RUNNING, then reset it."""
        self.halt_child(0)

    def halt(self) -> None:
        self.reset_child()
        self.reset_status()


#: Builds the behaviour of a leaf type that has no implementation (scripted leaves).
LeafFactory = Callable[[Node, Runtime, "Blackboard"], Behavior]

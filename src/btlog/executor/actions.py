"""Leaves: the base classes for users' own actions and conditions, and the built-ins.

Write a leaf by subclassing one of:

- ``SyncAction``: ``tick()`` returns SUCCESS or FAILURE in one tick (logged IDLE→result);
- ``Condition``: ``check()`` returns a Status or a bool. As in the paper, a condition may
  return RUNNING while a check takes time;
- ``StatefulAction``: ``on_start()`` when started from IDLE, ``on_running()`` on later
  ticks while RUNNING, ``on_halted()`` when halted while RUNNING (BT.CPP's
  StatefulActionNode).

Declare ports with ``ports = {"pose": InputPort("json"), "output": OutputPort()}``; read
them with ``self.get_input("pose")`` and write with ``self.set_output("output", value)``.
Register the class with ``Registry.register_leaf``, named by its ``type_id`` (or the class
name), and the loader and executor will use it wherever the XML names that type.
"""

from __future__ import annotations

from typing import Any

from btlog.executor.behavior import Behavior, NodeExecutionError
from btlog.executor.blackboard import EntryWatch
from btlog.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, Status
from btlog.tree.model import INOUT, INPUT, OUTPUT
from btlog.tree.registry import PortSpec
from btlog.tree.script import compile_script, truthy


def InputPort(
    type_name: str = "str", default: str | None = None, description: str = ""
) -> PortSpec:
    """Declare an input port of a leaf."""
    return PortSpec(INPUT, type_name, default, description)


def OutputPort(type_name: str = "any", description: str = "") -> PortSpec:
    """Declare an output port of a leaf."""
    return PortSpec(OUTPUT, type_name, None, description)


def InoutPort(type_name: str = "any", description: str = "") -> PortSpec:
    """Declare a port that is read and written."""
    return PortSpec(INOUT, type_name, None, description)


def _as_status(value: Any, node: Behavior) -> Status:
    if isinstance(value, Status):
        return value
    if isinstance(value, bool):
        return SUCCESS if value else FAILURE
    raise NodeExecutionError(node.node, f"a leaf returned {value!r}, not a Status or a bool")


class SyncAction(Behavior):
    """An action that completes in the tick it starts. Override ``tick``."""

    kind = "action"

    def execute_tick(self) -> Status:
        result = Behavior.execute_tick(self)
        if result is RUNNING:
            raise NodeExecutionError(self.node, "a SyncAction must not return RUNNING")
        return result


class Condition(Behavior):
    """A check. Override ``check``; it may return RUNNING while the check takes time."""

    kind = "condition"

    def check(self) -> Status | bool:
        """Return the result of the check."""
        raise NotImplementedError

    def tick(self) -> Status:
        return _as_status(self.check(), self)


class StatefulAction(Behavior):
    """An action that runs over several ticks: ``on_start``, ``on_running``, ``on_halted``."""

    kind = "action"

    def on_start(self) -> Status | bool:
        """Called when ticked from IDLE; return RUNNING to keep going."""
        raise NotImplementedError

    def on_running(self) -> Status | bool:
        """Called on every later tick while RUNNING."""
        return RUNNING

    def on_halted(self) -> None:
        """Called when halted while RUNNING."""

    def tick(self) -> Status:
        status = self.status
        if status is IDLE:
            result = _as_status(self.on_start(), self)
        elif status is RUNNING:
            result = _as_status(self.on_running(), self)
        else:
            return status
        if result is IDLE:
            raise NodeExecutionError(self.node, "a stateful action must not return IDLE")
        return result

    def halt(self) -> None:
        if self.status is RUNNING:
            self.on_halted()
        self.reset_status()


class AlwaysSuccess(SyncAction):
    """SUCCESS, at once."""

    #: a constant cannot be RUNNING: no check of the result (the hot path)
    execute_tick = Behavior.execute_tick

    def tick(self) -> Status:
        return SUCCESS


class AlwaysFailure(SyncAction):
    """FAILURE, at once."""

    #: a constant cannot be RUNNING: no check of the result (the hot path)
    execute_tick = Behavior.execute_tick

    def tick(self) -> Status:
        return FAILURE


class Script(SyncAction):
    """Run the ``code`` script; SUCCESS."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._script = compile_script(self.get_input("code"))

    def tick(self) -> Status:
        self._run_script(self._script)
        return SUCCESS


class ScriptCondition(Condition):
    """SUCCESS when the ``code`` script is true, else FAILURE."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._script = compile_script(self.get_input("code"))

    def check(self) -> Status:
        return SUCCESS if truthy(self._run_script(self._script)) else FAILURE


class SetBlackboard(SyncAction):
    """Write ``value`` (a literal, or a copy of another ``{entry}``) to ``output_key``."""

    def tick(self) -> Status:
        key = self.get_input("output_key")
        source, raw = self._port("value")
        if source is None:
            value = raw
        elif self.blackboard.exists(source):
            value = self.blackboard.get(source)
        else:
            raise NodeExecutionError(self.node, f"blackboard entry {source!r} does not exist")
        self.blackboard.set(key, value)
        return SUCCESS


class UnsetBlackboard(SyncAction):
    """Remove the entry named by ``key``."""

    def tick(self) -> Status:
        self.blackboard.unset(self.get_input("key"))
        return SUCCESS


class Sleep(StatefulAction):
    """RUNNING for ``msec`` milliseconds of the executor's clock, then SUCCESS."""

    required_ports = ("msec",)

    def on_start(self) -> Status:
        msec = self.get_input("msec", "unsigned")
        if msec <= 0:
            return SUCCESS
        self.deadline = self.runtime.clock.now_ns() + msec * 1_000_000
        return RUNNING

    def on_running(self) -> Status:
        return SUCCESS if self.runtime.clock.now_ns() >= self.deadline else RUNNING


class WasEntryUpdated(SyncAction):
    """SUCCESS when the blackboard entry named by ``entry`` (``{key}`` or a plain key) was
    written since this node last looked (every write counts), else FAILURE; a missing
    entry is FAILURE."""

    required_ports = ("entry",)

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.watch = EntryWatch(self.node.ports["entry"].value if self.has_port("entry") else "")

    def tick(self) -> Status:
        return SUCCESS if self.watch.updated(self.blackboard) else FAILURE


ACTIONS: dict[str, type[Behavior]] = {
    "AlwaysSuccess": AlwaysSuccess,
    "AlwaysFailure": AlwaysFailure,
    "Script": Script,
    "ScriptCondition": ScriptCondition,
    "SetBlackboard": SetBlackboard,
    "UnsetBlackboard": UnsetBlackboard,
    "Sleep": Sleep,
    "WasEntryUpdated": WasEntryUpdated,
}

__all__ = [
    "ACTIONS",
    "SKIPPED",
    "Condition",
    "InoutPort",
    "InputPort",
    "OutputPort",
    "StatefulAction",
    "SyncAction",
]

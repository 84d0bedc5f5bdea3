"""What a py_trees tree does, seen as it happens: status changes and blackboard activity.

**Status changes.** py_trees sets ``behaviour.status`` in many places — a behaviour's own
tick, ``stop()``, a composite resetting its children, a Selector invalidating a
pre-empted lower-priority child it does not visit — so btlog watches the assignment
itself. ``hook`` gives a behaviour a subclass of its own class (same name, cached per
class) whose ``status`` is a data descriptor with only ``__set__``: a read of
``status`` still finds the instance's dict at C speed, an assignment goes through
``StatusHook.__set__``, which stores the value and, on a change (old is not new), appends
the change, packed, to the recorder's list: two dict look-ups by the statuses' ids (an
enum's own hash is computed in Python) and an append, nothing numbered, timed or built
(the changes of a tick take the tick's time). ``unhook`` gives
the behaviour its class back.

**Blackboard.** py_trees reports blackboard activity to ``Blackboard.activity_stream``
when one is enabled. ``ActivityTap`` takes its place while recording: each write, first
write (INITIALISED) and removal (UNSET) is handed on at once, in the order it happened
among the status changes; when the program had a stream of its own, the tap keeps
filling it as it was.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import orjson
from py_trees import blackboard as pt_blackboard
from py_trees import common as pt_common

#: Where a hooked behaviour puts a change: the append of the packed changes' list.
Sink = Callable[[bytes], None]
#: A behaviour's packed changes by the ids of its old and new py_trees status (an enum
#: member is one object; its own hash is computed in Python, an int's is not).
Rows = dict[int, dict[int, bytes]]

#: Activities that change the blackboard.
WRITES = frozenset({"WRITE", "INITIALISED", "UNSET"})
#: The longest ``repr`` kept of a value that is not JSON.
MAX_REPR = 1000
#: The largest JSON value kept as JSON; a larger one is kept as a bounded repr.
MAX_JSON_BYTES = 64 * 1024

_UID = "_btlog_uid"
_ROWS = "_btlog_rows"
_SINK = "_btlog_sink"
_SUBCLASSES: dict[type, type] = {}


class StatusHook:
    """The ``status`` of a hooked behaviour (see the module docstring)."""

    __slots__ = ()

    def __set__(self, behaviour: Any, status: Any, _id: Callable[[Any], int] = id) -> None:
        """Store ``status``; when it differs from the last one, put the change in the
        sink."""
        slots = behaviour.__dict__
        old = slots["status"]
        slots["status"] = status
        if old is not status:
            slots[_SINK](slots[_ROWS][_id(old)][_id(status)])


def _subclass(cls: type) -> type:
    hooked = _SUBCLASSES.get(cls)
    if hooked is None:
        namespace = {
            "status": StatusHook(),
            "_btlog_original": cls,
            "__module__": cls.__module__,
            "__qualname__": cls.__qualname__,
        }
        hooked = _SUBCLASSES[cls] = type(cls)(cls.__name__, (cls,), namespace)
    return hooked


def hook(behaviour: Any, uid: int, rows: Rows, sink: Sink) -> None:
    """Put every later status change of ``behaviour``, node ``uid``, in ``sink``, packed
    as ``rows`` says."""
    cls = type(behaviour)
    if "_btlog_original" not in cls.__dict__:
        behaviour.__class__ = _subclass(cls)
    slots = behaviour.__dict__
    slots.setdefault("status", pt_common.Status.INVALID)
    slots[_UID] = uid
    slots[_ROWS] = rows
    slots[_SINK] = sink


def unhook(behaviour: Any) -> None:
    """Give ``behaviour`` its own class back; it reports nothing more."""
    original = type(behaviour).__dict__.get("_btlog_original")
    if original is not None:
        behaviour.__class__ = original
    for key in (_UID, _ROWS, _SINK):
        behaviour.__dict__.pop(key, None)


def hooked_uid(behaviour: Any) -> int | None:
    """The uid ``behaviour`` reports as, if it is hooked."""
    return behaviour.__dict__.get(_UID)


def recorded_value(value: Any) -> Any:
    """``value`` when it is JSON of at most ``MAX_JSON_BYTES``, else its ``repr`` cut
    to ``MAX_REPR`` characters."""
    if value is None or type(value) in (str, bool, int, float):
        return value
    try:
        if len(orjson.dumps(value)) <= MAX_JSON_BYTES:
            return value
    except Exception:  # not JSON, or a value whose own code fails
        pass
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not stop the run
        text = f"<{type(value).__name__} object>"
    return text if len(text) <= MAX_REPR else text[: MAX_REPR - 1] + "…"


class ActivityTap(pt_blackboard.ActivityStream):
    """An activity stream that hands each blackboard change to ``on_change`` as it
    comes (and keeps the stream ``previous`` filled, if the program had one)."""

    def __init__(
        self,
        previous: pt_blackboard.ActivityStream | None,
        on_change: Callable[[pt_blackboard.ActivityItem], None],
    ) -> None:
        self.previous = previous
        self.on_change = on_change
        super().__init__(previous.maximum_size if previous is not None else 0)

    @property
    def data(self) -> list[pt_blackboard.ActivityItem]:
        """The program's own stream's items (none without one)."""
        return self.previous.data if self.previous is not None else []

    @data.setter
    def data(self, items: list[pt_blackboard.ActivityItem]) -> None:
        if self.previous is not None:
            self.previous.data = items

    def push(self, activity_item: pt_blackboard.ActivityItem) -> None:
        """Hand a change on; pass every item to the program's own stream."""
        if activity_item.activity_type in WRITES:
            self.on_change(activity_item)
        if self.previous is not None:
            self.previous.push(activity_item)

    def clear(self) -> None:
        """Clear the program's own stream (the tap keeps nothing)."""
        if self.previous is not None:
            self.previous.clear()


def tap_blackboard(on_change: Callable[[pt_blackboard.ActivityItem], None]) -> ActivityTap:
    """Put an ``ActivityTap`` in place of py_trees' activity stream."""
    tap = ActivityTap(pt_blackboard.Blackboard.activity_stream, on_change)
    pt_blackboard.Blackboard.activity_stream = tap
    return tap


def untap_blackboard(tap: ActivityTap) -> None:
    """Put the program's own stream (or none) back, if the tap is still in place."""
    if pt_blackboard.Blackboard.activity_stream is tap:
        pt_blackboard.Blackboard.activity_stream = tap.previous

"""What a py_trees tree does, seen as it happens: status changes and blackboard activity.

**Status changes.** py_trees sets ``behaviour.status`` in two places only: at the end of
``stop()`` — a behaviour completing (every SUCCESS, FAILURE and INVALID goes through it),
a composite resetting its children, a Selector invalidating a pre-empted lower-priority
child it does not visit, ``tree.interrupt()`` — and, for RUNNING, in a behaviour's own
``tick()`` just before it yields itself. ``TreeWatch`` watches both where they happen:

- each watched behaviour gets a ``stop`` of its own (an instance attribute) that calls the
  one it had and then, when the status is not the one last seen, appends the change,
  packed, to the recorder's list. That is a Python-to-Python call, which the interpreter
  makes without leaving its loop; watching the ``status`` assignment itself (a data
  descriptor) costs a call from C per assignment, and giving the behaviour another class
  (needed to put a descriptor on it) makes py_trees' own attribute accesses slower: the
  instance's inline attribute values become a dict;
- the root's ``tick`` is wrapped: every behaviour a tick yields reaches the root at once
  (composites and decorators hand their children's yields up before doing anything
  else), so the root sees a behaviour that has just set itself RUNNING before anything
  else happens.

A behaviour's last seen status and its packed changes (the executor's ``CHANGE`` rows:
``btlog.events.change_rows``) are kept in a ``Cell`` the behaviour's ``stop`` holds: a
change is one look-up by the new status's id (an enum's own hash is computed in Python, an
int's is not), two stores and an append, nothing numbered, timed or built (the changes of
a tick take the tick's time). Together they give every change py_trees makes, in its
order. A status assigned anywhere else (a user's behaviour writing ``self.status``) is
found by ``sweep`` at the tick's end, so the recorded state after every tick is the
tree's whatever the code does; ``unwatch`` gives the behaviour its ``stop`` back.

**Children.** A composite's ``add_child``, ``insert_child``, ``prepend_child``,
``remove_child`` and ``remove_all_children`` are given the same way (``watch_children``):
py_trees' other ways to change children (``add_children``, ``replace_child``, the tree's
``insert_subtree``, ``prune_subtree``, ``replace_subtree``) go through them, so every
change of the tree's shape reaches the recorder, at no cost per tick.

**Blackboard.** py_trees reports blackboard activity to ``Blackboard.activity_stream``
when one is enabled. ``ActivityTap`` takes its place while recording: each write, first
write (INITIALISED) and removal (UNSET) is handed on at once, in the order it happened
among the status changes; when the program had a stream of its own, the tap keeps
filling it as it was.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import orjson
from py_trees import blackboard as pt_blackboard
from py_trees import common as pt_common

#: Where a watched behaviour puts a change: the append of the packed changes' list.
Sink = Callable[[bytes], None]
#: A behaviour's packed changes by the ids of its old and new py_trees status.
Rows = dict[int, dict[int, bytes]]
#: ``[status last seen, its Table]``: a behaviour's state as its watchers share it.
Cell = list[Any]
#: The changes out of one status, by the id of the new status: ``(packed change, new
#: status, the new status's Table)``, what a ``Cell`` becomes.
Table = dict[int, tuple[bytes, Any, Any]]

#: Activities that change the blackboard.
WRITES = frozenset({"WRITE", "INITIALISED", "UNSET"})
#: The longest ``repr`` kept of a value that is not JSON.
MAX_REPR = 1000
#: The largest JSON value kept as JSON; a larger one is kept as a bounded repr.
MAX_JSON_BYTES = 64 * 1024

_INVALID = pt_common.Status.INVALID
_RUNNING = pt_common.Status.RUNNING


def tables(rows: Rows) -> dict[int, Table]:
    """The ``Table`` of each status (by its id) from a behaviour's packed ``rows``."""
    found: dict[int, Table] = {id(status): {} for status in pt_common.Status}
    for old in pt_common.Status:
        for new in pt_common.Status:
            found[id(old)][id(new)] = (rows[id(old)][id(new)], new, found[id(new)])
    return found


def _watched_stop(behaviour: Any, cell: Cell, sink: Sink) -> Callable[..., None]:
    """A ``stop`` for ``behaviour`` that calls the one it has and puts the change it made
    in ``sink``."""
    bound = behaviour.stop
    if getattr(bound, "__func__", None) is getattr(type(behaviour), "stop", None):
        own = bound.__func__  # called unbound: a bound method's call costs more

        def stop(new_status: Any = _INVALID) -> None:
            own(behaviour, new_status)
            status = behaviour.status
            if status is not cell[0]:
                packed, cell[0], cell[1] = cell[1][id(status)]
                sink(packed)

    else:  # a stop of its own (another recorder's, the program's)

        def stop(new_status: Any = _INVALID) -> None:
            bound(new_status)
            status = behaviour.status
            if status is not cell[0]:
                packed, cell[0], cell[1] = cell[1][id(status)]
                sink(packed)

    return stop


class TreeWatch:
    """Watches the behaviours given to ``watch``: each status change is put, packed, in
    ``sink``, and a composite's children put in or taken out go to the callbacks (see
    the module docstring)."""

    def __init__(self, sink: Sink) -> None:
        self.sink = sink
        #: each watched behaviour's cell (its ``stop`` holds the same)
        self.cells: dict[Any, Cell] = {}
        #: each watched behaviour's node uid
        self.uids: dict[Any, int] = {}
        #: what each watched behaviour was given, by attribute name
        self._given: dict[Any, dict[str, Callable[..., Any]]] = {}

    def _give(self, behaviour: Any, name: str, method: Callable[..., Any]) -> None:
        method.__doc__ = getattr(behaviour, name).__doc__
        setattr(behaviour, name, method)
        self._given.setdefault(behaviour, {})[name] = method

    def watch(self, behaviour: Any, uid: int, rows: Rows) -> None:
        """Put every later status change of ``behaviour``, node ``uid``, in the sink,
        packed as ``rows`` says (the status it has now is the last seen)."""
        status = getattr(behaviour, "status", _INVALID)
        table = tables(rows)
        cell = [status, table[id(status)]]
        self.cells[behaviour] = cell
        self.uids[behaviour] = uid
        self._give(behaviour, "stop", _watched_stop(behaviour, cell, self.sink))

    def watch_children(
        self, composite: Any, inserted: Callable[[Any], None], removed: Callable[[Any], None]
    ) -> None:
        """Hand each child later put in ``composite`` (``add_child``, ``insert_child``,
        ``prepend_child``, and so ``add_children``, ``replace_child`` and the tree's
        ``insert_subtree``...) to ``inserted`` once it is in, and each taken out
        (``remove_child``, ``remove_all_children``, ...) to ``removed`` once it is out."""
        for name in ADDERS:
            self._give(composite, name, _after(getattr(composite, name), inserted))
        self._give(composite, "remove_child", _after(composite.remove_child, removed))
        remove_all = composite.remove_all_children

        def remove_all_children() -> None:
            children = list(composite.children)
            remove_all()
            for child in children:
                removed(child)

        self._give(composite, "remove_all_children", remove_all_children)

    def unwatch(self, behaviour: Any) -> None:
        """Give ``behaviour`` its own methods back; it reports nothing more."""
        for name, method in self._given.pop(behaviour, {}).items():
            if getattr(behaviour, name, None) is method:
                delattr(behaviour, name)
        self.cells.pop(behaviour, None)
        self.uids.pop(behaviour, None)

    def uid_of(self, behaviour: Any) -> int | None:
        """The uid ``behaviour`` is recorded as, if it is watched."""
        return self.uids.get(behaviour)

    def watch_ticks(self, root: Any) -> None:
        """Wrap ``root``'s ``tick``: a watched behaviour it yields that is RUNNING, and
        was not, puts the change in the sink."""
        ticks = root.tick
        cells, sink, running = self.cells, self.sink, id(_RUNNING)

        def tick() -> Iterator[Any]:
            for behaviour in ticks():
                if behaviour.status is _RUNNING:
                    cell = cells.get(behaviour)
                    if cell is not None and cell[0] is not _RUNNING:
                        packed, cell[0], cell[1] = cell[1][running]
                        sink(packed)
                yield behaviour

        self._give(root, "tick", tick)

    def sweep(self) -> int:
        """Put in the sink the change of each watched behaviour whose status is not the
        one last seen (set outside ``stop`` and a tick's yield); how many there were."""
        found = 0
        sink = self.sink
        for behaviour, cell in self.cells.items():
            status = behaviour.status
            if status is not cell[0]:
                packed, cell[0], cell[1] = cell[1][id(status)]
                sink(packed)
                found += 1
        return found


#: A composite's methods that put a child in (the child is their first argument).
ADDERS = ("add_child", "insert_child", "prepend_child")


def _after(method: Callable[..., Any], then: Callable[[Any], None]) -> Callable[..., Any]:
    """``method``, then ``then`` of its first argument."""

    def called(child: Any, *args: Any) -> Any:
        result = method(child, *args)
        then(child)
        return result

    return called


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

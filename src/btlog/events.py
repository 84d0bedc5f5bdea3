"""Events: the immutable facts a run is made of.

A run is the sequence of its events, numbered by a global, gap-free ``seq`` from 0 and
stamped with ``t_ns`` since the run started and the ``tick`` they happened in:

- ``StatusChange``: a node's status changed (IDLE resets included), as BT.CPP's loggers
  see it;
- ``BlackboardWrite``: an entry was written (or removed: ``type == "unset"``) by a node;
- ``TreeMutation``: the tree itself changed (a subtree inserted while running).

``TickRecord`` summarises one root tick. A ``Gap`` — a time a source gave no data
(``btlog attach``'s publisher fell silent or restarted, its buffer overflowed) — is kept
as a write of the scope ``GAP_SCOPE``, so it is stored, read, replayed and shown with the
events around it. Everything else — the state at a moment, the
read model in DuckDB, the answers to questions — is a projection folded from these.

The executor delivers events to a ``Subscriber`` as positional fields (no object per
event on the hot path); ``EventLog`` is a subscriber that keeps them as records. A sole
subscriber that buffers status changes, such as the recorder, may take them in batches
instead (``StatusBatch``): the nodes append their own packed ``CHANGE`` without a seq or
a time, and the source numbers the lot at once before any other event.
"""

from __future__ import annotations

import struct
from typing import Any, NamedTuple

from btlog.status import Status

#: A status change as the executor batches it: the node's uid (i32), the previous and the
#: new status (i8), little-endian. It is also the row of the recording's uid, prev and
#: status columns (``btlog.record.columns``), so a batch is stored without decoding it.
CHANGE = struct.Struct("<ibb")


def change_rows(uid: int) -> tuple[tuple[bytes, ...], ...]:
    """Every packed change of node ``uid``, indexed ``[prev][status]`` by status value:
    a node looks its change up instead of building it."""
    return tuple(tuple(CHANGE.pack(uid, prev, new) for new in Status) for prev in Status)


class StatusChange(NamedTuple):
    """Node ``uid`` went from ``prev`` to ``status``."""

    seq: int
    t_ns: int
    tick: int
    uid: int
    prev: Status
    status: Status


class BlackboardWrite(NamedTuple):
    """Entry ``key`` of scope ``scope`` was set to ``value`` by node ``writer_uid``."""

    seq: int
    t_ns: int
    tick: int
    scope: str
    key: str
    value: Any
    type: str
    writer_uid: int | None


#: The operations of a ``TreeMutation``.
INSERT = "insert"
PRUNE = "prune"


class TreeMutation(NamedTuple):
    """The tree changed: ``nodes`` (records with fresh uids) inserted under ``parent_uid``
    right after ``after_uid``, because of ``question`` (``op`` ``INSERT``); or, ``op``
    ``PRUNE`` (a py_trees ``prune_subtree``), the subtree ``nodes`` describes taken out
    from under ``parent_uid`` (its uids are never used again)."""

    seq: int
    t_ns: int
    tick: int
    op: str
    parent_uid: int
    after_uid: int | None
    nodes: list[dict]
    question: str

    @property
    def inserted_root_uid(self) -> int:
        """The uid of the inserted (or pruned) subtree's root."""
        return self.nodes[0]["uid"]


#: The scope of the writes that mark gaps in a recording: key ``gap N``, value a
#: ``Gap.to_json()``. A later write of the same key extends that gap.
GAP_SCOPE = "btlog.gaps"


class Gap(NamedTuple):
    """No data from ``from_ns`` to ``to_ns`` (times since the start), and ``why``."""

    from_ns: int
    to_ns: int
    why: str

    def to_json(self) -> dict[str, Any]:
        """The value of its write."""
        return {"from_ns": self.from_ns, "to_ns": self.to_ns, "why": self.why}


def gaps_in(entries: dict[str, Any]) -> list[Gap]:
    """The gaps among the entries of ``GAP_SCOPE`` (a state's blackboard), in time order;
    entries that are not gaps are left out."""
    found = []
    for value in entries.values():
        try:
            found.append(Gap(int(value["from_ns"]), int(value["to_ns"]), str(value["why"])))
        except (TypeError, KeyError, ValueError):
            continue
    return sorted(found)


class TickRecord(NamedTuple):
    """Root tick ``tick`` ran from ``start_ns`` to ``end_ns`` and returned ``root_status``;
    ``teardown`` marks the run's final tick in which the tree was halted as BT.CPP halts a
    tree it destroys (its root status is IDLE)."""

    tick: int
    start_ns: int
    end_ns: int
    root_status: Status
    teardown: bool = False


Event = StatusChange | BlackboardWrite | TreeMutation


class Subscriber:
    """Receives a run's events in execution order. Override what you need."""

    def on_status(
        self, seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
    ) -> None:
        """A status change."""

    def takes_status_batches(self) -> bool:
        """True when the subscriber takes status changes in batches (``on_status_batch``)
        instead of one ``on_status`` call each. The executor's nodes then append each
        change to a list as a packed ``CHANGE`` they look up, without numbering it, which
        is most of what a change costs a recorder; the executor hands the list over
        before any other event, at every tick's start and end and whenever ``seq`` is
        read. It does so only for a sole subscriber."""
        return False

    def on_status_batch(
        self, seq: int, tick: int, t_ns: int, changes: list[bytes], times: list[int] | None
    ) -> None:
        """Status changes numbered ``seq``, ``seq + 1``, ..., all in tick ``tick``, each a
        ``CHANGE`` (uid, prev, status). ``times`` holds each change's time, or is None
        when they all happened at ``t_ns`` (a simulated clock's time within a tick). The
        lists are the executor's and are cleared after the call: copy what you keep. The
        default calls ``on_status`` for each."""
        for index, change in enumerate(changes):
            uid, prev, status = CHANGE.unpack(change)
            at = t_ns if times is None else times[index]
            self.on_status(seq + index, at, tick, uid, Status(prev), Status(status))

    def on_write(
        self,
        seq: int,
        t_ns: int,
        tick: int,
        scope: str,
        key: str,
        value: Any,
        type_name: str,
        writer_uid: int | None,
    ) -> None:
        """A blackboard write (``type_name == "unset"`` for a removal)."""

    def on_mutation(self, mutation: TreeMutation) -> None:
        """A change of the tree."""

    def on_tick(self, record: TickRecord) -> None:
        """The end of a root tick."""

    def on_close(self) -> None:
        """The run is over (or stopped); flush what is buffered."""


class StatusBatch:
    """Status changes a source has made but not numbered yet, for the one subscriber that
    takes them in batches (``Subscriber.takes_status_batches``).

    The source appends each change to ``changes`` as a packed ``CHANGE`` it looks up
    (``change_rows``), and its time to ``times`` unless the batch is untimed (every
    change at the time ``hand_over`` is given: a simulated clock's). It calls
    ``hand_over`` before anything else takes a seq and before the tick or that time
    changes, so the numbers are those of execution order.
    """

    __slots__ = ("changes", "taker", "times")

    def __init__(self, taker: Subscriber, timed: bool) -> None:
        self.taker = taker
        self.changes: list[bytes] = []
        self.times: list[int] | None = [] if timed else None

    def count(self) -> int:
        """The changes in the batch (a change whose time an interrupt, Ctrl-C, kept from
        being noted is dropped: the seqs the batch will take)."""
        changes, times = self.changes, self.times
        if times is not None and len(times) != len(changes):
            del changes[len(times) :], times[len(changes) :]
        return len(changes)

    def hand_over(self, seq: int, tick: int, t_ns: int) -> int:
        """Give the batch to the taker as changes ``seq``, ``seq + 1``, ... of tick
        ``tick`` (at ``t_ns`` if untimed), empty it, and return how many there were."""
        changes, times = self.changes, self.times
        count = self.count()
        if count:
            try:
                self.taker.on_status_batch(seq, tick, t_ns, changes, times)
            finally:
                changes.clear()
                if times is not None:
                    times.clear()
        return count


class Fanout(Subscriber):
    """Hands each batch of status changes to several subscribers that all take batches
    (``StatusBatch``'s one taker, when there are several)."""

    def __init__(self, takers: list[Subscriber]) -> None:
        self.takers = takers

    def takes_status_batches(self) -> bool:
        """True: it is made for batches."""
        return True

    def on_status_batch(
        self, seq: int, tick: int, t_ns: int, changes: list[bytes], times: list[int] | None
    ) -> None:
        """The batch to each taker in turn."""
        for taker in self.takers:
            taker.on_status_batch(seq, tick, t_ns, changes, times)


class Backlog(Subscriber):
    """Keeps a run's events, batches as batches, for a subscriber that is not fed as they
    come (a live history built only when a question is asked): ``catch_up`` hands it
    every event kept, in order, and forgets them. Keeping a batch is one copy of its
    lists, so a source that batches its changes keeps batching."""

    def __init__(self) -> None:
        self.kept: list[tuple[str, tuple[Any, ...]]] = []

    def takes_status_batches(self) -> bool:
        """True: a batch is kept whole."""
        return True

    def on_status_batch(
        self, seq: int, tick: int, t_ns: int, changes: list[bytes], times: list[int] | None
    ) -> None:
        """Keep a copy of the batch."""
        kept_times = None if times is None else times.copy()
        self.kept.append(("on_status_batch", (seq, tick, t_ns, changes.copy(), kept_times)))

    def on_status(
        self, seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
    ) -> None:
        """Keep a status change."""
        self.kept.append(("on_status", (seq, t_ns, tick, uid, prev, status)))

    def on_write(
        self,
        seq: int,
        t_ns: int,
        tick: int,
        scope: str,
        key: str,
        value: Any,
        type_name: str,
        writer_uid: int | None,
    ) -> None:
        """Keep a write."""
        self.kept.append(("on_write", (seq, t_ns, tick, scope, key, value, type_name, writer_uid)))

    def on_mutation(self, mutation: TreeMutation) -> None:
        """Keep a change of the tree."""
        self.kept.append(("on_mutation", (mutation,)))

    def on_tick(self, record: TickRecord) -> None:
        """Keep a tick's end."""
        self.kept.append(("on_tick", (record,)))

    def catch_up(self, subscriber: Subscriber) -> None:
        """Hand ``subscriber`` every event kept so far (a batch as its changes, unless it
        takes batches), and forget them."""
        kept, self.kept = self.kept, []
        for method, args in kept:
            getattr(subscriber, method)(*args)


class EventLog(Subscriber):
    """A subscriber that keeps every event and tick as records, in order."""

    def __init__(self) -> None:
        self.events: list[Event] = []
        self.ticks: list[TickRecord] = []

    def on_status(
        self, seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
    ) -> None:
        self.events.append(StatusChange(seq, t_ns, tick, uid, prev, status))

    def on_write(
        self,
        seq: int,
        t_ns: int,
        tick: int,
        scope: str,
        key: str,
        value: Any,
        type_name: str,
        writer_uid: int | None,
    ) -> None:
        self.events.append(
            BlackboardWrite(seq, t_ns, tick, scope, key, value, type_name, writer_uid)
        )

    def on_mutation(self, mutation: TreeMutation) -> None:
        self.events.append(mutation)

    def on_tick(self, record: TickRecord) -> None:
        self.ticks.append(record)

    @property
    def transitions(self) -> list[StatusChange]:
        """Only the status changes."""
        return [e for e in self.events if isinstance(e, StatusChange)]


def type_name(value: Any) -> str:
    """The recorded type of a blackboard value."""
    if value is None:
        return "null"
    return type(value).__name__

"""A run's history: the few questions about past events the explanations ask.

The explanation algorithms are pure functions of (tree, state, history). ``State`` is
the present moment; ``History`` answers what happened before it, always *bounded by a
moment*: every query takes a range ``lo <= seq < hi`` of events, and callers pass
``hi = state.seq`` so that nothing after the moment is ever seen.

Two implementations give the same answers for the same events:

- ``LiveHistory`` — a ``Subscriber`` fed by the executor (or by any fold of events);
  it keeps each node's transitions in memory, indexed by uid, plus a snapshot of the
  state every ``snapshot_every`` events;
- ``btlog.replay.sql_history.SqlHistory`` — point queries on the read model's
  ``transitions`` table and its snapshots; never a replay from the start.

The queries: the last/first transition of some nodes to some statuses in a range
(``starts=True`` keeps only the starts of activations: see ``resumes``), all of them in
order (bounded by ``limit``), and the (tree, state) after a given number of events; and
of blackboard writes, the ones a node made in a range and the last write of one entry
(what grounds a failure in what the failing node reported or read). One hint,
``read_ahead``, lets a caller that is about to ask many questions about known spans of
events (the story, a page of failures at a time) have them read at once; it changes no
answer.
"""

from __future__ import annotations

import copy
from bisect import bisect_left
from collections.abc import Collection
from heapq import merge
from itertools import islice
from typing import Any, NamedTuple

from btlog.events import TreeMutation
from btlog.state import State, StateProjection
from btlog.status import IDLE, Status
from btlog.tree.model import Tree

#: Both completions.
COMPLETIONS = (Status.SUCCESS, Status.FAILURE)
#: Every status a node can change to.
ANY_STATUS = tuple(Status)


#: The nodes and statuses a query is about.
Uids = Collection[int]
Statuses = Collection[Status]


class Transition(NamedTuple):
    """One status change of one node."""

    seq: int
    t_ns: int
    uid: int
    prev: Status
    status: Status


class Write(NamedTuple):
    """One blackboard write: the entry (scope, key), its value and who wrote it."""

    seq: int
    t_ns: int
    scope: str
    key: str
    value: Any
    type_name: str
    writer: int | None


def resumes(before: Transition | None, change: Transition) -> bool:
    """True when ``change``, out of IDLE, does not start an activation but ends the one
    ``before`` (the node's own previous change) interrupted: a node that resets itself
    to IDLE and then returns its result, the two changes one right after the other
    (Nav2's RecoveryNode halts itself before it returns SUCCESS). Every other change out
    of IDLE starts an activation. ``btlog.replay.sql_history`` asks the same in SQL."""
    return (
        before is not None
        and change.prev is IDLE
        and change.status in COMPLETIONS
        and before.seq == change.seq - 1
        and before.prev is Status.RUNNING
        and before.status is IDLE
    )


def activation_end(history: Queries, start: Transition, hi: int) -> Transition | None:
    """The change that ended the activation ``start`` began, before event ``hi``: its
    completion, or the reset to IDLE that halted it — unless the node returned its result
    right after that reset (``resumes``), which then ends it; None while it still runs.
    Durations, results and runs of the goal all end activations here."""
    if start.status in COMPLETIONS:
        return start
    end = history.first([start.uid], (*COMPLETIONS, IDLE), start.seq + 1, hi)
    if end is None or end.status is not IDLE:
        return end
    after = history.first([start.uid], ANY_STATUS, end.seq + 1, min(end.seq + 2, hi))
    return after if after is not None and resumes(end, after) else end


class Queries:
    """``History``'s transition queries, each one call of ``select`` (which a backend
    implements once: in memory, or as SQL)."""

    def select(
        self, kind: str, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool, limit: int
    ) -> list[Transition] | int:
        """``kind`` "last" or "first" (a list of at most one), "all" (at most ``limit``,
        in order) or "count" (an int) of the matching transitions."""
        raise NotImplementedError

    def last(
        self, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool = False
    ) -> Transition | None:
        """See ``History.last``."""
        found = self.select("last", uids, statuses, lo, hi, starts, 1)
        return found[0] if isinstance(found, list) and found else None

    def first(
        self, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool = False
    ) -> Transition | None:
        """See ``History.first``."""
        found = self.select("first", uids, statuses, lo, hi, starts, 1)
        return found[0] if isinstance(found, list) and found else None

    def transitions(
        self,
        uids: Collection[int],
        statuses: Collection[Status],
        lo: int,
        hi: int,
        limit: int,
        starts: bool = False,
    ) -> list[Transition]:
        """See ``History.transitions``."""
        found = self.select("all", uids, statuses, lo, hi, starts, limit)
        return found if isinstance(found, list) else []

    def count(self, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool = False) -> int:
        """See ``History.count``."""
        found = self.select("count", uids, statuses, lo, hi, starts, 0)
        return found if isinstance(found, int) else len(found)

    def counts(
        self, uids: Collection[int], statuses: Statuses, lo: int, hi: int, starts: bool = False
    ) -> dict[int, int]:
        """``count`` for each node of ``uids`` on its own (a backend may answer them all
        in one pass: the story counts the runs of every subgoal over the whole run)."""
        return {uid: self.count([uid], statuses, lo, hi, starts) for uid in uids}

    def read_ahead(
        self, spans: Collection[tuple[int, int]], uids: Collection[int] | None = None
    ) -> None:
        """A hint, no question: the next questions are mostly about events in these
        spans (``lo <= seq < hi`` each) and, unless None, these nodes ``uids``, e.g. the
        story's about a page of failures. A
        backend may read them at once (``SqlHistory`` keeps them in memory until the
        next hint; an empty one lets them go); every answer stays the same with or
        without it. Nothing to do for a history already in memory."""


class History(Queries):
    """What the explanations may ask about a run's past (see the module docstring): the
    transition queries of ``Queries``, the blackboard writes, and the state at an
    earlier moment."""

    def state_after(self, count: int) -> tuple[Tree, State]:
        """(tree, state) after the first ``count`` events."""
        raise NotImplementedError

    def writes_by(self, writer: int, lo: int, hi: int, limit: int) -> list[Write]:
        """The first ``limit`` writes node ``writer`` made in events ``lo <= seq < hi``."""
        raise NotImplementedError

    def last_write(self, scope: str, key: str, lo: int, hi: int) -> Write | None:
        """The last write of the entry ``key`` of ``scope`` in events ``lo <= seq < hi``."""
        raise NotImplementedError


class WriteIndex:
    """Blackboard writes kept in memory by writer and by entry (in seq order)."""

    def __init__(self) -> None:
        self.by_writer: dict[int | None, list[Write]] = {}
        self.by_entry: dict[tuple[str, str], list[Write]] = {}

    def add(self, write: Write) -> None:
        """Keep one more write (seqs increase)."""
        self.by_writer.setdefault(write.writer, []).append(write)
        self.by_entry.setdefault((write.scope, write.key), []).append(write)

    def writes_by(self, writer: int, lo: int, hi: int, limit: int) -> list[Write]:
        """See ``History.writes_by``."""
        rows = self.by_writer.get(writer, [])
        start = bisect_left(rows, lo, key=lambda w: w.seq)
        end = bisect_left(rows, hi, key=lambda w: w.seq)
        return rows[start : min(end, start + limit)]

    def last_write(self, scope: str, key: str, lo: int, hi: int) -> Write | None:
        """See ``History.last_write``."""
        rows = self.by_entry.get((scope, key), [])
        end = bisect_left(rows, hi, key=lambda w: w.seq)
        return rows[end - 1] if end and rows[end - 1].seq >= lo else None


class TransitionIndex(Queries):
    """Transitions kept in memory by node, status and whether each starts an activation
    (in seq order): a query is a binary search per (node, status), whatever the range."""

    def __init__(self) -> None:
        self._last: dict[int, Transition] = {}  # each node's latest change
        # (uid, status, starts an activation) -> (seqs, rows)
        self._keyed: dict[tuple[int, Status, bool], tuple[list[int], list[Transition]]] = {}

    def add(self, row: Transition) -> None:
        """Keep one more transition (seqs increase)."""
        seq, _, uid, prev, status = row
        start = prev is IDLE and not resumes(self._last.get(uid), row)
        self._last[uid] = row
        key = (uid, status, start)
        found = self._keyed.get(key)
        if found is None:
            found = self._keyed[key] = ([], [])
        found[0].append(seq)
        found[1].append(row)

    def select(
        self, kind: str, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool, limit: int
    ) -> list[Transition] | int:
        """See ``Queries.select``."""
        kinds = (True,) if starts else (True, False)
        keyed = self._keyed
        slices = []
        for uid in set(uids):
            for status in set(statuses):
                for start in kinds:
                    found = keyed.get((uid, status, start))
                    if found is not None:
                        first, end = bisect_left(found[0], lo), bisect_left(found[0], hi)
                        if first < end:
                            slices.append((found[1], first, end))
        if kind == "count":
            return sum(end - first for _, first, end in slices)
        if not slices:
            return []
        if kind == "last":
            return [max(rows[end - 1] for rows, _, end in slices)]
        if kind == "first":
            return [min(rows[first] for rows, first, _ in slices)]
        return list(
            islice(
                merge(*(rows[first : min(end, first + limit)] for rows, first, end in slices)),
                limit,
            )
        )


class LiveHistory(StateProjection, TransitionIndex, History):
    """The in-memory history, fed event by event (subscribe it to an executor).

    It is a state projection itself (so ``tree`` and ``state`` are the present) and a
    ``TransitionIndex`` of every transition, and it keeps a copy of the state every
    ``snapshot_every`` events, from which ``state_after`` folds the kept events.
    """

    def __init__(self, base: Tree, snapshot_every: int = 512) -> None:
        StateProjection.__init__(self, base)
        TransitionIndex.__init__(self)
        self._writes = WriteIndex()
        self._base = base
        self._every = snapshot_every
        self._events: list[tuple[str, tuple[Any, ...]]] = []
        self._snapshots: list[dict] = [self.state.to_json()]
        self._mutations: list[TreeMutation] = []

    # -- feeding -----------------------------------------------------------------------
    def _keep(self, kind: str, event: tuple[Any, ...]) -> None:
        self._events.append((kind, event))
        if len(self._events) % self._every == 0:
            self._snapshots.append(copy.deepcopy(self.state.to_json()))

    def on_status(
        self, seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
    ) -> None:
        """Apply and keep a status change."""
        super().on_status(seq, t_ns, tick, uid, prev, status)
        self.add(Transition(seq, t_ns, uid, prev, status))
        self._keep("status", (seq, t_ns, tick, uid, prev, status))

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
        """Apply and keep a blackboard write."""
        super().on_write(seq, t_ns, tick, scope, key, value, type_name, writer_uid)
        kept = copy.deepcopy(value)
        self._writes.add(Write(seq, t_ns, scope, key, kept, type_name, writer_uid))
        self._keep("write", (seq, t_ns, tick, scope, key, kept, type_name, writer_uid))

    def on_mutation(self, mutation: TreeMutation) -> None:
        """Apply and keep a change of the tree."""
        super().on_mutation(mutation)
        self._mutations.append(mutation)
        self._keep("mutation", (mutation,))

    # -- the past --------------------------------------------------------------------
    def writes_by(self, writer: int, lo: int, hi: int, limit: int) -> list[Write]:
        """See ``History.writes_by``."""
        return self._writes.writes_by(writer, lo, hi, limit)

    def last_write(self, scope: str, key: str, lo: int, hi: int) -> Write | None:
        """See ``History.last_write``."""
        return self._writes.last_write(scope, key, lo, hi)

    def state_after(self, count: int) -> tuple[Tree, State]:
        """See ``History.state_after``: the nearest snapshot plus the kept events."""
        if not 0 <= count <= len(self._events):
            raise ValueError(f"the run has {len(self._events)} events; cannot apply {count}")
        index = count // self._every
        start = index * self._every
        earlier = [m for m in self._mutations if m.seq < start]
        projection = StateProjection(self._base, State.from_json(self._snapshots[index], earlier))
        for kind, event in self._events[start:count]:
            if kind == "status":
                projection.on_status(*event)
            elif kind == "write":
                projection.on_write(*event)
            else:
                projection.on_mutation(event[0])
        return projection.tree, projection.state

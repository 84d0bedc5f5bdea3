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
(``starts=True`` keeps only activations, i.e. transitions out of IDLE), all of them in
order (bounded by ``limit``), and the (tree, state) after a given number of events.
"""

from __future__ import annotations

import copy
from bisect import bisect_left
from collections.abc import Collection
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


class History(Queries):
    """What the explanations may ask about a run's past (see the module docstring): the
    transition queries of ``Queries`` and the state at an earlier moment."""

    def state_after(self, count: int) -> tuple[Tree, State]:
        """(tree, state) after the first ``count`` events."""
        raise NotImplementedError


class TransitionIndex(Queries):
    """Transitions kept in memory by uid (in seq order); a query is a binary search per
    uid."""

    def __init__(self) -> None:
        self.by_uid: dict[int, list[Transition]] = {}
        self._seqs: dict[int, list[int]] = {}

    def add(self, row: Transition) -> None:
        """Keep one more transition (seqs increase)."""
        self.by_uid.setdefault(row.uid, []).append(row)
        self._seqs.setdefault(row.uid, []).append(row.seq)

    def select(
        self, kind: str, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool, limit: int
    ) -> list[Transition] | int:
        """See ``Queries.select``."""
        wanted = set(statuses)
        groups = []
        for uid in set(uids):
            rows = self.by_uid.get(uid)
            if rows:
                seqs = self._seqs[uid]
                chosen = rows[bisect_left(seqs, lo) : bisect_left(seqs, hi)]
                groups.append(
                    [r for r in chosen if r.status in wanted and (not starts or r.prev is IDLE)]
                )
        if kind == "count":
            return sum(len(rows) for rows in groups)
        if kind == "last":
            return [max(rows[-1] for rows in groups if rows)] if any(groups) else []
        if kind == "first":
            return [min(rows[0] for rows in groups if rows)] if any(groups) else []
        return sorted(r for rows in groups for r in rows)[:limit]


class LiveHistory(StateProjection, TransitionIndex, History):
    """The in-memory history, fed event by event (subscribe it to an executor).

    It is a state projection itself (so ``tree`` and ``state`` are the present) and a
    ``TransitionIndex`` of every transition, and it keeps a copy of the state every
    ``snapshot_every`` events, from which ``state_after`` folds the kept events.
    """

    def __init__(self, base: Tree, snapshot_every: int = 512) -> None:
        StateProjection.__init__(self, base)
        TransitionIndex.__init__(self)
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
        event = (seq, t_ns, tick, scope, key, copy.deepcopy(value), type_name, writer_uid)
        self._keep("write", event)

    def on_mutation(self, mutation: TreeMutation) -> None:
        """Apply and keep a change of the tree."""
        super().on_mutation(mutation)
        self._mutations.append(mutation)
        self._keep("mutation", (mutation,))

    # -- the past --------------------------------------------------------------------
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

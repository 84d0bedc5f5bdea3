"""The history of a recorded run, from its read model (see ``btlog.history``).

Every query is one SQL statement on the run's ``transitions`` table (its rows are in seq
order, so DuckDB's zone maps skip the blocks outside ``lo..hi``), and ``state_after`` is
the read model's snapshot plus a short tail. Nothing is replayed from the start of the
run, whatever the question. A short run (at most ``IN_MEMORY_EVENTS`` events) has its
transitions read once, on the first question, into the same in-memory index the live
history uses: a statement costs about a millisecond, a binary search microseconds. A
longer run reads into such indexes only the spans a caller says it is about to ask about
(``read_ahead``: the story's failures, a page at a time).
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Collection
from typing import Protocol

import duckdb
import orjson

from btlog.history import History, Statuses, Transition, TransitionIndex, Uids, Write
from btlog.replay.moments import RunExtent
from btlog.replay.tables import TRANSITION_CODES, halts_query, starts_condition
from btlog.state import State
from btlog.status import Status
from btlog.tree.model import Tree


class StoredRun(Protocol):
    """What ``SqlHistory`` reads of one stored run (``btlog.replay.run.Run`` is one): a
    protocol, so this module does not import the run that uses it."""

    con: duckdb.DuckDBPyConnection
    catalog: str
    extent: RunExtent

    @property
    def stored_id(self) -> str:
        """The run's id in its tables."""
        ...

    def state_after(self, count: int) -> tuple[Tree, State]:
        """The tree and state after the first ``count`` events."""
        ...


#: Runs with at most this many events are queried in memory (see the module docstring).
IN_MEMORY_EVENTS = 200_000
#: At most this many events are read ahead at once (see ``SqlHistory.read_ahead``).
READ_AHEAD_EVENTS = 1 << 20
#: The first window (events) looked at for a last/first match, and how it grows.
FIRST_WINDOW = 1 << 14
WINDOW_GROWTH = 16


_COLUMNS = "seq, t_ns, uid, prev_code, code"


def _in_list(values: Collection[int]) -> str:
    """A SQL list of integers (only ints are ever written into the statement)."""
    return "(" + ", ".join(str(int(v)) for v in sorted(set(values))) + ")"


#: Where the halts an activation's start may follow are looked for (``starts_condition``).
_HALTS = "h.seq >= $lo - 1 AND h.seq < $hi"


class SqlHistory(History):
    """``History`` over one run of a ``RunDatabase``."""

    def __init__(self, run: StoredRun, in_memory: bool | None = None) -> None:
        self.run = run
        self._table = f"{run.catalog}.{TRANSITION_CODES}"
        if in_memory is None:
            in_memory = run.extent.events <= IN_MEMORY_EVENTS
        self._index: TransitionIndex | None = None
        self._ahead: list[tuple[int, int, TransitionIndex]] = []  # see ``read_ahead``
        self._ahead_uids: frozenset[int] | None = None
        if in_memory:
            self._index = TransitionIndex()
            for row in self._rows("", "ORDER BY seq", {}):
                self._index.add(_transition(row))

    def _rows(self, where: str, tail: str, params: dict, columns: str = _COLUMNS) -> list[tuple]:
        return self.run.con.execute(
            f"SELECT {columns} FROM {self._table} t WHERE run_id = $run_id {where} {tail}",
            {"run_id": self.run.stored_id, **params},
        ).fetchall()

    def select(
        self, kind: str, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool, limit: int
    ) -> list[Transition] | int:
        """See ``Queries.select``: the in-memory index of a short run, else one SQL
        statement."""
        if self._index is not None:
            return self._index.select(kind, uids, statuses, lo, hi, starts, limit)
        if not uids or not statuses or lo >= hi:
            return 0 if kind == "count" else []
        if self._ahead and (self._ahead_uids is None or self._ahead_uids.issuperset(uids)):
            found = self._read_ahead_select(kind, uids, statuses, lo, hi, starts, limit)
            if found is not None:
                return found
        return self._sql_select(kind, uids, statuses, lo, hi, starts, limit)

    def _sql_select(
        self, kind: str, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool, limit: int
    ) -> list[Transition] | int:
        """``select`` as one SQL statement."""
        if lo >= hi:
            return 0 if kind == "count" else []
        where = (
            f"AND seq >= $lo AND seq < $hi AND uid IN {_in_list(uids)} "
            f"AND code IN {_in_list([int(s) for s in statuses])}"
        )
        if starts:
            where += f" AND {starts_condition(halts_query(self._table, _HALTS))}"
        params = {"lo": lo, "hi": hi}
        if kind == "count":
            return int(self._rows(where, "", params, "count(*)")[0][0])
        if kind == "all":
            tail = f"ORDER BY seq LIMIT {int(limit)}"
            return [_transition(row) for row in self._rows(where, tail, params)]
        return self._nearest(kind, where, lo, hi)

    def read_ahead(
        self, spans: Collection[tuple[int, int]], uids: Collection[int] | None = None
    ) -> None:
        """See ``Queries.read_ahead``: the transitions of the spans (merged; at most
        ``READ_AHEAD_EVENTS`` events, the rest left to SQL), of the nodes ``uids`` (or
        all), read in one statement into an in-memory index per merged span. A
        question about those nodes and a span's events is then answered from its index,
        and SQL asked only for what lies before the span (a last match or a count
        reaching back before it) or after it (a first match)."""
        self._ahead = []
        self._ahead_uids = None if uids is None else frozenset(uids)
        if self._index is not None:
            return
        merged: list[list[int]] = []
        budget = READ_AHEAD_EVENTS
        for lo, hi in sorted((max(0, lo), hi) for lo, hi in spans if hi > max(0, lo)):
            if merged and lo <= merged[-1][1]:
                grown = max(merged[-1][1], hi)
                budget -= grown - merged[-1][1]
                merged[-1][1] = grown
            else:
                merged.append([lo, hi])
                budget -= hi - lo
            if budget <= 0:
                break
        if not merged:
            return
        nodes = "" if uids is None else f" AND uid IN {_in_list(uids or [-1])}"
        # each span from one event earlier: whether its first change resumes the halt
        # right before it (``btlog.history.resumes``) is then known, as in SQL
        selects = " UNION ALL ".join(
            f"SELECT {_COLUMNS} FROM {self._table} WHERE run_id = $run_id "
            f"AND seq >= {int(lo) - 1} AND seq < {int(hi)}{nodes}"
            for lo, hi in merged
        )
        rows = self.run.con.execute(
            f"{selects} ORDER BY seq", {"run_id": self.run.stored_id}
        ).fetchall()
        position = 0
        for lo, hi in merged:
            index = TransitionIndex()
            while position < len(rows) and rows[position][0] < hi:
                index.add(_transition(rows[position]))
                position += 1
            self._ahead.append((lo, hi, index))

    def _read_ahead_select(
        self, kind: str, uids: Uids, statuses: Statuses, lo: int, hi: int, starts: bool, limit: int
    ) -> list[Transition] | int | None:
        """``select`` from the span read ahead that holds the query's edge (its end for
        a last match or a count, its start for a first match or all of them), SQL asked
        for the rest; None when no span holds it."""
        edge = lo if kind in ("first", "all") else hi - 1
        at = bisect_right(self._ahead, edge, key=lambda span: span[0]) - 1
        if at < 0 or edge >= self._ahead[at][1]:
            return None
        start, end, index = self._ahead[at]
        if kind == "all":
            return index.select(kind, uids, statuses, lo, hi, starts, limit) if hi <= end else None
        if kind == "first":
            found = index.select(kind, uids, statuses, lo, min(hi, end), starts, limit)
            if found or hi <= end:
                return found
            return self._sql_select(kind, uids, statuses, end, hi, starts, limit)
        found = index.select(kind, uids, statuses, max(lo, start), hi, starts, limit)
        if kind == "count":
            before = self._sql_select(kind, uids, statuses, lo, start, starts, limit)
            assert isinstance(found, int) and isinstance(before, int)
            return found + before
        if found or lo >= start:
            return found
        return self._sql_select(kind, uids, statuses, lo, start, starts, limit)

    def counts(
        self, uids: Collection[int], statuses: Statuses, lo: int, hi: int, starts: bool = False
    ) -> dict[int, int]:
        """See ``Queries.counts``: one SQL statement for every node (the in-memory index
        of a short run, one node at a time)."""
        if self._index is not None or not uids or not statuses or lo >= hi:
            return super().counts(uids, statuses, lo, hi, starts)
        where = (
            f"AND seq >= $lo AND seq < $hi AND uid IN {_in_list(uids)} "
            f"AND code IN {_in_list([int(s) for s in statuses])}"
        )
        if starts:
            where += f" AND {starts_condition(halts_query(self._table, _HALTS))}"
        found = dict(self._rows(where, "GROUP BY uid", {"lo": lo, "hi": hi}, "uid, count(*)"))
        return {uid: int(found.get(uid, 0)) for uid in uids}

    def _nearest(self, kind: str, where: str, lo: int, hi: int) -> list[Transition]:
        """The last (or first) match, looked for in growing windows from ``hi`` back
        (from ``lo`` on): the answer is usually near, and the rows are in seq order,
        so a narrow window reads a few blocks instead of the whole table."""
        tail = "ORDER BY seq DESC LIMIT 1" if kind == "last" else "ORDER BY seq LIMIT 1"
        width = FIRST_WINDOW
        while True:
            window = (max(lo, hi - width), hi) if kind == "last" else (lo, min(hi, lo + width))
            rows = self._rows(where, tail, {"lo": window[0], "hi": window[1]})
            if rows or window == (lo, hi):
                return [_transition(row) for row in rows]
            width *= WINDOW_GROWTH

    def state_after(self, count: int) -> tuple[Tree, State]:
        """See ``History.state_after``: the read model's snapshot and tail."""
        return self.run.state_after(count)

    def _writes(self, where: str, tail: str, params: dict) -> list[Write]:
        rows = self.run.con.execute(
            "SELECT seq, t_ns, scope, key, value, type, writer_uid "
            f"FROM {self.run.catalog}.blackboard WHERE run_id = $run_id "
            f"AND seq >= $lo AND seq < $hi {where} {tail}",
            {"run_id": self.run.stored_id, **params},
        ).fetchall()
        return [
            Write(seq, t_ns, scope, key, None if value is None else orjson.loads(value), kind, who)
            for seq, t_ns, scope, key, value, kind, who in rows
        ]

    def writes_by(self, writer: int, lo: int, hi: int, limit: int) -> list[Write]:
        """See ``History.writes_by``: one SQL statement."""
        params = {"lo": lo, "hi": hi, "writer": writer}
        return self._writes("AND writer_uid = $writer", f"ORDER BY seq LIMIT {int(limit)}", params)

    def last_write(self, scope: str, key: str, lo: int, hi: int) -> Write | None:
        """See ``History.last_write``: one SQL statement."""
        params = {"lo": lo, "hi": hi, "scope": scope, "key": key}
        where = "AND scope = $scope AND key = $key"
        found = self._writes(where, "ORDER BY seq DESC LIMIT 1", params)
        return found[0] if found else None


#: Statuses by value (``Status(value)`` goes through the enum: the hot path of
#: ``read_ahead``).
_STATUSES = tuple(Status)


def _transition(row: tuple) -> Transition:
    seq, t_ns, uid, prev, status = row
    return Transition(seq, t_ns, uid, _STATUSES[prev], _STATUSES[status])

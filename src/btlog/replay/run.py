"""One run of the read model: its tree, moments, states at any moment and timeline.

**The state at a moment.** ``Run.state_at(moment)`` resolves the moment to a number of
events (``btlog.replay.moments``) and reads one row of ``_snapshots``: the state every
``snapshot_every`` events together with the block of events up to the next snapshot. The
snapshots are built a segment at a time, on the first state asked for in the segment's
range (a question in SQL needs only the tables), into a file beside the run's cache
(``Run.snapshots_table``): a first answer at the end of a long run builds the last
segment, not the whole run's. A time or tick is found by a binary search over the
blocks' first events, read from the tables. It folds only the
events of that block up to the moment with ``StateProjection`` — never the run from its
start — so every moment of a long run costs the same: one point query and at most
``snapshot_every`` events. Times and ticks are resolved from the same rows (each knows
the time and tick of its first event). The tree's shape comes from the same fold:
mutations before the snapshot are re-applied to the recorded tree, later ones are folded
with the tail.

Errors are ``ReplayError`` (unknown runs or nodes, events outside the run) or
``MomentError`` (moments), both ``ValueError`` with a one-line message.
"""

from __future__ import annotations

from bisect import bisect_right
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from typing import Any, NamedTuple, Protocol

import duckdb
import orjson

from btlog.replay.blocks import EventBatch
from btlog.replay.moments import (
    BEFORE_END,
    END,
    SEQ,
    TICK,
    TIME,
    WALL,
    Moment,
    Resolved,
    RunExtent,
    parse_moment,
    parse_started_at,
    resolve_moment,
)
from btlog.replay.snapshots import load_mutations, load_snapshot, segment_of, segments
from btlog.replay.sql_history import SqlHistory
from btlog.replay.tables import only_row
from btlog.state import State, StateProjection
from btlog.status import STATUS_NAMES, Status
from btlog.tree.model import Tree

#: A key past every time and tick (the first key of an empty block).
_PAST = 2**63 - 1
#: The seqs a timeline query reads at a time (``Run.iter_timeline``).
TIMELINE_WINDOW = 200_000


class ReplayError(ValueError):
    """A run that cannot be opened or queried as asked; one line naming what is wrong."""


@dataclass(frozen=True)
class RunInfo:
    """One run of a database: the ``runs`` row and what ingestion noticed."""

    run_id: str
    file: str
    tree_name: str
    started_at: datetime | None
    duration_ns: int
    final_status: str | None
    domain: str | None
    seed: int | None
    events: int
    last_tick: int
    truncated: bool
    warnings: tuple[str, ...]
    metadata: dict


class TimelineEntry(NamedTuple):
    """One event of a timeline: a status change (``kind == "status"``), a blackboard
    write (``"write"``: ``uid`` is the writer) or a tree mutation (``"mutation"``: ``uid``
    is the inserted subtree's root)."""

    seq: int
    t_ns: int
    tick: int
    kind: str
    uid: int | None
    node: str | None
    prev_status: str | None
    status: str | None
    scope: str | None
    key: str | None
    value: Any


class Database(Protocol):
    """What a ``Run`` uses of the database holding it (``btlog.replay.database.RunDatabase``
    is one): a protocol, so this module does not import the database that opens it."""

    con: duckdb.DuckDBPyConnection

    def snapshots_of(self, catalog: str, segment: int) -> str:
        """The qualified name of the ``_snapshots`` table holding segment ``segment`` of
        the snapshots of the run in ``catalog``."""
        ...


class Run:
    """One run of a ``RunDatabase``: its tree, moments, states and timeline.

    Snapshot rows are read on demand (one point query each) and the last few are kept
    decoded, so nearby moments cost no query at all.
    """

    CACHED_BLOCKS = 8

    def __init__(self, database: Database, catalog: str, run_id: str, path: str) -> None:
        self.con = database.con
        self.catalog = catalog
        self.run_id = run_id
        self._prefix = f"{catalog}."
        row = only_row(
            self.con,
            f"SELECT run_id, events, last_tick, truncated, warnings, snapshot_every, "
            f"tree FROM {catalog}._ingest",
        )
        self._stored_id, events, last_tick, truncated, warnings, every, tree = row
        self.snapshot_every = every
        self.tree = Tree.from_description(orjson.loads(tree))
        self.mutations = load_mutations(self.con, self._stored_id, self._prefix)
        self.info = self._info(path, events, last_tick, truncated, orjson.loads(warnings))
        self._database = database
        #: the ``_snapshots`` table of each segment built or attached so far
        self._snapshots: dict[int, str] = {}
        #: time and tick of the first event of the blocks looked at (``_FirstKeys``)
        self._keys = {"t_ns": _FirstKeys(self, 0), "tick": _FirstKeys(self, 1)}
        self._blocks: OrderedDict[int, tuple[dict, EventBatch]] = OrderedDict()
        started_ns, zone = parse_started_at(self.info.metadata.get("started_at"))
        self.extent = RunExtent(
            events,
            self.info.duration_ns,
            last_tick,
            started_ns,
            self._count_at,
            self._count_after_tick,
            self._keys_of,
            self._tick_end,
            self._tick_at,
            zone,
        )

    def _info(
        self, path: str, events: int, last_tick: int, truncated: bool, warnings: list
    ) -> RunInfo:
        """The run's info, naming the recording as opened now (the cache may have been
        built from a copy of it elsewhere)."""
        row = only_row(
            self.con,
            f"SELECT file, tree_name, started_at, duration_ns, final_status, domain, "
            f"seed, metadata FROM {self.catalog}.runs",
        )
        built_from, tree_name, started_at, duration, final, domain, seed, metadata = row
        return RunInfo(
            self.run_id,
            path,
            tree_name,
            started_at,
            duration,
            final,
            domain,
            seed,
            events,
            last_tick,
            truncated,
            tuple(warning.replace(built_from, path) for warning in warnings),
            orjson.loads(metadata),
        )

    def __repr__(self) -> str:
        return f"<Run {self.run_id} {self.info.file} {self.info.events} events>"

    @property
    def stored_id(self) -> str:
        """The run id as stored in this run's own tables."""
        return self._stored_id

    def history(self) -> SqlHistory:
        """The run's history for the explanations (queries on the read model)."""
        return SqlHistory(self)

    # -- snapshot blocks -----------------------------------------------------------------
    def snapshots_table(self, segment: int | None = None) -> str:
        """What to read the run's ``_snapshots`` rows from (in SQL, after ``FROM``): the
        table of ``segment``, built on its first use (a question in SQL never needs
        them), then reused; or, when ``segment`` is None, every segment's (all built)."""
        if segment is None:
            every = self.snapshot_every
            tables = dict.fromkeys(
                self.snapshots_table(n) for n in range(segments(self.extent.events, every))
            )
            if len(tables) == 1:
                return next(iter(tables))
            return "(" + " UNION ALL ".join(f"SELECT * FROM {t}" for t in tables) + ")"
        found = self._snapshots.get(segment)
        if found is None:
            found = self._snapshots[segment] = self._database.snapshots_of(self.catalog, segment)
        return found

    def first_keys(self, index: int) -> tuple[int, int]:
        """(time, tick) of the first event of snapshot ``index``'s block (``_PAST`` for
        both when the block is empty), read from the tables (a point query on seq)."""
        p, lo, hi = self._prefix, index * self.snapshot_every, (index + 1) * self.snapshot_every
        where = "WHERE run_id = $run_id AND seq >= $lo AND seq < $hi"
        found = self.con.execute(
            f"""SELECT t_ns, tick FROM (
                SELECT seq, t_ns, tick FROM {p}transitions {where}
                UNION ALL SELECT seq, t_ns, tick FROM {p}blackboard {where}
                UNION ALL SELECT seq, t_ns, tick FROM {p}_mutations {where})
            ORDER BY seq LIMIT 1""",
            {"run_id": self._stored_id, "lo": lo, "hi": hi},
        ).fetchall()
        return (found[0][0], found[0][1]) if found else (_PAST, _PAST)

    def _block(self, index: int) -> tuple[dict, EventBatch]:
        """Snapshot ``index``: the state before event ``index * snapshot_every`` (as JSON)
        and the events up to the next snapshot."""
        cached = self._blocks.get(index)
        if cached is not None:
            self._blocks.move_to_end(index)
            return cached
        seq = index * self.snapshot_every
        state, events = only_row(
            self.con,
            f"SELECT state, events FROM {self.snapshots_table(segment_of(index))} "
            f"WHERE run_id = $run_id AND seq = $seq",
            {"run_id": self._stored_id, "seq": seq},
        )
        mutations = [m for m in self.mutations if seq <= m.seq < seq + self.snapshot_every]
        snapshot = load_snapshot(self.con, self._stored_id, state, self._prefix)
        block = (snapshot, EventBatch.from_block(events, mutations))
        self._blocks[index] = block
        if len(self._blocks) > self.CACHED_BLOCKS:
            self._blocks.popitem(last=False)
        return block

    # -- moments -------------------------------------------------------------------------
    def resolve(self, moment: str | Moment) -> Resolved:
        """The moment as a number of events to apply (MomentError when outside the run)."""
        return resolve_moment(moment, self.extent)

    def _count_where(self, attribute: str, limit: int) -> int:
        """Events whose ``t_ns`` (or ``tick``) is at most ``limit``. Both never decrease
        along seq, so the blocks' first keys find the one block to count in."""
        index = bisect_right(self._keys[attribute], limit) - 1
        if index < 0:
            return 0
        _state, batch = self._block(index)
        bound = batch.bound_at_most(attribute, limit)
        return index * self.snapshot_every if bound is None else bound

    def _count_at(self, t_ns: int) -> int:
        return self._count_where("t_ns", t_ns)

    def _count_after_tick(self, tick: int) -> int:
        return self._count_where("tick", tick)

    def _keys_of(self, count: int) -> tuple[int, int]:
        """(time, tick) of event ``count - 1`` ((0, 0) before any event)."""
        if count <= 0:
            return 0, 0
        _state, batch = self._block((count - 1) // self.snapshot_every)
        keys = batch.keys_of(count - 1)
        return (0, 0) if keys is None else keys

    def _tick_end(self, tick: int) -> int | None:
        """The end time of the last recorded tick up to ``tick`` (None if none)."""
        return self.con.execute(
            f"SELECT arg_max(end_ns, tick) FROM {self._prefix}ticks "
            "WHERE run_id = $run_id AND tick <= $tick",
            {"run_id": self._stored_id, "tick": tick},
        ).fetchone()[0]  # type: ignore[index]

    def _tick_at(self, t_ns: int) -> int:
        """The last tick that started at or before ``t_ns`` (0 if none did)."""
        found = self.con.execute(
            f"SELECT max(tick) FROM {self._prefix}ticks "
            "WHERE run_id = $run_id AND start_ns <= $t_ns",
            {"run_id": self._stored_id, "t_ns": t_ns},
        ).fetchone()
        return 0 if found is None or found[0] is None else int(found[0])

    def ticks_run(self) -> int:
        """How many ticks the tree ran: its last tick, the teardown not counted (the
        number ``btlog run`` prints; ticks with no event count too)."""
        found = self.con.execute(
            f"SELECT max(tick) FROM {self._prefix}ticks WHERE run_id = $run_id AND NOT teardown",
            {"run_id": self._stored_id},
        ).fetchone()
        return 0 if found is None or found[0] is None else int(found[0])

    # -- states --------------------------------------------------------------------------
    def state_at(self, moment: str | Moment) -> tuple[Tree, State]:
        """(tree, state) at ``moment``: the tree's shape and every node's status, retry
        counts, the blackboard… after all events up to it."""
        return self.state_after(self.resolve(moment).count)

    def tree_at(self, moment: str | Moment) -> Tree:
        """The tree's shape at ``moment`` (mutations up to then applied)."""
        return self.state_at(moment)[0]

    def state_after(self, count: int) -> tuple[Tree, State]:
        """(tree, state) after the first ``count`` events: the snapshot at or before
        ``count`` plus the events between, folded with ``StateProjection``."""
        if not 0 <= count <= self.extent.events:
            raise ReplayError(
                f"run {self.run_id} has {self.extent.events} events; cannot apply {count}"
            )
        index = count // self.snapshot_every
        start = index * self.snapshot_every
        snapshot, batch = self._block(index)
        earlier = [m for m in self.mutations if m.seq < start]
        projection = StateProjection(self.tree, State.from_json(snapshot, earlier))
        batch.fold(projection, start, count)
        return projection.tree, projection.state

    # -- timeline ------------------------------------------------------------------------
    def timeline(
        self,
        node: int | str | None = None,
        status: str | Status | None = None,
        start: str | Moment | None = None,
        end: str | Moment | None = None,
    ) -> list[TimelineEntry]:
        """The events from ``start`` (at or after it) to ``end`` (up to it), in seq order.

        ``node`` (a uid, or a name, type or path as in outcomes files) keeps that node's
        status changes, its writes and the mutations inserting it; ``status`` keeps the
        status changes to that status. A list (``iter_timeline`` streams them).
        """
        return list(self.iter_timeline(node, status, start, end))

    def iter_timeline(
        self,
        node: int | str | None = None,
        status: str | Status | None = None,
        start: str | Moment | None = None,
        end: str | Moment | None = None,
    ) -> Iterator[TimelineEntry]:
        """``timeline``'s events one at a time, read ``TIMELINE_WINDOW`` seqs a query, so a
        run's whole timeline is printed in bounded memory (the filters are checked before
        the first one comes)."""
        lo = 0 if start is None else self._first_at(parse_moment(start))
        hi = self.extent.events if end is None else self.resolve(end).count
        uids = None if node is None else self._node_uids(node)
        wanted = None if status is None else _status_name(status)
        return self._timeline_windows(lo, hi, uids, wanted)

    def _timeline_windows(
        self, lo: int, hi: int, uids: list[int] | None, wanted: str | None
    ) -> Iterator[TimelineEntry]:
        query = self._timeline_query(uids is not None, wanted is not None)
        names = {n.uid: n.description for n in self.final_tree()}
        for low in range(lo, hi, TIMELINE_WINDOW):
            params = self._timeline_params(low, min(hi, low + TIMELINE_WINDOW), uids, wanted)
            for seq, t, tick, kind, uid, prev, new, scope, key, value in self.con.execute(
                query, params
            ).fetchall():
                yield TimelineEntry(
                    seq,
                    t,
                    tick,
                    kind,
                    uid,
                    names.get(uid),
                    prev,
                    new,
                    scope,
                    key,
                    None if value is None else orjson.loads(value),
                )

    def _first_at(self, moment: Moment) -> int:
        """The first event at or after a start moment."""
        resolved = resolve_moment(moment, self.extent)
        if moment.kind == SEQ:
            return moment.value
        if moment.kind == TICK:
            return self._count_after_tick(moment.value - 1)
        if moment.kind == END:
            return resolved.count
        assert moment.kind in (TIME, BEFORE_END, WALL)
        return self._count_at(resolved.t_ns - 1)

    def _timeline_query(self, by_node: bool, by_status: bool) -> str:
        p = self._prefix
        node = " AND list_contains($uids, {c})" if by_node else ""
        range_ = "run_id = $run_id AND seq >= $lo AND seq < $hi"
        status = " AND status = $status" if by_status else ""
        parts = [
            f"""SELECT seq, t_ns, tick, 'status' AS kind, uid, prev_status::VARCHAR,
                status::VARCHAR, NULL, NULL, NULL FROM {p}transitions
                WHERE {range_}{node.format(c="uid")}{status}"""
        ]
        if not by_status:
            parts.append(f"""SELECT seq, t_ns, tick, 'write', writer_uid, NULL, NULL, scope,
                key, value::VARCHAR FROM {p}blackboard WHERE {range_}
                {node.format(c="writer_uid")}""")
            parts.append(f"""SELECT seq, t_ns, tick, 'mutation',
                (message -> 'nodes' -> 0 ->> 'uid')::INTEGER, NULL, NULL, NULL, NULL, NULL
                FROM {p}_mutations WHERE {range_}
                {node.format(c="(message -> 'nodes' -> 0 ->> 'uid')::INTEGER")}""")
        return " UNION ALL ".join(parts) + " ORDER BY seq"

    def _timeline_params(
        self, lo: int, hi: int, uids: list[int] | None, status: str | None
    ) -> dict:
        params: dict[str, Any] = {"run_id": self._stored_id, "lo": lo, "hi": hi}
        if uids is not None:
            params["uids"] = uids
        if status is not None:
            params["status"] = status
        return params

    def final_tree(self) -> Tree:
        """The run's tree with every recorded mutation applied (each node knows when it
        was added); a copy, the recorded tree is left as it is."""
        return StateProjection(self.tree, State(mutations=list(self.mutations))).tree

    def _node_uids(self, node: int | str) -> list[int]:
        tree = self.final_tree()
        if isinstance(node, int) or (isinstance(node, str) and node.isdigit()):
            if int(node) in tree.nodes:
                return [int(node)]
            raise ReplayError(f"run {self.run_id} has no node with uid {node}")
        # a path, a name, a nameless node's type; else a type names every node of it
        found = tree.lookup(str(node)) or [n for n in tree if n.type == node]
        if not found:
            raise ReplayError(
                f"no node of run {self.run_id} matches {node!r} "
                "(a name, a type of nameless nodes, or a path)"
            )
        return [n.uid for n in found]

    # -- answers asked live ---------------------------------------------------------------
    def answers(self) -> list[dict]:
        """The questions asked live during the run and their recorded answers."""
        rows = self.con.execute(
            f"SELECT seq, t_ns, tick, question, intent, answer FROM {self._prefix}_answers "
            f"WHERE run_id = $run_id ORDER BY seq",
            {"run_id": self._stored_id},
        ).fetchall()
        keys = ("seq", "t_ns", "tick", "question", "intent", "answer")
        return [dict(zip(keys, row, strict=True)) for row in rows]


class _FirstKeys:
    """The time (``column`` 0) or tick (1) of the first event of each snapshot's block,
    as a sequence that ``bisect`` searches: each is read from the tables when first
    looked at (``Run.first_keys``), so a search costs a few point queries."""

    def __init__(self, run: Run, column: int) -> None:
        self.run = run
        self.column = column
        self.known: dict[int, int] = {}

    def __len__(self) -> int:
        return self.run.extent.events // self.run.snapshot_every + 1

    def __getitem__(self, index: int) -> int:
        found = self.known.get(index)
        if found is None:
            found = self.known[index] = self.run.first_keys(index)[self.column]
        return found


def _status_name(status: str | Status) -> str:
    if isinstance(status, Status):
        return status.name
    name = str(status).strip().upper()
    if name not in STATUS_NAMES:
        raise ReplayError(f"unknown status {status!r} (expected one of {', '.join(STATUS_NAMES)})")
    return name

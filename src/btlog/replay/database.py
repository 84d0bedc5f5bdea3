"""The read model as a Python API: open runs, the state at any moment, the timeline, SQL.

``open_runs(*paths)`` gives a ``RunDatabase``: one DuckDB connection in which every run
is a *catalog* of its own (the tables of docs/design.md, "The read model", plus the
snapshots), and the main schema holds views named like the tables (``runs``, ``nodes``,
``transitions``, ``blackboard``, ``ticks``, ``mutations``) that union all the runs,
``run_id`` in every row. Users write SQL against those views; ``Run`` objects query
their own catalog.

**The cache.** Each recording's catalog is a DuckDB file in the user's cache folder,
keyed by the recording's content (``btlog.replay.cache``), attached read-only so SQL
cannot damage it. Several runs are *attached*, not copied: opening a second cached run
costs milliseconds whatever its size. When the cache folder cannot be written, the run
is ingested in memory instead and ``notices`` says so; with ``cache=False`` every run is
ingested into an in-memory catalog.

**The state at a moment.** ``Run.state_at(moment)`` resolves the moment to a number of
events (``btlog.replay.moments``) and reads one row of ``_snapshots``: the state every
``snapshot_every`` events together with the block of events up to the next snapshot. The
snapshots are built on the first state asked for (a question in SQL needs only the
tables), into a file beside the run's cache (``Run.snapshots_table``). It folds only the
events of that block up to the moment with ``StateProjection`` — never the run from its
start — so every moment of a long run costs the same: one point query and at most
``snapshot_every`` events. Times and ticks are resolved from the same rows (each knows
the time and tick of its first event). The tree's shape comes from the same fold:
mutations before the snapshot are re-applied to the recorded tree, later ones are folded
with the tail.

Errors are ``ReplayError`` (unreadable recordings, unknown runs or nodes, bad SQL) or
``MomentError`` (moments), both ``ValueError`` with a one-line message.
"""

from __future__ import annotations

import os
import re
from bisect import bisect_right
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, NamedTuple

import duckdb
import orjson

from btlog.errors import one_line
from btlog.record.reader import RecordingError
from btlog.replay import cache
from btlog.replay import ingest as ingestion
from btlog.replay.moments import (
    BEFORE_END,
    END,
    SEQ,
    TICK,
    TIME,
    WALL,
    Moment,
    MomentError,
    Resolved,
    RunExtent,
    parse_moment,
    parse_started_at,
    resolve_moment,
)
from btlog.replay.snapshots import (
    DEFAULT_SNAPSHOT_EVERY,
    EventBatch,
    load_mutations,
    load_snapshot,
)
from btlog.replay.sql_history import SqlHistory
from btlog.replay.tables import INGEST_VERSION, PUBLIC_TABLES, create_schema, only_row
from btlog.state import State, StateProjection
from btlog.status import STATUS_NAMES, Status
from btlog.tree.model import Tree

CACHE_SUFFIX = ".duckdb"
#: What a run id may hold (it is written into the views' SQL).
_SAFE_ID = re.compile(r"[A-Za-z0-9_]{1,64}")
#: A key past every time and tick (the first key of an empty block).
_PAST = 2**63 - 1


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


# -- opening ------------------------------------------------------------------------------
def open_runs(
    *paths: str | os.PathLike,
    cache: bool = True,
    snapshot_every: int = DEFAULT_SNAPSHOT_EVERY,
    cache_dir: str | os.PathLike | None = None,
) -> RunDatabase:
    """Open one or many recordings in one database (see the module docstring).

    ``cache_dir`` puts the caches there instead of beside the recordings.
    Raises ``ReplayError`` naming the file when one cannot be read.
    """
    if not paths:
        raise ReplayError("open_runs needs at least one recording")
    database = RunDatabase(snapshot_every)
    try:
        for path in dict.fromkeys(os.path.abspath(os.fspath(p)) for p in paths):
            database.add(path, cache=cache, cache_dir=cache_dir)
    except BaseException:
        database.close()
        raise
    return database


def cache_location(
    recording: str | os.PathLike,
    cache_dir: str | os.PathLike | None = None,
    snapshot_every: int = DEFAULT_SNAPSHOT_EVERY,
) -> Path:
    """Where the cache of ``recording`` (as its content is now) lives."""
    return cache.cache_path(recording, snapshot_every, cache_dir)


# -- the database ---------------------------------------------------------------------------
class RunDatabase:
    """Several runs in one DuckDB connection (build it with ``open_runs``)."""

    def __init__(self, snapshot_every: int = DEFAULT_SNAPSHOT_EVERY) -> None:
        self.con = duckdb.connect()
        self.snapshot_every = snapshot_every
        self.ingested: list[ingestion.IngestReport] = []
        #: one-line notices for the user (e.g. a cache folder that cannot be written)
        self.notices: list[str] = []
        self._runs: list[Run] = []
        self._attached: set[Path] = set()
        #: the cache file of each run's catalog (none for a run read into memory)
        self._caches: dict[str, Path] = {}
        #: True once ``lock`` made user SQL read-only
        self.locked = False

    # -- adding runs ---------------------------------------------------------------------
    def add(
        self,
        path: str | os.PathLike,
        cache: bool = True,
        cache_dir: str | os.PathLike | None = None,
    ) -> Run:
        """Open one more recording (from its cache when valid) and return its run."""
        if self.locked:
            raise ReplayError("this database is locked for user SQL; open runs before lock()")
        name = os.path.abspath(os.fspath(path))
        catalog = f"run{len(self._runs)}"
        try:
            if cache:
                self._attach_cached(name, catalog, cache_dir)
            else:
                self._ingest_in_memory(name, catalog)
        except RecordingError as error:
            raise ReplayError(str(error)) from None
        except OSError as error:
            raise ReplayError(f"{name}: cannot read: {error.strerror or error}") from None
        except duckdb.Error as error:
            raise ReplayError(f"{name}: cannot build its read model: {one_line(error)}") from None
        run = Run(self, catalog, self._unique_id(catalog), name)
        self._runs.append(run)
        self._create_views()
        return run

    def _attach_cached(self, path: str, catalog: str, cache_dir: str | os.PathLike | None) -> None:
        """Attach the recording's cache, building it first unless it exists. When the
        cache folder cannot be written, the run is ingested in memory (with a notice)."""
        root = cache.cache_root(cache_dir)
        for folder in (root, Path(path).parent):
            cache.remove_leftovers(folder)
        place = cache.cache_path(path, self.snapshot_every, cache_dir)
        if self._attach_if_current(place, catalog, path):
            cache.touch(place)
            self._caches[catalog] = place
            return
        try:
            self.ingested.append(cache.build(path, place, self.snapshot_every))
        except (OSError, duckdb.IOException) as error:
            if not os.access(path, os.R_OK):
                raise
            reason = getattr(error, "strerror", None) or one_line(error)
            self.notices.append(
                f"cannot write the cache folder {root} ({reason}); "
                f"{Path(path).name} is read into memory instead"
            )
            self._ingest_in_memory(path, catalog)
            return
        self.con.execute(f"ATTACH $path AS {catalog} (READ_ONLY)", {"path": str(place)})
        self._attached.add(place)
        self._caches[catalog] = place
        cache.evict(root, cache.max_bytes(), self._attached)

    def snapshots_of(self, catalog: str) -> str:
        """The qualified name of the ``_snapshots`` table of the run in ``catalog``,
        built on first use: into the run's own catalog for a run read into memory, else
        into a file beside its cache (``cache.snapshots_path``), attached read-only; in
        memory when that file cannot be written."""
        place = self._caches.get(catalog)
        if place is None:
            table = f"{catalog}._snapshots"
            if only_row(self.con, f"SELECT count(*) FROM {table}")[0] == 0:
                ingestion.snapshots_into(self.con, table, catalog)
            return table
        name = f"{catalog}_snapshots"
        target = cache.snapshots_path(place)
        if not self._attach_snapshots(target, name):
            try:
                cache.build_snapshots(place, target)
            except (OSError, duckdb.IOException) as error:
                reason = getattr(error, "strerror", None) or one_line(error)
                self.notices.append(
                    f"cannot write the cache folder {target.parent} ({reason}); "
                    "the snapshots are built in memory instead"
                )
                self.con.execute(f"ATTACH ':memory:' AS {name}")
                self.con.execute(
                    f"CREATE TABLE {name}._snapshots AS FROM {catalog}._snapshots LIMIT 0"
                )
                ingestion.snapshots_into(self.con, f"{name}._snapshots", catalog)
                return f"{name}._snapshots"
            if not self._attach_snapshots(target, name):
                raise ReplayError(f"{target}: cannot read the snapshots just built")
            cache.evict(place.parent, cache.max_bytes(), self._attached)
        cache.touch(target)
        return f"{name}._snapshots"

    def _attach_snapshots(self, target: Path, name: str) -> bool:
        """Attach the snapshot file ``target`` as catalog ``name`` if it can be read."""
        if not target.is_file():
            return False
        try:
            self.con.execute(f"ATTACH $path AS {name} (READ_ONLY)", {"path": str(target)})
            self.con.execute(f"SELECT count(*) FROM {name}._snapshots").fetchall()
        except duckdb.Error:
            self.con.execute(f"DETACH DATABASE IF EXISTS {name}")
            return False
        self._attached.add(target)
        return True

    def _attach_if_current(self, place: Path, catalog: str, path: str) -> bool:
        """Attach the cache ``place`` if it exists and is complete and current (its
        name holds the recording's hash; the layout and interval are checked here)."""
        if not place.is_file():
            return False
        try:
            self.con.execute(f"ATTACH $path AS {catalog} (READ_ONLY)", {"path": str(place)})
        except duckdb.Error:
            return False
        try:
            rows = self.con.execute(
                f"SELECT size, ingest_version, snapshot_every FROM {catalog}._ingest"
            ).fetchall()
        except duckdb.Error:
            rows = []
        if rows == [(os.stat(path).st_size, INGEST_VERSION, self.snapshot_every)]:
            self._attached.add(place)
            return True
        self.con.execute(f"DETACH {catalog}")
        return False

    def _ingest_in_memory(self, path: str, catalog: str) -> None:
        self.con.execute(f"ATTACH ':memory:' AS {catalog}")
        self.con.execute(f"USE {catalog}")
        try:
            create_schema(self.con)
            self.ingested.append(
                ingestion.ingest(
                    self.con, path, snapshot_every=self.snapshot_every, snapshots=False
                )
            )
        except BaseException:
            self.con.execute("USE memory")
            self.con.execute(f"DETACH {catalog}")
            raise
        self.con.execute("USE memory")

    def _unique_id(self, catalog: str) -> str:
        """The run's id, with a suffix when another open run has it already."""
        (stored,) = only_row(self.con, f"SELECT run_id FROM {catalog}._ingest")
        if not _SAFE_ID.fullmatch(stored):  # ids go into view definitions
            stored = catalog
        taken = {run.run_id for run in self._runs}
        run_id, number = stored, 1
        while run_id in taken:
            number += 1
            run_id = f"{stored}_{number}"
        return run_id

    def _create_views(self) -> None:
        """The public tables as views over every run's catalog (run ids made unique)."""
        for table in PUBLIC_TABLES:
            parts = [
                f"SELECT * REPLACE ('{run.run_id}' AS run_id{_file_column(table, run)}) "
                f"FROM {run.catalog}.{table}"
                for run in self._runs
            ]
            self.con.execute(
                f"CREATE OR REPLACE VIEW memory.main.{table} AS " + " UNION ALL ".join(parts)
            )

    # -- using it ------------------------------------------------------------------------
    @property
    def runs(self) -> list[RunInfo]:
        """Every run, in the order they were opened."""
        return [run.info for run in self._runs]

    def run(self, key: str | os.PathLike | None = None) -> Run:
        """A run by run id or by recording path (the only run when ``key`` is None)."""
        if key is None:
            if len(self._runs) == 1:
                return self._runs[0]
            raise ReplayError(f"{len(self._runs)} runs are open; name one by run id or path")
        for run in self._runs:
            if run.run_id == str(key):
                return run
        path = os.path.abspath(os.fspath(key))
        for run in self._runs:
            if run.info.file == path:
                return run
        known = ", ".join(run.run_id for run in self._runs)
        raise ReplayError(f"no run {str(key)!r} in this database (runs: {known})")

    def lock(self) -> None:
        """Make the connection safe for SQL from anyone: ``sql`` then runs only queries
        (``SELECT`` in any form, ``EXPLAIN``: no ``DETACH``/``ATTACH``, ``DELETE``,
        ``COPY``, ``INSTALL``…), with no file or network access (DuckDB's
        ``enable_external_access``: no ``read_csv``, ``glob``) and no setting that can
        change any more (``lock_configuration``). The runs' caches stay attached
        read-only, so no query can change a later answer. No run can be added afterwards."""
        self.con.execute("SET enable_external_access = false")
        self.con.execute("SET lock_configuration = true")
        self.locked = True

    def sql(
        self, query: str, params: Sequence | dict | None = None
    ) -> tuple[list[str], list[tuple]]:
        """Run ``query`` (with ``params`` bound to its ``?`` or ``$name`` placeholders);
        returns (column names, rows). Once ``lock``ed, only queries are run."""
        try:
            if self.locked:
                only_queries(self.con, query)
            cursor = (
                self.con.execute(query, params) if params is not None else self.con.execute(query)
            )
            if cursor is None:  # DuckDB's answer to a query without a statement
                raise ReplayError(f"SQL error: no statement in {query!r}")
            columns = [d[0] for d in cursor.description or ()]
            rows = cursor.fetchall() if cursor.description else []
        except duckdb.Error as error:
            raise ReplayError(f"SQL error: {one_line(error)}") from None
        return columns, rows

    def close(self) -> None:
        """Close the connection (the caches stay on disk)."""
        self.con.close()

    def __enter__(self) -> RunDatabase:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def only_queries(con: duckdb.DuckDBPyConnection, query: str) -> None:
    """ReplayError unless every statement of ``query`` is a query (SELECT, or EXPLAIN
    without ANALYZE, which would run the statement)."""
    for statement in con.extract_statements(query):
        kind = statement.type
        analyze = kind == duckdb.StatementType.EXPLAIN and re.match(
            r"\s*EXPLAIN\s+ANALY[SZ]E\b", statement.query, re.IGNORECASE
        )
        if kind not in (duckdb.StatementType.SELECT, duckdb.StatementType.EXPLAIN) or analyze:
            name = "EXPLAIN ANALYZE" if analyze else kind.name
            raise ReplayError(f"SQL error: btlog sql runs read-only queries; {name} is refused")


def _file_column(table: str, run: Run) -> str:
    """The ``runs`` table names the recording as opened now (a cache is shared by every
    copy of a recording)."""
    if table != "runs":
        return ""
    return ", '" + run.info.file.replace("'", "''") + "' AS file"


# -- one run --------------------------------------------------------------------------------
class Run:
    """One run of a ``RunDatabase``: its tree, moments, states and timeline.

    Snapshot rows are read on demand (one point query each) and the last few are kept
    decoded, so nearby moments cost no query at all.
    """

    CACHED_BLOCKS = 8

    def __init__(self, database: RunDatabase, catalog: str, run_id: str, path: str) -> None:
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
        self._snapshots: str | None = None
        #: time and tick of the first event of each block (past the end for an empty one)
        self._keys: dict[str, list[int]] | None = None
        self._blocks: OrderedDict[int, tuple[dict, EventBatch]] = OrderedDict()
        started_ns, zone = parse_started_at(self.info.metadata.get("started_at"))
        self.extent = RunExtent(
            events,
            self.info.duration_ns,
            last_tick,
            started_ns,
            self._count_at,
            self._count_after_tick,
            self._time_of,
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
    def snapshots_table(self) -> str:
        """The qualified name of the run's ``_snapshots`` table. The snapshots are built
        on the first call (a question in SQL never needs them), then reused."""
        if self._snapshots is None:
            self._snapshots = self._database.snapshots_of(self.catalog)
        return self._snapshots

    @property
    def _first_keys(self) -> dict[str, list[int]]:
        """Time and tick of the first event of each snapshot's block."""
        if self._keys is None:
            rows = self.con.execute(
                f"SELECT first_t_ns, first_tick FROM {self.snapshots_table()} "
                "WHERE run_id = $run_id ORDER BY seq",
                {"run_id": self._stored_id},
            ).fetchall()
            self._keys = {
                "t_ns": [_PAST if r[0] is None else r[0] for r in rows],
                "tick": [_PAST if r[1] is None else r[1] for r in rows],
            }
        return self._keys

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
            f"SELECT state, events FROM {self.snapshots_table()} "
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
        index = bisect_right(self._first_keys[attribute], limit) - 1
        if index < 0:
            return 0
        _state, batch = self._block(index)
        bound = batch.bound_at_most(attribute, limit)
        return index * self.snapshot_every if bound is None else bound

    def _count_at(self, t_ns: int) -> int:
        return self._count_where("t_ns", t_ns)

    def _count_after_tick(self, tick: int) -> int:
        return self._count_where("tick", tick)

    def _time_of(self, count: int) -> int:
        """The time of event ``count - 1`` (0 before any event)."""
        if count <= 0:
            return 0
        _state, batch = self._block((count - 1) // self.snapshot_every)
        keys = batch.keys_of(count - 1)
        return 0 if keys is None else keys[0]

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
        status changes to that status.
        """
        lo = 0 if start is None else self._first_at(parse_moment(start))
        hi = self.extent.events if end is None else self.resolve(end).count
        uids = None if node is None else self._node_uids(node)
        wanted = None if status is None else _status_name(status)
        rows = self.con.execute(
            self._timeline_query(uids is not None, wanted is not None),
            self._timeline_params(lo, hi, uids, wanted),
        ).fetchall()
        names = {n.uid: n.description for n in self._final_tree()}
        return [
            TimelineEntry(
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
            for seq, t, tick, kind, uid, prev, new, scope, key, value in rows
        ]

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

    def _final_tree(self) -> Tree:
        tree = Tree.from_description(self.tree.describe())
        projection = StateProjection(tree, State(mutations=list(self.mutations)))
        return projection.tree

    def _node_uids(self, node: int | str) -> list[int]:
        tree = self._final_tree()
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


def _status_name(status: str | Status) -> str:
    if isinstance(status, Status):
        return status.name
    name = str(status).strip().upper()
    if name not in STATUS_NAMES:
        raise ReplayError(f"unknown status {status!r} (expected one of {', '.join(STATUS_NAMES)})")
    return name


__all__ = [
    "MomentError",
    "ReplayError",
    "Run",
    "RunDatabase",
    "RunInfo",
    "TimelineEntry",
    "cache_location",
    "open_runs",
]

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

A ``Run`` of the database (``btlog.replay.run``) gives the state at any moment and the
timeline.

Errors are ``ReplayError`` (unreadable recordings, unknown runs or nodes, bad SQL) or
``MomentError`` (moments), both ``ValueError`` with a one-line message.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import duckdb

from btlog.errors import one_line
from btlog.record.walk import RecordingError
from btlog.replay import cache
from btlog.replay.connections import connect
from btlog.replay.deadline import QueryTimeout, time_limit
from btlog.replay.moments import MomentError
from btlog.replay.run import ReplayError, Run, RunInfo, TimelineEntry
from btlog.replay.snapshots import DEFAULT_SNAPSHOT_EVERY
from btlog.replay.tables import INGEST_VERSION, PUBLIC_TABLES, create_schema, literal, only_row

if TYPE_CHECKING:  # ingestion (and pyarrow) is imported when a run is read, not when cached
    from btlog.replay import ingest as ingestion

#: Rows a streamed query reads at a time (``query_rows``).
FETCH_ROWS = 10_000

CACHE_SUFFIX = ".duckdb"
#: What a run id may hold (it is written into the views' SQL).
_SAFE_ID = re.compile(r"[A-Za-z0-9_]{1,64}")


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
        self.con = connect(sandbox=True)
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

    def snapshots_of(self, catalog: str, segment: int) -> str:
        """The qualified name of the ``_snapshots`` table holding segment ``segment`` of
        the snapshots of the run in ``catalog`` (``btlog.replay.snapshots.segment_of``),
        built on first use: every segment at once into the run's own catalog for a run
        read into memory, else the segment into a file beside its cache
        (``cache.snapshots_path``), attached read-only; in memory when that file cannot
        be written."""
        place = self._caches.get(catalog)
        if place is None:
            table = f"{catalog}._snapshots"
            if only_row(self.con, f"SELECT count(*) FROM {table}")[0] == 0:
                from btlog.replay import ingest as ingestion

                ingestion.snapshots_into(self.con, table, catalog)
            return table
        name = f"{catalog}_snapshots{segment}"
        target = cache.snapshots_path(place, segment)
        if not self._attach_snapshots(target, name):
            try:
                cache.build_snapshots(place, target, segment)
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
                from btlog.replay import ingest as ingestion

                ingestion.snapshots_into(self.con, f"{name}._snapshots", catalog, segment=segment)
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
        # A run with a large state has its snapshots further apart than asked
        # (``snapshot_interval``); the cache's name holds the interval asked for.
        if (
            len(rows) == 1
            and rows[0][:2] == (os.stat(path).st_size, INGEST_VERSION)
            and rows[0][2] >= self.snapshot_every
            and self._transitions_readable(catalog)
        ):
            self._attached.add(place)
            return True
        self.con.execute(f"DETACH {catalog}")
        return False

    def _transitions_readable(self, catalog: str) -> bool:
        """Whether the cache's ``transitions`` view finds its file (a cache folder moved
        elsewhere, or a file removed by hand, is built again)."""
        try:
            self.con.execute(f"SELECT count(*) FROM {catalog}.transitions").fetchall()
        except duckdb.Error:
            return False
        return True

    def _ingest_in_memory(self, path: str, catalog: str) -> None:
        from btlog.replay import ingest as ingestion

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
        files = [
            str(file) for place in self._caches.values() for file in cache.transitions_paths(place)
        ]
        if files:  # the runs' transitions views read these files, and nothing else may
            self.con.execute(f"SET allowed_paths = [{', '.join(map(literal, files))}]")
        self.con.execute("SET enable_external_access = false")
        self.con.execute("SET lock_configuration = true")
        self.locked = True

    def sql(
        self, query: str, params: Sequence | dict | None = None, timeout: float | None = None
    ) -> tuple[list[str], list[tuple]]:
        """Run ``query`` (with ``params`` bound to its ``?`` or ``$name`` placeholders)
        within ``timeout`` seconds (None: no limit); returns (column names, rows). Once
        ``lock``ed, only queries are run."""
        return run_query(self.con, query, params, queries_only=self.locked, timeout=timeout)

    def sql_rows(
        self, query: str, timeout: float | None = None
    ) -> AbstractContextManager[tuple[list[str], Iterator[tuple]]]:
        """``sql`` streamed (``query_rows``): (column names, the rows as they are read)."""
        return query_rows(self.con, query, queries_only=self.locked, timeout=timeout)

    def close(self) -> None:
        """Close the connection (the caches stay on disk)."""
        self.con.close()

    def __enter__(self) -> RunDatabase:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def run_query(
    con: duckdb.DuckDBPyConnection,
    query: str,
    params: Sequence | dict | None = None,
    queries_only: bool = True,
    timeout: float | None = None,
) -> tuple[list[str], list[tuple]]:
    """Run ``query`` on ``con`` (only queries when ``queries_only``, see
    ``only_queries``) within ``timeout`` seconds; returns (column names, rows).
    ``ReplayError`` (one line) for bad SQL or a query stopped at its time limit."""
    with query_rows(con, query, params, queries_only, timeout) as (columns, rows):
        return columns, list(rows)


@contextmanager
def query_rows(
    con: duckdb.DuckDBPyConnection,
    query: str,
    params: Sequence | dict | None = None,
    queries_only: bool = True,
    timeout: float | None = None,
) -> Iterator[tuple[list[str], Iterator[tuple]]]:
    """``run_query`` streamed: (column names, the rows as they are read, ``FETCH_ROWS``
    at a time), so a result of any size is printed in bounded memory. The time limit
    covers the query and the reading of its rows, and the errors are ``run_query``'s."""
    try:
        with time_limit(con, timeout):
            if queries_only:
                only_queries(con, query)
            cursor = con.execute(query, params) if params is not None else con.execute(query)
            if cursor is None:  # DuckDB's answer to a query without a statement
                raise ReplayError(f"SQL error: no statement in {query!r}")
            columns = [d[0] for d in cursor.description or ()]
            yield columns, _fetched(cursor) if cursor.description else iter(())
    except QueryTimeout as error:
        raise ReplayError(str(error)) from None
    except duckdb.Error as error:
        raise ReplayError(f"SQL error: {one_line(error)}") from None


def _fetched(cursor: duckdb.DuckDBPyConnection) -> Iterator[tuple]:
    """The rows of ``cursor``'s result, ``FETCH_ROWS`` at a time."""
    while rows := cursor.fetchmany(FETCH_ROWS):
        yield from rows


def only_queries(con: duckdb.DuckDBPyConnection, query: str) -> None:
    """ReplayError unless every statement of ``query`` is a query (SELECT, or EXPLAIN
    without ANALYZE, which would run the statement) and there is one at least."""
    statements = con.extract_statements(query)
    if not statements:
        raise ReplayError(f"SQL error: no statement in {query!r}")
    for statement in statements:
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
    return f", {literal(run.info.file)} AS file"


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

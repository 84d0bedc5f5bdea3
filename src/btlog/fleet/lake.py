"""Runs into a Parquet lake, and a lake back into DuckDB for queries.

The layout (documented in the README, "A fleet of runs")::

    LAKE/{table}/domain={domain}/date={YYYY-MM-DD}/{file}.parquet

for ``table`` in ``runs, nodes, transitions, blackboard, ticks, mutations, causes,
activations``. The files hold the read model's columns (``run_id`` among them) except the
two partition keys, which readers take from the folder names (``hive_partitioning``).
Statuses are strings. An export writes one file per run, ``run-{run_id}.parquet``, in
each table (the ``runs`` table last, which marks the run complete); a compaction
(``btlog.fleet.compact``, at the end of every export) merges a partition's files into
one ``part-{stamp}.parquet`` per table, so a lake of thousands of runs is a few files per
day and domain. Re-exporting a run replaces its rows, so an export can be repeated.
Exports and readers may run side by side; a compaction waits for them and they for it
(``btlog.fleet.lock``).
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import duckdb

from btlog.fleet.derived import create_derived, drop_derived
from btlog.fleet.layout import FILES, LAKE_TABLES, NONE, PARTITIONS, LakeError
from btlog.fleet.lock import lake_lock
from btlog.replay.connections import connect
from btlog.replay.database import ReplayError, Run, open_runs
from btlog.replay.tables import identifier

#: A partition value as it may appear in a folder name.
_UNSAFE = re.compile(r"[^A-Za-z0-9_.@+-]")
#: Columns that hold a status (an ENUM in the read model, a string in the lake).
_STATUS_COLUMNS = ("status", "prev_status", "final_status", "root_status")


@dataclass(frozen=True)
class Exported:
    """One run written into the lake."""

    recording: str
    run_id: str
    partition: str
    transitions: int
    causes: int


def partition_value(value: object) -> str:
    """``value`` as a folder-safe partition value (``none`` for a missing one)."""
    text = NONE if value is None or value == "" else str(value)
    return _UNSAFE.sub("_", text)[:100]


def export_runs(
    recordings: Iterable[str | os.PathLike],
    lake: str | os.PathLike,
    on_run: Callable[[Exported], None] | None = None,
    compact: bool = True,
    jobs: int = 1,
) -> list[Exported]:
    """Export each recording's tables into ``lake`` (see the module docstring), in
    ``jobs`` processes, then compact the partitions it wrote to (unless ``compact`` is
    false: several processes exporting into one lake compact once when all are done).

    Each recording is read into a read model of its own in a temporary folder, removed
    after (no cache is kept: an export is a one-off pass over many files), DuckDB
    spilling there past its memory limit. The runs exported before an error are
    compacted too.
    """
    root = Path(lake)
    paths = [os.fspath(r) for r in recordings]
    done: list[Exported] = []
    (root / "runs").mkdir(parents=True, exist_ok=True)
    try:
        with lake_lock(root, exclusive=False):
            if jobs > 1 and len(paths) > 1:
                _export_in_processes(paths, root, jobs, done, on_run)
            else:
                done.extend(_export_serially(paths, str(root), on_run))
    finally:
        if compact and done:
            from btlog.fleet.compact import compact_lake

            compact_lake(root, sorted({e.partition for e in done}))
    return done


def _export_serially(
    paths: list[str], lake: str, on_run: Callable[[Exported], None] | None = None
) -> list[Exported]:
    """Export ``paths`` one after the other in this process (no compaction)."""
    done = []
    columns: dict[str, list[str]] = {}
    for recording in paths:
        # a read model on disk (DuckDB reads it within its memory limit, a day-long run
        # too), in a folder of its own removed after: nothing is left in the cache
        with (
            tempfile.TemporaryDirectory(prefix="btlog-export-") as folder,
            open_runs(recording, cache_dir=folder) as database,
        ):
            spill = os.path.join(folder, "spill")
            database.con.execute(f"SET temp_directory = '{_quoted(spill)}'")
            exported = _export_run(database.run(), database.con, Path(lake), columns)
        done.append(exported)
        if on_run is not None:
            on_run(exported)
    return done


def _export_in_processes(
    paths: list[str],
    root: Path,
    jobs: int,
    done: list[Exported],
    on_run: Callable[[Exported], None] | None,
) -> None:
    """Export ``paths`` in ``jobs`` fresh (spawned) processes, a few chunks each so they
    finish together; append to ``done`` in the recordings' order."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    size = -(-len(paths) // (jobs * 4))
    chunks = [paths[i : i + size] for i in range(0, len(paths), size)]
    context = multiprocessing.get_context("spawn")  # no fork of a process holding DuckDB
    with ProcessPoolExecutor(min(jobs, len(chunks)), mp_context=context) as pool:
        try:
            for chunk in pool.map(_export_serially, chunks, [str(root)] * len(chunks)):
                for exported in chunk:
                    done.append(exported)
                    if on_run is not None:
                        on_run(exported)
        except BaseException:
            pool.shutdown(cancel_futures=True)
            raise


def _export_run(
    run: Run, con: duckdb.DuckDBPyConnection, root: Path, columns: dict[str, list[str]]
) -> Exported:
    """Write one run's file in every table (``columns``: each table's columns, filled on
    first use); each file is written under a temporary name and renamed into place."""
    info = run.info
    date = info.started_at.date() if info.started_at else None
    partition = f"domain={partition_value(info.domain)}/date={partition_value(date)}"
    name = f"run-{partition_value(info.run_id)}.parquet"
    try:
        causes = create_derived(run, con)
        for table in LAKE_TABLES[1:] + LAKE_TABLES[:1]:  # runs last: the run is complete
            folder = root / table / partition
            folder.mkdir(parents=True, exist_ok=True)
            source = {
                "causes": "_btlog_causes",
                "activations": "_btlog_activations",
            }.get(table, f"{run.catalog}.{identifier(table)}")
            if table not in columns:
                columns[table] = _columns(con, source)
            selected = ", ".join(
                f"CAST({identifier(c)} AS VARCHAR) AS {identifier(c)}"
                if c in _STATUS_COLUMNS
                else identifier(c)
                for c in columns[table]
                if c not in PARTITIONS
            )
            temporary = folder / f".{name}.tmp"
            con.execute(
                f"COPY (SELECT {selected} FROM {source} WHERE run_id = $run) "
                f"TO $file (FORMAT parquet, COMPRESSION zstd)",
                {"run": run.stored_id, "file": str(temporary)},
            )
            os.replace(temporary, folder / name)
        count = con.execute(
            f"SELECT count(*) FROM {run.catalog}.transitions WHERE run_id = $run",
            {"run": run.stored_id},
        ).fetchone()
    finally:
        drop_derived(con)
    return Exported(info.file, info.run_id, partition, count[0] if count else 0, causes)


def _columns(con: duckdb.DuckDBPyConnection, source: str) -> list[str]:
    return [row[0] for row in con.execute(f"DESCRIBE SELECT * FROM {source}").fetchall()]


def open_lake(lake: str | os.PathLike) -> duckdb.DuckDBPyConnection:
    """A read-only DuckDB connection with one view per lake table (Hive partitions as
    columns ``domain``, ``date``, ``run_id``): it can read the lake and nothing else, and
    its configuration is locked."""
    root = Path(lake).resolve()
    if not root.is_dir():
        raise LakeError(f"{lake}: not a folder")
    present = [t for t in LAKE_TABLES if any((root / t).glob(FILES))]
    if "runs" not in present:
        raise LakeError(f"{lake}: not a btlog lake (no runs/domain=…/date=…/*.parquet)")
    con = connect(sandbox=True)
    for table in present:
        pattern = str(root / table / FILES)
        con.execute(
            f"CREATE VIEW {identifier(table)} AS SELECT * FROM read_parquet("
            f"'{_quoted(pattern)}', hive_partitioning = true, "
            f"hive_types = {{'domain': VARCHAR, 'date': VARCHAR}})"
        )
    con.execute(f"SET allowed_directories = ['{_quoted(str(root))}/']")
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")
    return con


@contextmanager
def reading_lake(lake: str | os.PathLike) -> Iterator[duckdb.DuckDBPyConnection]:
    """``open_lake``'s connection, closed at the end of the block, with the lake's lock
    held shared meanwhile (no compaction removes a file under the query)."""
    with lake_lock(lake, exclusive=False):
        con = open_lake(lake)
        try:
            yield con
        finally:
            con.close()


def _quoted(text: str) -> str:
    """``text`` inside a single-quoted SQL literal (paths are the user's own, but a
    quote in a folder name must not end the literal)."""
    return text.replace("'", "''")


def check_exportable(recordings: Iterable[str | os.PathLike], lake: str | os.PathLike) -> None:
    """LakeError unless every recording is a readable file outside the lake folder."""
    root = Path(lake).resolve()
    for recording in recordings:
        path = Path(recording)
        if not path.is_file():
            raise LakeError(f"{recording}: no such recording")
        if root in path.resolve().parents:
            raise LakeError(f"{recording}: lies inside the lake {lake}")


__all__ = [
    "FILES",
    "LAKE_TABLES",
    "Exported",
    "LakeError",
    "ReplayError",
    "check_exportable",
    "export_runs",
    "open_lake",
    "partition_value",
    "reading_lake",
]

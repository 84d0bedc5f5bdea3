"""Ingestion: one recording into the DuckDB read model, end to end.

The read model is a projection of the MCAP file, rebuilt from it at will, so ingestion is
a pure function of the file's bytes. It must be fast (millions of events a second), so
nothing is done per row in Python: ``McapScan`` (``btlog.replay.scan``) cuts each message
into row batches while it walks the file, ``Loader`` (``btlog.replay.load``) parses and
inserts them in worker threads, the small tables follow (``btlog.replay.run_tables``),
then the snapshots (``btlog.replay.snapshots``), timed and reported separately. The
tables are those of ``btlog.replay.tables``.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import duckdb
import orjson

import btlog
from btlog.record import format as fmt
from btlog.record.reader import RecordingError, decode_metadata, read_metadata, tree_of
from btlog.record.walk import MAGIC
from btlog.replay.load import Destination, load_other_messages, load_part
from btlog.replay.run_tables import (
    Extent,
    extent_of,
    insert_run,
    insert_small_tables,
    seq_space,
    short_run_id,
)
from btlog.replay.scan import Collected, warnings_of
from btlog.replay.snapshots import DEFAULT_SNAPSHOT_EVERY, build_snapshots, snapshot_interval
from btlog.replay.tables import (
    INGEST_VERSION,
    discard_run,
    first_row,
    identifier,
    one_row,
    transitions_views,
)
from btlog.tree.model import Tree


@dataclass
class IngestReport:
    """What one ingestion read and how long it took (seconds). ``events`` counts seqs
    (last seq + 1): the number of events of a gap-free run."""

    run_id: str
    file: str
    events: int
    transitions: int
    writes: int
    ticks: int
    mutations: int
    truncated: bool
    warnings: list[str]
    ingest_seconds: float
    snapshot_seconds: float
    snapshots: int
    snapshot_every: int

    @property
    def events_per_second(self) -> float:
        """Events loaded per second of table ingestion (snapshots excluded)."""
        return self.events / self.ingest_seconds if self.ingest_seconds else 0.0


def ingest(
    con: duckdb.DuckDBPyConnection,
    path: str | os.PathLike,
    run_id: str | None = None,
    snapshot_every: int = DEFAULT_SNAPSHOT_EVERY,
    snapshots: bool = True,
) -> IngestReport:
    """Load the recording at ``path`` into ``con`` (whose tables ``create_schema`` made)
    as run ``run_id`` (default: ``short_run_id``): ``load_tables``, then
    ``add_snapshots`` unless ``snapshots`` is false (the tables alone serve SQL, not
    states).

    Raises ``RecordingError`` for a file that is not a readable recording; nothing of it
    is left in the tables then. A truncated file loads its readable prefix, with a
    warning in the report. The tables are filled by several statements (and worker
    threads), not one transaction: build a database, then publish it.
    """
    report = load_tables(con, path, run_id, snapshot_every)
    return add_snapshots(con, report) if snapshots else report


def load_tables(
    con: duckdb.DuckDBPyConnection,
    path: str | os.PathLike,
    run_id: str | None = None,
    snapshot_every: int = DEFAULT_SNAPSHOT_EVERY,
    transitions_files: Callable[[int], Path] | None = None,
) -> IngestReport:
    """Every table of the run but ``_snapshots`` (see ``ingest``); the snapshots are
    to be ``snapshot_interval`` events apart, at least ``snapshot_every``. With
    ``transitions_files``, the status changes are written as Parquet
    (``btlog.replay.transitions_file``) to ``transitions_files(n)`` for each part ``n``
    of the file read (``btlog.replay.parts``), and ``transitions`` becomes a view of
    them (for a cache: the files stay beside it)."""
    if snapshot_every < 1:
        raise ValueError(f"snapshot_every must be at least 1, got {snapshot_every}")
    started = time.perf_counter()
    name = os.path.abspath(os.fspath(path))
    stat = os.stat(name)
    run_id = run_id or short_run_id(read_metadata(name), name)
    try:
        collected = _load_rows(con, run_id, name, transitions_files)
        metadata = decode_metadata(name, collected.metadata or {})
        tree_of(name, collected.tree, collected.walk)  # refuses a file without a tree
        tree = collected.tree or {}
        insert_small_tables(con, run_id, collected)
        extent = extent_of(con, run_id)
        _check_consistency(con, run_id, name, extent)
        insert_run(con, run_id, name, tree, metadata, extent)
        report = IngestReport(
            run_id,
            name,
            seq_space(extent),
            *_counts(con, run_id),
            len(collected.mutations),
            collected.walk.truncated,
            _warnings(name, collected, extent),
            time.perf_counter() - started,
            0.0,
            0,
            snapshot_interval(con, run_id, snapshot_every),
        )
        _insert_ingest(con, report, stat, extent, tree)
    except BaseException:
        discard_run(con, run_id)
        raise
    return report


def add_snapshots(con: duckdb.DuckDBPyConnection, report: IngestReport) -> IngestReport:
    """Fold the run loaded by ``load_tables`` and store its snapshots; the report with
    the snapshot figures."""
    try:
        stored, seconds = snapshots_into(con, "_snapshots", run_id=report.run_id)
        con.execute(
            "UPDATE _ingest SET snapshot_seconds = $seconds WHERE run_id = $run_id",
            {"seconds": seconds, "run_id": report.run_id},
        )
    except BaseException:
        con.execute("DELETE FROM _snapshots WHERE run_id = $run_id", {"run_id": report.run_id})
        raise
    return replace(report, snapshot_seconds=seconds, snapshots=stored)


def snapshots_into(
    con: duckdb.DuckDBPyConnection,
    target: str,
    catalog: str | None = None,
    run_id: str | None = None,
    segment: int | None = None,
) -> tuple[int, float]:
    """Build the snapshots of run ``run_id`` (default: the only one) whose tables are in
    ``catalog`` (default: the current one; it may be read-only) into the table ``target``
    (``_snapshots``, or ``other_catalog._snapshots``): those of ``segment``
    (``btlog.replay.snapshots.segment_of``), or all of them; (rows, seconds)."""
    started = time.perf_counter()
    (before,) = one_row(con, "SELECT current_database()")
    if catalog is not None:
        con.execute(f"USE {identifier(catalog)}")
    try:
        where = "" if run_id is None else "WHERE run_id = $run_id"
        run_id, events, every, tree = one_row(
            con,
            f"SELECT run_id, events, snapshot_every, tree FROM _ingest {where}",
            {} if run_id is None else {"run_id": run_id},
        )
        stored = build_snapshots(
            con, run_id, Tree.from_description(orjson.loads(tree)), events, every, target, segment
        )
    finally:
        if catalog is not None:
            con.execute(f"USE {identifier(before)}")
    return stored, time.perf_counter() - started


def _load_rows(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    name: str,
    transitions_files: Callable[[int], Path] | None,
) -> Collected:
    """Walk the file, loading its bulk rows as it goes; returns what else it found.
    With ``transitions_files`` (the file of each part's status changes), a long
    recording is read in parts, each in a process of its own (``btlog.replay.parts``),
    and ``transitions`` becomes a view of the files; parts that were not read as one
    read would read them (``parts.agree``) are read again, in one part."""
    if transitions_files is None:
        return _read_rows(con, run_id, name, transitions_files)
    from btlog.replay import parts

    try:
        return _read_rows(con, run_id, name, transitions_files)
    except parts.Disagree:
        discard_run(con, run_id)
        return _read_rows(con, run_id, name, transitions_files, whole=True)


def _read_rows(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    name: str,
    transitions_files: Callable[[int], Path] | None,
    whole: bool = False,
) -> Collected:
    """``_load_rows``, in the parts ``parts.plan`` gives (one if ``whole``); ``Disagree``
    when the parts' reads do not agree (the files of the parts but the first removed)."""
    to = Destination(run_id)
    start, stop = len(MAGIC), None  # the caller's part: the whole file unless cut
    scans: list = []
    files: list[Path] = []
    try:
        with tempfile.TemporaryDirectory(prefix="btlog-ingest-") as folder:
            if transitions_files is not None:
                from btlog.replay import parts
                from btlog.replay.transitions_file import TransitionsFile

                plan = [parts.Part(start, stop)] if whole else parts.plan(name)
                files = [transitions_files(number) for number in range(len(plan))]
                scans = [
                    parts.PartScan(name, part, run_id, files[n], Path(folder) / f"part-{n}")
                    for n, part in enumerate(plan)
                    if n
                ]
                to.transitions = TransitionsFile(files[0])
                start, stop = plan[0].start, plan[0].stop
            collected = load_part(con, to, name, Path(folder), start, stop)
            others = [scan.rows() for scan in scans]
            if others and not parts.agree([collected, *(rows.collected for rows in others)]):
                for file in files[1:]:
                    file.unlink(missing_ok=True)
                raise parts.Disagree(name)
            if others:
                for rows in others:
                    for table, file in (("ticks", rows.ticks), ("blackboard", rows.blackboard)):
                        con.execute(
                            f"INSERT INTO {table} SELECT * FROM read_parquet($file)",
                            {"file": str(file)},
                        )
                collected = parts.merge(collected, [rows.collected for rows in others])
        if collected.metadata is None:
            raise RecordingError(f"{name}: not a btlog recording: no {fmt.METADATA_NAME} metadata")
        load_other_messages(con, to, collected, name)
    finally:
        for scan in scans:
            scan.stop()
        if to.transitions is not None:
            to.transitions.close()
    if files:
        con.execute("DROP TABLE IF EXISTS transitions")
        for statement in transitions_views(run_id, [str(file) for file in files]):
            con.execute(statement)
    return collected


def _check_consistency(
    con: duckdb.DuckDBPyConnection, run_id: str, name: str, extent: Extent
) -> None:
    """RecordingError when what was read cannot be a run: a status change of a node the
    tree does not have, or two events with one seq (CRCs catch damage; this catches
    files written wrong). Seqs are checked in one pass without a hash table when the run
    looks gap-free (the sum of a hash of every seq equals that of ``0..last``), with a
    ``GROUP BY`` only for a run with gaps."""
    params: dict[str, Any] = {"run_id": run_id}
    stray = first_row(con, *_stray_query(con, params))
    if stray is not None:
        raise RecordingError(
            f"{name}: event seq {stray[0]} is about node uid {stray[1]}, "
            "which the tree does not have"
        )
    seqs = """SELECT seq FROM transitions WHERE run_id = $run_id
        UNION ALL SELECT seq FROM blackboard WHERE run_id = $run_id
        UNION ALL SELECT seq FROM _mutations WHERE run_id = $run_id"""
    if extent.events and extent.last_seq == extent.events - 1:
        (same,) = one_row(
            con,
            f"""SELECT (SELECT sum(hash(seq)) FROM ({seqs}))
                = (SELECT sum(hash(range)) FROM range($n))""",
            {**params, "n": extent.events},
        )
        if same:
            return
    twice = first_row(con, f"SELECT seq FROM ({seqs}) GROUP BY seq HAVING count(*) > 1", params)
    if twice is not None:
        raise RecordingError(f"{name}: two events have seq {twice[0]}")


def _stray_query(
    con: duckdb.DuckDBPyConnection, params: dict[str, Any]
) -> tuple[str, dict[str, Any]]:
    """The query of a status change of a node the tree does not have. A tree's uids are
    usually ``lo..hi`` without a hole: then a stray uid is one outside that range, which
    the row groups' own min and max answer for most of the table without reading it
    (an anti-join on ``nodes`` reads every row: 2 s at 100M events)."""
    lo, hi, count = one_row(
        con,
        "SELECT min(uid), max(uid), count(DISTINCT uid) FROM nodes WHERE run_id = $run_id",
        params,
    )
    if count and hi - lo + 1 == count:
        query = """SELECT seq, uid FROM transitions WHERE run_id = $run_id
            AND (uid < $lo OR uid > $hi) LIMIT 1"""
        return query, {**params, "lo": lo, "hi": hi}
    query = """SELECT seq, uid FROM transitions t WHERE run_id = $run_id AND NOT EXISTS
        (SELECT 1 FROM nodes n WHERE n.run_id = $run_id AND n.uid = t.uid) LIMIT 1"""
    return query, params


def _counts(con: duckdb.DuckDBPyConnection, run_id: str) -> tuple[int, int, int]:
    counts = [
        one_row(con, f"SELECT count(*) FROM {table} WHERE run_id = $run_id", {"run_id": run_id})[0]
        for table in ("transitions", "blackboard", "ticks")
    ]
    return counts[0], counts[1], counts[2]


def _warnings(name: str, collected: Collected, extent: Extent) -> list[str]:
    warnings = warnings_of(collected)
    if extent.events and extent.last_seq != extent.events - 1:
        warnings.append(
            f"{name}: events are not gap-free: {extent.events} events up to seq {extent.last_seq}"
        )
    if collected.walk.truncated:
        last = "(none)" if extent.last_seq is None else f"up to seq {extent.last_seq}"
        warnings.insert(0, f"{name}: truncated recording; read {extent.events} events {last}")
    return warnings


def _insert_ingest(
    con: duckdb.DuckDBPyConnection,
    report: IngestReport,
    stat: os.stat_result,
    extent: Extent,
    tree: dict,
) -> None:
    con.execute(
        "INSERT INTO _ingest VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14)",
        [
            report.run_id,
            report.file,
            stat.st_size,
            stat.st_mtime_ns,
            btlog.SCHEMA_VERSION,
            INGEST_VERSION,
            seq_space(extent),
            extent.last_tick,
            report.truncated,
            orjson.dumps(report.warnings).decode(),
            report.snapshot_every,
            orjson.dumps(tree).decode(),
            report.ingest_seconds,
            None,
        ],
    )

"""Compaction: a lake partition's many small files merged into one file per table.

An export writes one file per run and table; thousands of runs make thousands of files
per partition, and opening them dominates every query. ``compact_lake`` rewrites each
``domain=…/date=…`` partition of every table as one ``part-{stamp}.parquet`` (rows sorted
by ``run_id``), the same stamp in every table.

Which rows survive: for each run, those of the *newest* file holding it in the ``runs``
table (a ``run-…`` file, written by a later export, beats any ``part-…`` file; of two
``part-…`` files the later stamp wins), and in every table only rows from a file of that
name. So a re-exported run replaces its old rows, and a run whose export stopped before
its ``runs`` file is left out.

Safety: each merged file is written under a hidden temporary name, flushed to disk and
renamed into place, ``runs`` last; only then are the merged inputs removed. A crash at
any point loses nothing and leaves a readable lake; at worst some runs show twice until
the next compaction (any export, or ``btlog fleet LAKE --compact``) removes the
leftovers. A compaction holds the lake's lock exclusively (``btlog.fleet.lock``): exports
and queries of the lake wait for it, and it for them.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable
from pathlib import Path

import duckdb

from btlog.fleet.layout import FILES, LAKE_TABLES, LakeError
from btlog.fleet.lock import lake_lock
from btlog.replay.connections import connect


def partitions(lake: str | os.PathLike) -> list[str]:
    """Every ``domain=…/date=…`` partition of ``lake`` that has runs."""
    root = Path(lake) / "runs"
    return sorted({str(f.parent.relative_to(root)) for f in root.glob(FILES)})


def compact_lake(lake: str | os.PathLike, only: Iterable[str] | None = None) -> int:
    """Compact the partitions ``only`` (default: all) of ``lake``; return how many
    partitions were rewritten (one already a single file per table is left alone)."""
    root = Path(lake)
    if not (root / "runs").is_dir():
        raise LakeError(f"{lake}: not a btlog lake (no runs folder)")
    rewritten = 0
    with lake_lock(root, exclusive=True):
        con = connect()
        try:
            for partition in only if only is not None else partitions(root):
                rewritten += _compact_partition(con, root, partition)
        finally:
            con.close()
    return rewritten


def _compact_partition(con: duckdb.DuckDBPyConnection, root: Path, partition: str) -> bool:
    """Merge one partition (see the module docstring); False when nothing to do."""
    inputs = {t: sorted((root / t / partition).glob("*.parquet")) for t in LAKE_TABLES}
    for table in LAKE_TABLES:
        for leftover in (root / table / partition).glob(".*.tmp"):
            leftover.unlink()  # a temporary file of an export or compaction that stopped
    if all(len(files) <= 1 for files in inputs.values()):
        return False
    if not inputs["runs"]:
        return False
    con.execute(
        "CREATE OR REPLACE TEMP TABLE _winners AS SELECT run_id, max(parse_filename("
        "filename)) AS file FROM read_parquet($files, filename = true, "
        "hive_partitioning = false) GROUP BY run_id",
        {"files": [str(f) for f in inputs["runs"]]},
    )
    name = f"part-{_stamp(inputs['runs']):020d}.parquet"
    for table in LAKE_TABLES[1:] + LAKE_TABLES[:1]:  # runs last, as an export does
        if not inputs[table]:
            continue
        folder = root / table / partition
        temporary = folder / f".{name}.tmp"
        con.execute(
            "COPY (SELECT t.* EXCLUDE (filename) FROM read_parquet($files, filename = true, "
            "hive_partitioning = false) t JOIN _winners w ON w.run_id = t.run_id "
            "AND w.file = parse_filename(t.filename) ORDER BY t.run_id) "
            "TO $file (FORMAT parquet, COMPRESSION zstd)",
            {"files": [str(f) for f in inputs[table]], "file": str(temporary)},
        )
        _flush(temporary)
        os.replace(temporary, folder / name)
    for table in LAKE_TABLES:
        for merged in inputs[table]:
            merged.unlink(missing_ok=True)
    return True


def _stamp(files: list[Path]) -> int:
    """A stamp later than the clock and than every ``part-…`` file of ``files``."""
    stamps = [int(f.stem[5:]) for f in files if f.stem[:5] == "part-" and f.stem[5:].isdigit()]
    return max([time.time_ns(), *(s + 1 for s in stamps)])


def _flush(path: Path) -> None:
    """Make ``path``'s bytes durable before it is renamed into place."""
    with open(path, "rb+") as file:
        os.fsync(file.fileno())

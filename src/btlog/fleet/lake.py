"""Runs into a Parquet lake, and a lake back into DuckDB for queries.

The layout (documented in ``docs/design.md``)::

    LAKE/{table}/domain={domain}/date={YYYY-MM-DD}/run_id={run_id}/data.parquet

for ``table`` in ``runs, nodes, transitions, blackboard, ticks, mutations, causes``. The
files hold the read model's columns except the three partition keys, which readers take
from the folder names (``hive_partitioning``). Statuses are strings. Re-exporting a run
replaces its folder, so an export can be repeated safely.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import duckdb

from btlog.explain.causes import cause
from btlog.history import COMPLETIONS
from btlog.replay.database import ReplayError, Run, open_runs
from btlog.replay.tables import PUBLIC_TABLES, identifier
from btlog.status import FAILURE

#: The lake's tables: the read model's public ones and the failure causes.
LAKE_TABLES = (*PUBLIC_TABLES, "causes")
#: Partition keys, outermost first.
PARTITIONS = ("domain", "date", "run_id")
#: A partition value as it may appear in a folder name.
_UNSAFE = re.compile(r"[^A-Za-z0-9_.@+-]")
#: The value used for a run without a domain or start date.
NONE = "none"


class LakeError(ValueError):
    """A lake that cannot be written or read (one line, naming the folder)."""


@dataclass(frozen=True)
class Exported:
    """One run written into the lake."""

    recording: str
    run_id: str
    folder: Path
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
) -> list[Exported]:
    """Export each recording's tables into ``lake`` (see the module docstring).

    Each recording is read into memory on its own (no cache is written: an export is a
    one-off pass over many files) and its folder in every table replaced.
    """
    root = Path(lake)
    done: list[Exported] = []
    columns: dict[str, list[str]] = {}
    for recording in recordings:
        with open_runs(recording, cache=False) as database:
            exported = _export_run(database.run(), database.con, root, columns)
        done.append(exported)
        if on_run is not None:
            on_run(exported)
    return done


def _export_run(
    run: Run, con: duckdb.DuckDBPyConnection, root: Path, columns: dict[str, list[str]]
) -> Exported:
    """Write one run's tables (``columns``: each table's columns, filled on first use)."""
    info = run.info
    keys = {
        "domain": partition_value(info.domain),
        "date": partition_value(info.started_at.date() if info.started_at else None),
        "run_id": partition_value(info.run_id),
    }
    folder = "/".join(f"{key}={keys[key]}" for key in PARTITIONS)
    causes = _causes_table(run, con)
    for table in LAKE_TABLES:
        target = root / table / folder
        if target.exists():
            shutil.rmtree(target)
        target.mkdir(parents=True)
        source = "_btlog_causes" if table == "causes" else f"{run.catalog}.{identifier(table)}"
        if table not in columns:
            columns[table] = _columns(con, source)
        selected = ", ".join(
            f"CAST({identifier(c)} AS VARCHAR) AS {identifier(c)}"
            if c in ("status", "prev_status", "final_status", "root_status")
            else identifier(c)
            for c in columns[table]
            if c not in PARTITIONS
        )
        con.execute(
            f"COPY (SELECT {selected} FROM {source} WHERE run_id = $run) "
            f"TO $file (FORMAT parquet, COMPRESSION zstd)",
            {"run": run.stored_id, "file": str(target / "data.parquet")},
        )
    count = con.execute(
        f"SELECT count(*) FROM {run.catalog}.transitions WHERE run_id = $run",
        {"run": run.stored_id},
    ).fetchone()
    con.execute("DROP TABLE _btlog_causes")
    return Exported(info.file, info.run_id, root, count[0] if count else 0, causes)


def _columns(con: duckdb.DuckDBPyConnection, source: str) -> list[str]:
    return [row[0] for row in con.execute(f"DESCRIBE SELECT * FROM {source}").fetchall()]


def _causes_table(run: Run, con: duckdb.DuckDBPyConnection) -> int:
    """Create ``_btlog_causes``: every FAILURE of a non-execution node with its causal
    leaf, in event order; return its row count."""
    tree = run.tree_at("end")
    history = run.history()
    inner = [node.uid for node in tree if not node.is_execution]
    failures = [
        done
        for done in history.transitions(inner, COMPLETIONS, 0, run.info.events, 1 << 62)
        if done.status is FAILURE
    ]
    rows = []
    for done in failures:
        node = tree.node(done.uid)
        leaf = cause(tree, node, done, history)
        culprit = tree.node(leaf.uid)
        rows.append(
            (
                run.stored_id,
                done.seq,
                done.t_ns,
                node.uid,
                node.path,
                node.description,
                culprit.uid,
                culprit.path,
                culprit.description,
                "succeeded" if leaf.status.name == "SUCCESS" else "failed",
            )
        )
    con.execute(
        "CREATE TEMP TABLE _btlog_causes (run_id VARCHAR, seq BIGINT, t_ns BIGINT, "
        "uid INTEGER, path VARCHAR, name VARCHAR, cause_uid INTEGER, cause_path VARCHAR, "
        "cause_name VARCHAR, verb VARCHAR)"
    )
    if rows:
        con.executemany("INSERT INTO _btlog_causes VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", rows)
    return len(rows)


def open_lake(lake: str | os.PathLike) -> duckdb.DuckDBPyConnection:
    """A read-only DuckDB connection with one view per lake table (Hive partitions as
    columns ``domain``, ``date``, ``run_id``): it can read the lake and nothing else, and
    its configuration is locked."""
    root = Path(lake).resolve()
    if not root.is_dir():
        raise LakeError(f"{lake}: not a folder")
    present = [t for t in LAKE_TABLES if any((root / t).glob("*/*/*/data.parquet"))]
    if "runs" not in present:
        raise LakeError(f"{lake}: not a btlog lake (no runs/…/data.parquet)")
    con = duckdb.connect()
    for table in present:
        pattern = str(root / table / "*" / "*" / "*" / "data.parquet")
        con.execute(
            f"CREATE VIEW {identifier(table)} AS SELECT * FROM read_parquet("
            f"'{_quoted(pattern)}', hive_partitioning = true, "
            f"hive_types = {{'domain': VARCHAR, 'date': VARCHAR, 'run_id': VARCHAR}})"
        )
    con.execute(f"SET allowed_directories = ['{_quoted(str(root))}/']")
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")
    return con


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
    "LAKE_TABLES",
    "Exported",
    "LakeError",
    "ReplayError",
    "check_exportable",
    "export_runs",
    "open_lake",
    "partition_value",
]

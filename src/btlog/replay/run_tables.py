"""The small tables of a run: ``runs``, ``nodes``, ``mutations``, ``_mutations``,
``_answers``, and the run's extent (event count, last seq, time and tick) read back
from the bulk tables once they are loaded."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import duckdb
import orjson
import pyarrow as pa

from btlog.replay.scan import Collected
from btlog.replay.tables import first_row, insert_arrow, one_row


def insert_small_tables(con: duckdb.DuckDBPyConnection, run_id: str, collected: Collected) -> None:
    """The nodes (the tree's, then each mutation's), the mutations and the answers."""
    _insert_nodes(con, run_id, collected.tree or {"nodes": []}, collected.mutations)
    _insert_mutations(con, run_id, collected.mutations)
    _insert_answers(con, run_id, collected.answers)


def short_run_id(metadata: dict[str, Any], path: str) -> str:
    """A short, stable id: the first 8 letters and digits of the metadata's run id (or of
    a hash of the file's path when the metadata has none)."""
    letters = "".join(c for c in str(metadata.get("run_id", "")).lower() if c.isalnum())
    if len(letters) >= 4 and letters.isascii():
        return letters[:8]
    return hashlib.sha1(os.path.abspath(path).encode()).hexdigest()[:8]


def _node_rows(tree: dict, mutations: list[dict]) -> list[tuple]:
    """(uid, parent_uid, idx, depth, kind, type, name, path, ports, added_seq) per node:
    the recorded tree's, then each insertion's nodes (as they were inserted); a pruned
    node keeps its row."""
    depth: dict[int, int] = {}
    rows = []
    inserted = [m for m in mutations if m.get("op", "insert") == "insert"]  # not prunes
    batches = [(None, tree["nodes"])] + [(m["seq"], m["nodes"]) for m in inserted]
    for added_seq, records in batches:
        for record in records:
            parent = record.get("parent_uid")
            depth[record["uid"]] = 0 if parent is None else depth.get(parent, -1) + 1
            rows.append(
                (
                    record["uid"],
                    parent,
                    record.get("idx", 0),
                    depth[record["uid"]],
                    record["kind"],
                    record["type"],
                    record.get("name", ""),
                    record.get("path", ""),
                    orjson.dumps(record.get("ports", {})).decode(),
                    added_seq,
                )
            )
    return rows


def _insert_nodes(
    con: duckdb.DuckDBPyConnection, run_id: str, tree: dict, mutations: list[dict]
) -> None:
    names = (
        "uid",
        "parent_uid",
        "idx",
        "depth",
        "kind",
        "type",
        "name",
        "path",
        "ports",
        "added_seq",
    )
    types = (
        pa.int32(),
        pa.int32(),
        pa.int32(),
        pa.int32(),
        pa.string(),
        pa.string(),
        pa.string(),
        pa.string(),
        pa.string(),
        pa.int64(),
    )
    rows = _node_rows(tree, mutations)
    columns = list(zip(*rows, strict=True)) if rows else [()] * len(names)
    table = pa.table({n: pa.array(c, t) for n, c, t in zip(names, columns, types, strict=True)})
    insert_arrow(con, "nodes", run_id, table)


def _insert_mutations(con: duckdb.DuckDBPyConnection, run_id: str, mutations: list[dict]) -> None:
    for message in mutations:
        nodes = message.get("nodes") or [{}]
        con.execute(
            "INSERT INTO mutations VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            [
                run_id,
                message["seq"],
                message["t_ns"],
                message["op"],
                message["parent_uid"],
                message.get("after_uid"),
                message.get("inserted_root_uid", nodes[0].get("uid")),
                message.get("question", ""),
            ],
        )
        con.execute(
            "INSERT INTO _mutations VALUES ($1, $2, $3, $4, $5)",
            [
                run_id,
                message["seq"],
                message["t_ns"],
                message.get("tick", 0),
                orjson.dumps(message).decode(),
            ],
        )


def _insert_answers(con: duckdb.DuckDBPyConnection, run_id: str, answers: list[dict]) -> None:
    for message in answers:
        con.execute(
            "INSERT INTO _answers VALUES ($1, $2, $3, $4, $5, $6, $7)",
            [
                run_id,
                message.get("seq"),
                message.get("t_ns"),
                message.get("tick"),
                message.get("question"),
                message.get("intent"),
                message.get("answer"),
            ],
        )


@dataclass(frozen=True)
class Extent:
    """A run's extent as ingested: event count, last seq, times and ticks."""

    events: int
    last_seq: int | None
    last_t_ns: int
    last_tick: int
    duration_ns: int
    final_status: str | None


def extent_of(con: duckdb.DuckDBPyConnection, run_id: str) -> Extent:
    events, last_seq, last_t, last_tick = one_row(
        con,
        """
        SELECT count(*), max(seq), max(t_ns), max(tick) FROM (
            SELECT seq, t_ns, tick FROM transitions WHERE run_id = $run_id
            UNION ALL SELECT seq, t_ns, tick FROM blackboard WHERE run_id = $run_id
            UNION ALL SELECT seq, t_ns, tick FROM _mutations WHERE run_id = $run_id)""",
        {"run_id": run_id},
    )
    tick_end, tick_max = one_row(
        con, "SELECT max(end_ns), max(tick) FROM ticks WHERE run_id = $run_id", {"run_id": run_id}
    )
    final = first_row(
        con,
        "SELECT root_status FROM ticks WHERE run_id = $run_id AND NOT teardown "
        "ORDER BY tick DESC LIMIT 1",
        {"run_id": run_id},
    )
    last_t = last_t or 0
    return Extent(
        events,
        last_seq,
        last_t,
        max(last_tick or 0, tick_max or 0),
        max(last_t, tick_end or 0),
        None if final is None else final[0],
    )


def seq_space(extent: Extent) -> int:
    """The number of seqs of a run: last seq + 1 (the event count when gap-free)."""
    return 0 if extent.last_seq is None else extent.last_seq + 1


def insert_run(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    path: str,
    tree: dict,
    metadata: dict,
    extent: Extent,
) -> None:
    started = metadata.get("started_at")
    try:
        started_at = datetime.fromisoformat(started) if started else None
    except (TypeError, ValueError):
        started_at = None
    if started_at is not None and started_at.tzinfo is not None:
        started_at = started_at.astimezone(UTC).replace(tzinfo=None)
    seed = str(metadata.get("seed", "")).strip()
    con.execute(
        "INSERT INTO runs VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)",
        [
            run_id,
            path,
            tree.get("tree_name", ""),
            started_at,
            extent.duration_ns,
            extent.final_status,
            metadata.get("domain") or None,
            int(seed) if seed.lstrip("-").isdigit() else None,
            orjson.dumps(metadata, default=repr).decode(),
        ],
    )

"""The read model's tables: their schema, and the few helpers every loader uses.

The public tables (``runs``, ``nodes``, ``transitions``, ``blackboard``, ``ticks``,
``mutations``) are the ones users write SQL against; internal tables start with ``_``:
``_snapshots`` (the state every K events and the events up to the next one),
``_mutations`` (the full mutation messages, to rebuild inserted nodes), ``_answers``
(questions asked live) and ``_ingest`` (what was read, and from which file).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import duckdb

if TYPE_CHECKING:
    import pyarrow as pa

from btlog.status import STATUS_NAMES, Status

#: The layout of the read model; part of the cache key (bump when a table changes).
INGEST_VERSION = "7"

SCHEMA = (
    # Status is numbered as BT.CPP numbers it; the ENUM uses the same order.
    "CREATE TYPE status AS ENUM (" + ", ".join(f"'{name}'" for name in STATUS_NAMES) + ")",
    """CREATE TABLE runs (run_id VARCHAR, file VARCHAR, tree_name VARCHAR,
        started_at TIMESTAMP, duration_ns BIGINT, final_status status, domain VARCHAR,
        seed BIGINT, metadata JSON)""",
    """CREATE TABLE nodes (run_id VARCHAR, uid INTEGER, parent_uid INTEGER, idx INTEGER,
        depth INTEGER, kind VARCHAR, type VARCHAR, name VARCHAR, path VARCHAR, ports JSON,
        added_seq BIGINT)""",
    """CREATE TABLE transitions (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        uid INTEGER, prev_status status, status status)""",
    """CREATE TABLE blackboard (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        scope VARCHAR, key VARCHAR, value JSON, type VARCHAR, writer_uid INTEGER)""",
    """CREATE TABLE ticks (run_id VARCHAR, tick BIGINT, start_ns BIGINT, end_ns BIGINT,
        root_status status, teardown BOOLEAN DEFAULT false)""",
    """CREATE TABLE mutations (run_id VARCHAR, seq BIGINT, t_ns BIGINT, op VARCHAR,
        parent_uid INTEGER, after_uid INTEGER, inserted_root_uid INTEGER, question VARCHAR)""",
    """CREATE TABLE _mutations (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        message JSON)""",
    """CREATE TABLE _answers (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        question VARCHAR, intent VARCHAR, answer VARCHAR)""",
    """CREATE TABLE _snapshots (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        first_t_ns BIGINT, first_tick BIGINT, state JSON, events BLOB)""",
    """CREATE TABLE _ingest (run_id VARCHAR, file VARCHAR, size BIGINT, mtime_ns BIGINT,
        schema_version VARCHAR, ingest_version VARCHAR, events BIGINT, last_tick BIGINT,
        truncated BOOLEAN, warnings JSON, snapshot_every BIGINT, tree JSON,
        ingest_seconds DOUBLE, snapshot_seconds DOUBLE)""",
)
#: The view of ``transitions`` with each status as its code (``btlog.status``): what the
#: snapshots' aggregations read. Over a cache's Parquet files the codes are the files'
#: own, and a filter on them is one the files' statistics answer; the ENUM's ``CASE``
#: (``transitions_views``) would be evaluated on every row.
TRANSITION_CODES = "_transition_codes"
_CODES_OF_TABLE = f"""CREATE OR REPLACE VIEW {TRANSITION_CODES} AS SELECT run_id, seq, t_ns,
    tick, uid, enum_code(prev_status)::TINYINT AS prev_code,
    enum_code(status)::TINYINT AS code FROM transitions"""


def halts_query(table: str, where: str) -> str:
    """The query of the (seq, uid) keys of the halts (RUNNING to IDLE) among the rows of
    ``table`` (``TRANSITION_CODES``, qualified or not; alias ``h``) where ``where``
    holds: what ``starts_condition`` looks a change up in."""
    running, idle = int(Status.RUNNING), int(Status.IDLE)
    return (
        f"SELECT struct_pack(s := h.seq, u := h.uid) FROM {table} h WHERE h.run_id = $run_id "
        f"AND {where} AND h.prev_code = {running} AND h.code = {idle}"
    )


def starts_condition(halts: str) -> str:
    """The condition on a row of ``TRANSITION_CODES`` that it starts an activation
    (``btlog.history.resumes``): a change out of IDLE that does not follow, right after,
    the node's own halt with its result. The halts are few: they are looked up in the
    set of their (seq, uid) that the query ``halts`` gives (``halts_query``; a
    correlated ``EXISTS`` made DuckDB group every change out of IDLE: 20 s and 1.2 GB at
    30M events)."""
    idle, success, failure = (int(s) for s in (Status.IDLE, Status.SUCCESS, Status.FAILURE))
    return (
        f"prev_code = {idle} AND NOT (code IN ({success}, {failure}) AND "
        f"struct_pack(s := seq - 1, u := uid) IN ({halts}))"
    )


#: The tables users write SQL against.
PUBLIC_TABLES = ("runs", "nodes", "transitions", "blackboard", "ticks", "mutations")
INTERNAL_TABLES = ("_mutations", "_answers", "_snapshots", "_ingest")


def create_schema(con: duckdb.DuckDBPyConnection) -> None:
    """Create the ``status`` type and every table in the connection's current catalog."""
    for statement in (*SCHEMA, _CODES_OF_TABLE):
        con.execute(statement)


def only_row(
    con: duckdb.DuckDBPyConnection, query: str, params: dict | list | None = None
) -> tuple[Any, ...]:
    """The row of a query the read model always answers (one row per run); a missing
    row means the read model is damaged, which ``ValueError`` says in one line."""
    row = first_row(con, query, params)
    if row is None:
        raise ValueError("the read model is incomplete (remove its cache and try again)")
    return row


def first_row(
    con: duckdb.DuckDBPyConnection, query: str, params: dict | list | None = None
) -> tuple[Any, ...] | None:
    """The first row of ``query`` (None if it has none). The result is fetched to its
    end: DuckDB refuses new work on a connection with an unfinished result."""
    rows = (
        con.execute(query, params).fetchall()
        if params is not None
        else con.execute(query).fetchall()
    )
    return rows[0] if rows else None


def one_row(
    con: duckdb.DuckDBPyConnection, query: str, params: dict | list | None = None
) -> tuple[Any, ...]:
    """The first row of a query that always returns one (an aggregate, a key lookup)."""
    row = first_row(con, query, params)
    if row is None:
        raise LookupError(f"no row for {' '.join(query.split())[:80]!r}")
    return row


def identifier(name: str) -> str:
    """A quoted SQL identifier."""
    return '"' + name.replace('"', '""') + '"'


def literal(text: str) -> str:
    """A quoted SQL string literal (for the few statements that take no parameters:
    a view's definition, a setting)."""
    return "'" + text.replace("'", "''") + "'"


def _status_of_code(column: str) -> str:
    """The ENUM ``status`` of a column of status codes. DuckDB casts no integer to an
    ENUM; its optimizer turns a comparison of this ``CASE`` with a constant into one of
    the codes, which the Parquet row groups' statistics then answer."""
    cases = " ".join(f"WHEN {code} THEN '{name}'::status" for code, name in enumerate(STATUS_NAMES))
    return f"CASE {column} {cases} END"


def transitions_views(run_id: str, paths: list[str]) -> tuple[str, str]:
    """The statements making ``transitions`` and ``TRANSITION_CODES`` of the current
    catalog views of run ``run_id``'s status changes in the Parquet files ``paths``
    (``btlog.replay.transitions_file``): the table's columns, the ENUM's statuses; the
    codes as the files hold them."""
    rows = f"FROM read_parquet([{', '.join(literal(path) for path in paths)}])"
    return (
        f"CREATE OR REPLACE VIEW transitions AS SELECT {literal(run_id)} AS run_id, seq, t_ns, "
        f"tick, uid, {_status_of_code('prev_status')} AS prev_status, "
        f"{_status_of_code('status')} AS status {rows}",
        f"CREATE OR REPLACE VIEW {TRANSITION_CODES} AS SELECT {literal(run_id)} AS run_id, "
        f"seq, t_ns, tick, uid, prev_status AS prev_code, status AS code {rows}",
    )


def insert_arrow(
    con: duckdb.DuckDBPyConnection, table_name: str, run_id: str, table: pa.Table
) -> None:
    """Insert an Arrow table whose columns are the table's, without ``run_id``
    (``table_name`` may name its catalog: ``catalog._snapshots``)."""
    view = "_arrow_" + table_name.replace(".", "_")
    con.register(view, table)
    try:
        names = ", ".join(table.column_names)
        con.execute(
            f"INSERT INTO {table_name} (run_id, {names}) SELECT $run_id, {names} FROM {view}",
            {"run_id": run_id},
        )
    finally:
        con.unregister(view)


def discard_run(con: duckdb.DuckDBPyConnection, run_id: str) -> None:
    """Delete every row of run ``run_id`` (a failed ingestion leaves nothing behind);
    a view over a file (``transitions_views``) goes with its file."""
    tables = {
        name
        for (name,) in con.execute(
            """SELECT table_name FROM duckdb_tables()
            WHERE database_name = current_database() AND schema_name = current_schema()"""
        ).fetchall()
    }
    for table in PUBLIC_TABLES + INTERNAL_TABLES:
        if table in tables:
            con.execute(f"DELETE FROM {table} WHERE run_id = $run_id", {"run_id": run_id})

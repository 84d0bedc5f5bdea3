"""Snapshots: the state every K events, so that any moment costs one row and a short fold.

``build_snapshots`` stores, every ``snapshot_every`` events, the state before that event,
computed as SQL over the tables (``SNAPSHOTS_SQL``): a node's status (activation, last
failure) at a boundary is that of its latest transition in the blocks before it (one
aggregation per block, carried forward over the boundaries); blackboard entries hold
until the next write of their (scope, key) (``lead(seq)``, repeated over the boundaries
they span). Only the retry counts, which depend on the tree's shape, are folded by
``StateProjection`` — over the few events that change them. The projection stays the
definition of the state: a property test keeps the SQL snapshots equal to its fold.
Each row also holds its block of events (status changes as fixed-width columns), so the
state at any moment is one snapshot row plus a fold of at most ``snapshot_every``
events (``btlog.replay.database``).
"""

from __future__ import annotations

import struct
from array import array
from bisect import bisect_left, bisect_right
from dataclasses import dataclass, field
from typing import Any, cast

import duckdb
import orjson
import pyarrow as pa
import pyarrow.compute as pa_compute
import zstandard

from btlog.events import BlackboardWrite, TreeMutation
from btlog.record import format as fmt
from btlog.replay.tables import insert_arrow
from btlog.state import RECOVERY_TYPE, RETRY_TYPE, StateProjection
from btlog.status import Status
from btlog.tree.model import EXECUTION_KINDS, Tree

#: Events between two snapshots. ``state_at`` reads one snapshot row and decodes and
#: folds at most this many events (~2.5 µs each, all told), on top of a fixed ~2.5 ms
#: (the query, the tree copy). Measured (``bench_replay.py --sweep``, 2M events): median
#: 2.8-3.1 ms at K = 256 and 512, 4.0 at 1024, 4.7 at 2048, 6.3 at 4096, for the same
#: build time; 512 keeps most of the gain with a quarter of the snapshot rows of 256.
DEFAULT_SNAPSHOT_EVERY = 512
#: Events fetched from DuckDB per query while building snapshots.
FOLD_BATCH = 1 << 18
#: Blackboard values whose JSON is longer than this are not copied into every snapshot:
#: a snapshot names the write that set them (its seq), and loading it reads that one row
#: of ``blackboard``, so a large value is stored and loaded once, not once per snapshot.
INLINE_VALUE_BYTES = 4096
_STATUS_BY_CODE = tuple(Status)


@dataclass
class EventBatch:
    """The events of a seq range: status changes as columns (codes for statuses), the
    blackboard writes and tree mutations as records (``others``, in seq order)."""

    seq: list[int]
    t_ns: list[int]
    tick: list[int]
    uid: list[int]
    prev: list[int]
    status: list[int]
    writes: list[BlackboardWrite]
    mutations: list[TreeMutation] = field(default_factory=list)
    #: seqs of the writes whose value is longer than ``INLINE_VALUE_BYTES`` as JSON

    def __post_init__(self) -> None:
        writes = cast(list[BlackboardWrite | TreeMutation], self.writes)
        self.others = sorted([*writes, *self.mutations], key=_seq_of) if self.mutations else writes
        self._other_seqs = [e.seq for e in self.others]

    def fold(self, projection: StateProjection, lo: int, hi: int) -> None:
        """Apply this batch's events with ``lo <= seq < hi`` to ``projection``, in order:
        one pass over the status changes, the other events slotted in by seq."""
        seqs, other_seqs, others = self.seq, self._other_seqs, self.others
        i, end = bisect_left(seqs, lo), bisect_left(seqs, hi)
        k, last = bisect_left(other_seqs, lo), bisect_left(other_seqs, hi)
        on_status, codes = projection.on_status, _STATUS_BY_CODE
        pending = other_seqs[k] if k < last else hi
        for seq, t_ns, tick, uid, prev, status in zip(
            seqs[i:end],
            self.t_ns[i:end],
            self.tick[i:end],
            self.uid[i:end],
            self.prev[i:end],
            self.status[i:end],
            strict=True,
        ):
            while pending < seq:
                _apply_other(projection, others[k])
                k += 1
                pending = other_seqs[k] if k < last else hi
            on_status(seq, t_ns, tick, uid, codes[prev], codes[status])
        for event in others[k:last]:
            _apply_other(projection, event)

    def bound_at_most(self, attribute: str, limit: int) -> int | None:
        """One past the last seq of the batch whose ``t_ns`` (or ``tick``) is at most
        ``limit`` (None if no event of the batch is). Both never decrease along seq."""
        keys = self.t_ns if attribute == "t_ns" else self.tick
        index = bisect_right(keys, limit)
        last = self.seq[index - 1] if index else None
        for event in self.others:
            if getattr(event, attribute) <= limit and (last is None or event.seq > last):
                last = event.seq
        return None if last is None else last + 1

    def keys_of(self, seq: int) -> tuple[int, int] | None:
        """(t_ns, tick) of event ``seq`` if the batch holds it."""
        return self.first_keys(seq, seq + 1)

    def first_keys(self, lo: int, hi: int) -> tuple[int, int] | None:
        """(t_ns, tick) of the first event with ``lo <= seq < hi`` (None if there is none)."""
        found = None
        index = bisect_left(self.seq, lo)
        if index < len(self.seq) and self.seq[index] < hi:
            found = (self.seq[index], self.t_ns[index], self.tick[index])
        index = bisect_left(self._other_seqs, lo)
        if index < len(self._other_seqs) and self._other_seqs[index] < hi:
            event = self.others[index]
            if found is None or event.seq < found[0]:
                found = (event.seq, event.t_ns, event.tick)
        return None if found is None else found[1:]

    @classmethod
    def from_block(cls, data: bytes, mutations: list[TreeMutation]) -> EventBatch:
        """The batch of a snapshot row's ``events`` (see ``build_snapshots``), with the
        given mutations of its range."""
        view = memoryview(zstandard.ZstdDecompressor().decompress(data))
        (count,) = _BLOCK_HEAD.unpack_from(view)
        at, columns = _BLOCK_HEAD.size, []
        for _name, _sql, code in _BLOCK_COLUMNS:
            end = at + count * struct.calcsize(code)
            values = array(code)
            values.frombytes(view[at:end])
            columns.append(values.tolist())
            at = end
        writes = [BlackboardWrite(*row) for row in orjson.loads(view[at:])]
        seq, t_ns, tick, uid, prev, status = columns
        return cls(seq, t_ns, tick, uid, prev, status, writes, mutations)


def _seq_of(event: BlackboardWrite | TreeMutation) -> int:
    return event.seq


def _apply_other(projection: StateProjection, event: BlackboardWrite | TreeMutation) -> None:
    if isinstance(event, BlackboardWrite):
        projection.on_write(*event)
    else:
        projection.on_mutation(event)


def load_mutations(
    con: duckdb.DuckDBPyConnection, run_id: str, prefix: str = ""
) -> list[TreeMutation]:
    """Every mutation of a run, in seq order."""
    rows = con.execute(
        f"SELECT message FROM {prefix}_mutations WHERE run_id = $run_id ORDER BY seq",
        {"run_id": run_id},
    ).fetchall()
    return [fmt.decode_mutation(orjson.loads(message)) for (message,) in rows]


def build_snapshots(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    tree: Tree,
    events: int,
    every: int,
    target: str = "_snapshots",
) -> int:
    """Store a row in ``target`` (a ``_snapshots`` table) every ``every`` events (from
    seq 0): the state *before* that event, read from the tables of the connection's
    current catalog (``snapshot_rows``). Returns the row count."""
    table = snapshot_rows(con, run_id, tree, events, every)
    insert_arrow(con, target, run_id, table)
    return table.num_rows


def snapshot_rows(
    con: duckdb.DuckDBPyConnection, run_id: str, tree: Tree, events: int, every: int
) -> pa.Table:
    """The ``_snapshots`` rows of a run (without ``run_id``), one every ``every`` events.
    Built as SQL over the tables (``SNAPSHOTS_SQL``), but for the retry counts, folded
    by ``StateProjection`` over the few events that change them."""
    mutations = load_mutations(con, run_id)
    final = StateProjection(tree)
    for mutation in mutations:
        final.on_mutation(mutation)
    nodes = list(final.tree)
    execution = [n.uid for n in nodes if n.kind in EXECUTION_KINDS]
    retries = [n for n in nodes if n.type in (RETRY_TYPE, RECOVERY_TYPE)]
    counted = (
        [n.uid for n in retries],
        [child.uid for n in retries for child in n.children],
    )
    attempts = _retry_attempts(con, run_id, tree, mutations, counted, events, every)
    view = "_btlog_retry_attempts"
    con.register(view, attempts)
    try:
        params = {
            "run_id": run_id,
            "k": every,
            "n": events,
            "execution": execution,
            "large": INLINE_VALUE_BYTES,
        }
        rows = con.sql(SNAPSHOTS_SQL.format(retry_view=view), params=params).to_arrow_table()
    finally:
        con.unregister(view)
    blocks = _event_blocks(con, run_id, every, rows["write_block"].to_pylist())
    table = rows.drop_columns(["write_block"])
    return table.append_column("events", pa.array(blocks, pa.binary()))


#: A block's status changes: these columns of ``transitions``, fixed-width, in this order.
_BLOCK_COLUMNS = (
    ("seq", "seq", "q"),
    ("t_ns", "t_ns", "q"),
    ("tick", "tick", "q"),
    ("uid", "uid::INTEGER", "i"),
    ("prev", "enum_code(prev_status)::UTINYINT", "B"),
    ("status", "enum_code(status)::UTINYINT", "B"),
)
_BLOCK_HEAD = struct.Struct("<Q")


def _event_blocks(
    con: duckdb.DuckDBPyConnection, run_id: str, every: int, writes: list[str]
) -> list[bytes]:
    """The ``events`` of each snapshot row (``writes``: each block's write rows as a
    JSON list), zstd-compressed: the count of status changes (8 bytes), the status
    changes as fixed-width columns (``_BLOCK_COLUMNS``, native byte order), then the
    writes. The columns are cut from one Arrow read of ``transitions`` (in seq order,
    as the rows are stored, or sorted), so nothing is done per row in Python."""
    columns = ", ".join(f"{sql} AS {name}" for name, sql, _code in _BLOCK_COLUMNS)
    params = {"run_id": run_id, "k": every}
    rows = con.sql(
        f"SELECT {columns} FROM transitions WHERE run_id = $run_id", params={"run_id": run_id}
    ).to_arrow_table()
    seqs = rows["seq"]
    if (
        len(seqs) > 1
        and not pa_compute.all(pa_compute.less(seqs.slice(0, len(seqs) - 1), seqs.slice(1))).as_py()
    ):
        rows = rows.sort_by("seq")  # rows are stored in seq order unless a file was not
    counts = dict(
        con.execute(
            "SELECT seq // $k, count(*) FROM transitions WHERE run_id = $run_id GROUP BY ALL",
            params,
        ).fetchall()
    )
    buffers = []
    for name, _sql, _code in _BLOCK_COLUMNS:
        array = rows[name].combine_chunks()
        width = array.type.bit_width // 8
        values = array.buffers()[1] if len(array) else None
        view = memoryview(b"") if values is None else memoryview(values)
        buffers.append((view[array.offset * width :], width))
    compress = zstandard.ZstdCompressor(level=1).compress
    blocks, lo = [], 0
    for index, written in enumerate(writes):
        hi = lo + counts.get(index, 0)
        parts: list[bytes | memoryview] = [_BLOCK_HEAD.pack(hi - lo)]
        parts.extend(buffer[lo * width : hi * width] for buffer, width in buffers)
        parts.append(written.encode())
        blocks.append(compress(b"".join(parts)))
        lo = hi
    return blocks


def _latest(name: str, where: str, partition: str, value: str) -> str:
    """CTEs ``name_in`` and ``name``: for each snapshot boundary ``b`` (a multiple of $k,
    at most $n) and each ``partition`` value, ``value`` of the latest row of
    ``transitions`` matching ``where`` before ``b``. The latest row of each block of $k
    seqs is found by one aggregation, then carried forward over the boundaries, so the
    millions of rows are grouped once and only blocks x keys rows are windowed."""
    return f"""{name}_in AS (
        SELECT (seq // $k + 1) * $k AS b, {partition} AS p, arg_max({value}, seq) AS v
        FROM transitions WHERE run_id = $run_id AND {where} GROUP BY ALL),
    {name} AS (
        SELECT * FROM (
            SELECT bounds.b, keys.p AS {partition},
                last_value(i.v IGNORE NULLS) OVER (PARTITION BY keys.p ORDER BY bounds.b
                    ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW) AS v
            FROM bounds CROSS JOIN (SELECT DISTINCT p FROM {name}_in) keys
            LEFT JOIN {name}_in i ON i.b = bounds.b AND i.p = keys.p)
        WHERE v IS NOT NULL)"""


#: The snapshot rows: the state before each boundary ``b`` as ``State.to_json`` writes it
#: (large blackboard values named by seq in ``blackboard_refs``, see ``snapshot_json``).
SNAPSHOTS_SQL = (
    "WITH bounds AS (SELECT unnest(range(0, $n // $k + 1)) * $k AS b),\n"
    + ",\n".join(
        (
            _latest("status_at", "true", "uid", "enum_code(status)"),
            _latest("activation_at", "prev_status = 'IDLE'", "uid", "seq"),
            _latest("failure_at", "status = 'FAILURE'", "uid", "seq"),
            _latest(
                "leaf_at", "status <> 'IDLE' AND list_contains($execution, uid)", "run_id", "uid"
            ),
        )
    )
    + """,
    writes AS (
        SELECT unnest(range(seq // $k + 1, coalesce(nxt, $n) // $k + 1)) * $k AS b,
            scope, key, seq, type, value, length(value::VARCHAR) > $large AS big
        FROM (SELECT *, lead(seq) OVER (PARTITION BY scope, key ORDER BY seq) AS nxt
              FROM blackboard WHERE run_id = $run_id)
        WHERE coalesce(nxt, $n) // $k > seq // $k),
    scopes AS (SELECT DISTINCT b, scope FROM writes),
    entries AS (
        SELECT b, scope, json_group_object(key, CASE WHEN big THEN NULL ELSE value END) AS obj
        FROM writes WHERE type <> 'unset' GROUP BY b, scope),
    scope_refs AS (
        SELECT b, scope, json_group_object(key, seq) AS obj
        FROM writes WHERE type <> 'unset' AND big GROUP BY b, scope),
    boards AS (
        SELECT b, json_group_object(scope, coalesce(obj, '{{}}'::JSON)) AS blackboard
        FROM scopes LEFT JOIN entries USING (b, scope) GROUP BY b),
    refs AS (SELECT b, json_group_object(scope, obj) AS refs FROM scope_refs GROUP BY b),
    maps AS (
        SELECT b, 'status' AS field, json_group_object(uid::VARCHAR, v) AS value
        FROM status_at GROUP BY b
        UNION ALL SELECT b, 'activation', json_group_object(uid::VARCHAR, v)
        FROM activation_at GROUP BY b
        UNION ALL SELECT b, 'last_failure', json_group_object(uid::VARCHAR, v)
        FROM failure_at GROUP BY b),
    every_event AS (
        SELECT seq, t_ns, tick FROM transitions WHERE run_id = $run_id
        UNION ALL SELECT seq, t_ns, tick FROM blackboard WHERE run_id = $run_id
        UNION ALL SELECT seq, t_ns, tick FROM _mutations WHERE run_id = $run_id),
    write_blocks AS (
        SELECT seq // $k * $k AS b,
            list(json_array(seq, t_ns, tick, scope, key, value, type, writer_uid)
                ORDER BY seq)::JSON AS block
        FROM blackboard WHERE run_id = $run_id GROUP BY ALL),
    last_in AS (
        SELECT (seq // $k + 1) * $k AS b, max(seq) + 1 AS seq, arg_max(t_ns, seq) AS t_ns,
            arg_max(tick, seq) AS tick
        FROM every_event GROUP BY ALL),
    last_event AS (
        SELECT b, last_value(seq IGNORE NULLS) OVER upto AS seq,
            last_value(t_ns IGNORE NULLS) OVER upto AS t_ns,
            last_value(tick IGNORE NULLS) OVER upto AS tick
        FROM bounds LEFT JOIN last_in USING (b)
        WINDOW upto AS (ORDER BY b ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW)),
    first_event AS (
        SELECT seq // $k * $k AS b, arg_min(t_ns, seq) AS t_ns, arg_min(tick, seq) AS tick
        FROM every_event GROUP BY ALL)
    SELECT bounds.b AS seq, coalesce(l.t_ns, 0) AS t_ns, coalesce(l.tick, 0) AS tick,
        f.t_ns AS first_t_ns, f.tick AS first_tick,
        json_object(
            'seq', coalesce(l.seq, 0), 't_ns', coalesce(l.t_ns, 0),
            'tick', coalesce(l.tick, 0),
            'status', coalesce(s.value, '{{}}'::JSON),
            'activation', coalesce(a.value, '{{}}'::JSON),
            'last_failure', coalesce(fl.value, '{{}}'::JSON),
            'retry_attempts', coalesce(r.attempts, '{{}}')::JSON,
            'last_leaf', leaf.v,
            'blackboard', coalesce(bb.blackboard, '{{}}'::JSON),
            'blackboard_refs', rf.refs)::VARCHAR AS state,
        coalesce(wb.block, '[]')::VARCHAR AS write_block
    FROM bounds
    LEFT JOIN last_event l USING (b)
    LEFT JOIN first_event f USING (b)
    LEFT JOIN maps s ON s.b = bounds.b AND s.field = 'status'
    LEFT JOIN maps a ON a.b = bounds.b AND a.field = 'activation'
    LEFT JOIN maps fl ON fl.b = bounds.b AND fl.field = 'last_failure'
    LEFT JOIN {retry_view} r ON r.b = bounds.b
    LEFT JOIN leaf_at leaf ON leaf.b = bounds.b
    LEFT JOIN boards bb ON bb.b = bounds.b
    LEFT JOIN refs rf ON rf.b = bounds.b
    LEFT JOIN write_blocks wb ON wb.b = bounds.b
    ORDER BY bounds.b"""
)


def _retry_attempts(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    tree: Tree,
    mutations: list[TreeMutation],
    counted: tuple[list[int], list[int]],
    events: int,
    every: int,
) -> pa.Table:
    """``State.retry_attempts`` at each boundary where it is not empty, as (b, JSON): the
    projection folded over the only events that change it — failures of retries' children,
    the retry nodes' own changes, and the mutations (which may add retries). ``counted``:
    the uids of every retry node and of every child of one, all mutations applied."""
    rows = con.execute(
        """SELECT seq, t_ns, tick, uid, enum_code(prev_status), enum_code(status)
        FROM transitions WHERE run_id = $run_id
            AND ((status = 'FAILURE' AND list_contains($children, uid))
                OR (status <> 'RUNNING' AND list_contains($retries, uid)))
        ORDER BY seq""",
        {"run_id": run_id, "retries": counted[0], "children": counted[1]},
    ).fetchall()
    projection, codes = StateProjection(tree), _STATUS_BY_CODE
    attempts = projection.state.retry_attempts
    pending = iter(mutations)
    mutation = next(pending, None)
    bounds: list[int] = []
    texts: list[str] = []

    def hold(after: int, upto: int) -> None:
        """The counts after event ``after`` hold at the boundaries in (after, upto]."""
        if attempts:
            text = orjson.dumps({str(k): v for k, v in attempts.items()}).decode()
            for b in range((after // every + 1) * every, upto // every * every + 1, every):
                bounds.append(b)
                texts.append(text)

    last: int | None = None
    for seq, t_ns, tick, uid, prev, status in rows:
        if last is not None:
            hold(last, seq)
        while mutation is not None and mutation.seq < seq:
            projection.on_mutation(mutation)
            mutation = next(pending, None)
        projection.on_status(seq, t_ns, tick, uid, codes[prev], codes[status])
        last = seq
    if last is not None:
        hold(last, events)
    return pa.table({"b": pa.array(bounds, pa.int64()), "attempts": pa.array(texts, pa.string())})


def load_snapshot(
    con: duckdb.DuckDBPyConnection, run_id: str, text: str, prefix: str = ""
) -> dict[str, Any]:
    """A snapshot row's state as ``State.from_json`` reads it: the large values it names
    by seq are read from the ``blackboard`` table (``prefix``: the catalog)."""
    data = orjson.loads(text)
    refs = data.pop("blackboard_refs", None)
    if refs:
        seqs = [seq for entries in refs.values() for seq in entries.values()]
        rows = con.execute(
            f"SELECT seq, value FROM {prefix}blackboard "
            "WHERE run_id = $run_id AND list_contains($seqs, seq)",
            {"run_id": run_id, "seqs": seqs},
        ).fetchall()
        values = {seq: None if value is None else orjson.loads(value) for seq, value in rows}
        for scope, entries in refs.items():
            for key, seq in entries.items():
                data["blackboard"][scope][key] = values[seq]
    return data

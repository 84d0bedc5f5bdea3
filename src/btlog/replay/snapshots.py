"""Snapshots: the state every K events, so that any moment costs one row and a short fold.

``build_snapshots`` stores, every ``snapshot_every`` events, the state before that event,
computed as SQL over the tables (``SNAPSHOTS_SQL``): a node's status (activation, last
failure) at a boundary is that of its latest transition in the blocks before it (one
aggregation per block, carried forward over the boundaries); blackboard entries hold
until the next write of their (scope, key) (``lead(seq)``, repeated over the boundaries
they span). Only the retry counts, which depend on the tree's shape, are folded by
``StateProjection`` — over the few events that change them. The projection stays the
definition of the state: a property test keeps the SQL snapshots equal to its fold.
Each row also holds its block of events (``btlog.replay.blocks``), so the state at any
moment is one snapshot row plus a fold of at most ``snapshot_every`` events
(``btlog.replay.run``).

A run's snapshots are ``snapshot_interval`` events apart: the interval asked for, or more
for a run whose state is large (a wide tree, a big blackboard), so that their total size
stays linear in the run's length (``STATE_BYTES_PER_EVENT``), never states x boundaries.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import duckdb
import orjson

from btlog.events import TreeMutation
from btlog.record import format as fmt
from btlog.replay.blocks import STATUS_BY_CODE, event_blocks
from btlog.replay.tables import TRANSITION_CODES as CODES
from btlog.replay.tables import halts_query, insert_arrow, starts_condition
from btlog.state import RECOVERY_TYPE, RETRY_TYPE, StateProjection
from btlog.status import Status
from btlog.tree.model import EXECUTION_KINDS, Tree

if TYPE_CHECKING:  # pyarrow builds the read model; a warm answer reads it without pyarrow
    import pyarrow as pa


IDLE, RUNNING, SUCCESS, FAILURE = (
    int(status) for status in (Status.IDLE, Status.RUNNING, Status.SUCCESS, Status.FAILURE)
)
#: Events between two snapshots. ``state_at`` reads one snapshot row and decodes and
#: folds at most this many events (~2.5 µs each, all told), on top of a fixed ~2.5 ms
#: (the query, the tree copy). Measured (``bench_replay.py --sweep``, 2M events): median
#: 2.8-3.1 ms at K = 256 and 512, 4.0 at 1024, 4.7 at 2048, 6.3 at 4096, for the same
#: build time; 512 keeps most of the gain with a quarter of the snapshot rows of 256.
DEFAULT_SNAPSHOT_EVERY = 512
#: Blackboard values whose JSON is longer than this are not copied into every snapshot:
#: a snapshot names the write that set them (its seq), and loading it reads that one row
#: of ``blackboard``, so a large value is stored and loaded once, not once per snapshot.
INLINE_VALUE_BYTES = 4096
#: Bytes of snapshot state stored per event of the run, at most (besides the first
#: snapshot): a state of S bytes gets snapshots every S / 64 events or more. Folding an
#: event costs about as much as decoding 64 bytes of a snapshot, so a moment still costs
#: about as much as reading one state, and 150,000 nodes or 200 MB of blackboard values
#: are stored a few times, not once every 512 events (issue 24).
STATE_BYTES_PER_EVENT = 64
#: Snapshots per segment: a segment's snapshots are built together, on the first state
#: asked for in its range (``segment_of``), so a first answer about a moment of a long
#: run builds one segment, not the whole run's snapshots (issue 27).
SEGMENT_BLOCKS = 2048
#: Bytes of one node's entries in a snapshot (status, activation, last failure).
_NODE_STATE_BYTES = 48
#: Bytes of a blackboard entry besides its key and value (quotes, scope, separators).
_ENTRY_STATE_BYTES = 8


def snapshot_interval(
    con: duckdb.DuckDBPyConnection, run_id: str, requested: int, prefix: str = ""
) -> int:
    """The events between two snapshots of the run loaded in ``con``: ``requested``, or
    the bytes its largest state may take (``state_bytes``) over ``STATE_BYTES_PER_EVENT``
    when that is more than the default interval (a small state is stored as often as
    asked)."""
    spread = -(-state_bytes(con, run_id, prefix) // STATE_BYTES_PER_EVENT)
    return max(requested, spread) if spread > DEFAULT_SNAPSHOT_EVERY else requested


def state_bytes(con: duckdb.DuckDBPyConnection, run_id: str, prefix: str = "") -> int:
    """A bound on the bytes of any snapshot of the run: every node (mutations'
    included) with its three entries, every blackboard key with its longest value as a
    snapshot stores it (a large value is named by its seq, see ``INLINE_VALUE_BYTES``)."""
    (nodes,) = con.execute(
        f"SELECT count(*) FROM {prefix}nodes WHERE run_id = $run_id", {"run_id": run_id}
    ).fetchone() or (0,)
    (entries,) = con.execute(
        f"""SELECT coalesce(sum(strlen(scope) + strlen(key) + $extra
                + CASE WHEN longest > $large THEN 20 ELSE longest END), 0)
        FROM (SELECT scope, key, max(strlen(value::VARCHAR)) AS longest
              FROM {prefix}blackboard WHERE run_id = $run_id GROUP BY scope, key)""",
        {"run_id": run_id, "extra": _ENTRY_STATE_BYTES, "large": INLINE_VALUE_BYTES},
    ).fetchone() or (0,)
    return int(nodes) * _NODE_STATE_BYTES + int(entries)


def load_mutations(
    con: duckdb.DuckDBPyConnection, run_id: str, prefix: str = ""
) -> list[TreeMutation]:
    """Every mutation of a run, in seq order."""
    rows = con.execute(
        f"SELECT message FROM {prefix}_mutations WHERE run_id = $run_id ORDER BY seq",
        {"run_id": run_id},
    ).fetchall()
    return [fmt.decode_mutation(orjson.loads(message)) for (message,) in rows]


def segments(events: int, every: int) -> int:
    """How many segments of ``SEGMENT_BLOCKS`` snapshots a run of ``events`` events has
    (its snapshots are every ``every`` events, from seq 0 to the last multiple)."""
    return (events // every) // SEGMENT_BLOCKS + 1


def segment_of(index: int) -> int:
    """The segment holding snapshot ``index`` (the one before event ``index * every``)."""
    return index // SEGMENT_BLOCKS


def segment_bounds(events: int, every: int, segment: int | None) -> tuple[int, int]:
    """(first, last) boundary (seq) of the snapshots of ``segment`` (None: every one)."""
    last = events // every
    if segment is None:
        return 0, last * every
    first = segment * SEGMENT_BLOCKS
    if not 0 <= first <= last:
        raise ValueError(f"segment {segment} is outside a run of {events} events")
    return first * every, min(last, first + SEGMENT_BLOCKS - 1) * every


def build_snapshots(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    tree: Tree,
    events: int,
    every: int,
    target: str = "_snapshots",
    segment: int | None = None,
) -> int:
    """Store a row in ``target`` (a ``_snapshots`` table) every ``every`` events (from
    seq 0) — those of ``segment`` only, or of every segment, one at a time (None): the
    state *before* that event, read from the tables of the connection's current catalog
    (``snapshot_rows``). Returns the row count."""
    stored = 0
    for number in range(segments(events, every)) if segment is None else (segment,):
        table = snapshot_rows(con, run_id, tree, events, every, number)
        insert_arrow(con, target, run_id, table)
        stored += table.num_rows
        del table
    return stored


def snapshot_rows(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    tree: Tree,
    events: int,
    every: int,
    segment: int | None = None,
) -> pa.Table:
    """The ``_snapshots`` rows of a run (without ``run_id``), one every ``every`` events:
    those of ``segment`` (None: all of them). Built as SQL over the tables
    (``SNAPSHOTS_SQL``): what holds at the segment's first boundary is one aggregation
    over the events before it, so a segment costs a scan of the run up to it plus the
    work of its own events. The retry counts are folded by ``StateProjection`` over the
    few events that change them."""
    import pyarrow as pa

    first, last = segment_bounds(events, every, segment)
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
    attempts = _retry_attempts(con, run_id, tree, mutations, counted, events, every, first, last)
    view = "_btlog_retry_attempts"
    con.register(view, attempts)
    try:
        params = {
            "run_id": run_id,
            "k": every,
            "n": events,
            "b0": first,
            "b1": last,
            **_last_before(con, run_id, first, every),
            "execution": execution,
            "large": INLINE_VALUE_BYTES,
        }
        rows = con.sql(SNAPSHOTS_SQL.format(retry_view=view), params=params).to_arrow_table()
    finally:
        con.unregister(view)
    blocks = event_blocks(con, run_id, every, rows.num_rows, first // every)
    return rows.append_column("events", pa.array(blocks, pa.binary()))


#: The rows before $b0 as ``_latest`` reads them: the latest seq of each kind of change
#: of each node (a few rows a node), so the run before a segment is grouped once, cheaply
#: (``max`` over small keys, not ``arg_max`` over blocks x nodes).
PREFIX = "prefix WHERE true"
#: The rows before $b0 themselves, for what the latest kinds of change cannot tell.
PREFIX_ROWS = f"{CODES} WHERE run_id = $run_id AND seq < $b0"


def _latest(name: str, where: str, partition: str, value: str, before: str = PREFIX) -> str:
    """CTEs ``name_in`` and ``name``: for each snapshot boundary ``b`` (a multiple of $k,
    from $b0 to $b1) and each ``partition`` value, ``value`` of the latest row of
    ``transitions`` matching ``where`` before ``b``. The latest row of each block of $k
    seqs, and of the rows before $b0 (read from ``before``: ``PREFIX`` or
    ``PREFIX_ROWS``) taken as one, is found by one aggregation, then carried forward
    over the boundaries, so the millions of rows are grouped once and only blocks x
    keys rows are windowed."""
    return f"""{name}_in AS (
        SELECT $b0 AS b, {partition} AS p, arg_max({value}, seq) AS v
        FROM {before} AND {where} GROUP BY ALL
        UNION ALL
        SELECT (seq // $k + 1) * $k AS b, {partition} AS p, arg_max({value}, seq) AS v
        FROM {CODES} WHERE run_id = $run_id AND seq >= $b0 AND seq < $b1 AND {where}
        GROUP BY ALL),
    {name} AS (
        SELECT * FROM (
            SELECT bounds.b, keys.p AS {partition},
                last_value(i.v IGNORE NULLS) OVER (PARTITION BY keys.p ORDER BY bounds.b
                    ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW) AS v
            FROM bounds CROSS JOIN (SELECT DISTINCT p FROM {name}_in) keys
            LEFT JOIN {name}_in i ON i.b = bounds.b AND i.p = keys.p)
        WHERE v IS NOT NULL)"""


#: A change that starts an activation (``btlog.history.resumes``), its halts read once
#: (the CTE ``halts``) for the run before the segment and the segment's own rows.
STARTS_WHERE = starts_condition("FROM halts")

#: The snapshot rows: the state before each boundary ``b`` as ``State.to_json`` writes it
#: (large blackboard values named by seq in ``blackboard_refs``, see ``snapshot_json``).
SNAPSHOTS_SQL = (
    "WITH bounds AS (SELECT unnest(range($b0 // $k, $b1 // $k + 1)) * $k AS b),\n"
    "prefix AS (SELECT uid, prev_code, code, max(seq) AS seq, $run_id AS run_id\n"
    f"    FROM {CODES} WHERE run_id = $run_id AND seq < $b0\n"
    "    GROUP BY uid, prev_code, code),\n"
    f"halts AS MATERIALIZED ({halts_query(CODES, 'h.seq < $b1')}),\n"
    + ",\n".join(
        (
            _latest("status_at", "true", "uid", "code"),
            _latest("activation_at", STARTS_WHERE, "uid", "seq", PREFIX_ROWS),
            _latest("failure_at", f"code = {FAILURE}", "uid", "seq"),
            _latest(
                "leaf_at", f"code <> {IDLE} AND list_contains($execution, uid)", "run_id", "uid"
            ),
            f"""halted_at AS (
        SELECT seq + 1 AS b, uid AS v FROM {CODES}
        WHERE run_id = $run_id AND prev_code = {RUNNING} AND code = {IDLE}
            AND (seq + 1) % $k = 0 AND seq >= $b0 - 1 AND seq < $b1)""",
        )
    )
    + """,
    board AS (
        SELECT scope, key, max(seq) AS seq, arg_max(type, seq) AS type,
            arg_max(value, seq) AS value
        FROM blackboard WHERE run_id = $run_id AND seq < $b0 GROUP BY scope, key
        UNION ALL SELECT scope, key, seq, type, value FROM blackboard
        WHERE run_id = $run_id AND seq >= $b0 AND seq < $b1),
    writes AS (
        SELECT unnest(range(greatest(seq // $k + 1, $b0 // $k),
                least(coalesce(nxt, $n), $b1) // $k + 1)) * $k AS b,
            scope, key, seq, type, value, length(value::VARCHAR) > $large AS big
        FROM (SELECT *, lead(seq) OVER (PARTITION BY scope, key ORDER BY seq) AS nxt
              FROM board)
        WHERE least(coalesce(nxt, $n), $b1) // $k > seq // $k),
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
        SELECT seq, t_ns, tick FROM transitions
        WHERE run_id = $run_id AND seq >= $b0 AND seq < $b1 + $k
        UNION ALL SELECT seq, t_ns, tick FROM blackboard
        WHERE run_id = $run_id AND seq >= $b0 AND seq < $b1 + $k
        UNION ALL SELECT seq, t_ns, tick FROM _mutations
        WHERE run_id = $run_id AND seq >= $b0 AND seq < $b1 + $k),
    last_in AS (
        SELECT (seq // $k + 1) * $k AS b, max(seq) + 1 AS seq,
            arg_max(t_ns, seq) AS t_ns, arg_max(tick, seq) AS tick
        FROM every_event WHERE seq < $b1 GROUP BY ALL
        UNION ALL SELECT $b0, $before_seq, $before_t_ns, $before_tick
        WHERE $before_seq IS NOT NULL),
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
            'blackboard_refs', rf.refs, 'halted', hl.v)::VARCHAR AS state
    FROM bounds
    LEFT JOIN last_event l USING (b)
    LEFT JOIN first_event f USING (b)
    LEFT JOIN maps s ON s.b = bounds.b AND s.field = 'status'
    LEFT JOIN maps a ON a.b = bounds.b AND a.field = 'activation'
    LEFT JOIN maps fl ON fl.b = bounds.b AND fl.field = 'last_failure'
    LEFT JOIN {retry_view} r ON r.b = bounds.b
    LEFT JOIN leaf_at leaf ON leaf.b = bounds.b
    LEFT JOIN halted_at hl ON hl.b = bounds.b
    LEFT JOIN boards bb ON bb.b = bounds.b
    LEFT JOIN refs rf ON rf.b = bounds.b
    ORDER BY bounds.b"""
)


def _last_before(
    con: duckdb.DuckDBPyConnection, run_id: str, seq: int, every: int
) -> dict[str, int | None]:
    """The last event before ``seq`` as ``before_seq`` (its seq + 1), ``before_t_ns``
    and ``before_tick`` (None when there is none): looked for in the block before
    ``seq`` first (it is there in a run without gaps), then in the whole run before."""
    found = None
    for lo in dict.fromkeys((max(seq - every, 0), 0)):
        where = "WHERE run_id = $run_id AND seq >= $lo AND seq < $seq"
        rows = con.execute(
            f"""SELECT seq + 1, t_ns, tick FROM (
                SELECT seq, t_ns, tick FROM transitions {where}
                UNION ALL SELECT seq, t_ns, tick FROM blackboard {where}
                UNION ALL SELECT seq, t_ns, tick FROM _mutations {where})
            ORDER BY seq DESC LIMIT 1""",
            {"run_id": run_id, "lo": lo, "seq": seq},
        ).fetchall()
        found = rows[0] if rows else None
        if found is not None or seq == 0:
            break
    keys = ("before_seq", "before_t_ns", "before_tick")
    return dict(zip(keys, found if found is not None else (None, None, None), strict=True))


def _retry_attempts(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    tree: Tree,
    mutations: list[TreeMutation],
    counted: tuple[list[int], list[int]],
    events: int,
    every: int,
    first: int,
    last: int,
) -> pa.Table:
    """``State.retry_attempts`` at each boundary from ``first`` to ``last`` where it is
    not empty, as (b, JSON): the
    projection folded over the only events that change it — failures of retries' children,
    the retry nodes' own changes, and the mutations (which may add retries). ``counted``:
    the uids of every retry node and of every child of one, all mutations applied."""
    import pyarrow as pa

    rows = (
        _rows_in_batches(
            con,
            f"""SELECT seq, t_ns, tick, uid, prev_code, code
        FROM {CODES} WHERE run_id = $run_id AND seq < $last
            AND ((code = {FAILURE} AND list_contains($children, uid))
                OR (code <> {RUNNING} AND list_contains($retries, uid)))
        ORDER BY seq""",
            {"run_id": run_id, "retries": counted[0], "children": counted[1], "last": last},
        )
        if counted[0]
        else iter(())
    )
    projection, codes = StateProjection(tree), STATUS_BY_CODE
    attempts = projection.state.retry_attempts
    pending = iter(mutations)
    mutation = next(pending, None)
    bounds: list[int] = []
    texts: list[str] = []

    def hold(after: int, upto: int) -> None:
        """The counts after event ``after`` hold at the boundaries in (after, upto]."""
        start = max((after // every + 1) * every, first)
        stop = min(upto // every * every, last)
        if attempts and start <= stop:
            text = orjson.dumps({str(k): v for k, v in attempts.items()}).decode()
            for b in range(start, stop + 1, every):
                bounds.append(b)
                texts.append(text)

    latest: int | None = None
    for seq, t_ns, tick, uid, prev, status in rows:
        if seq >= last:
            break
        if latest is not None:
            hold(latest, seq)
        while mutation is not None and mutation.seq < seq:
            projection.on_mutation(mutation)
            mutation = next(pending, None)
        projection.on_status(seq, t_ns, tick, uid, codes[prev], codes[status])
        latest = seq
    if latest is not None:
        hold(latest, events)
    return pa.table({"b": pa.array(bounds, pa.int64()), "attempts": pa.array(texts, pa.string())})


#: Rows fetched at a time where a run's rows are folded in Python (memory stays bounded).
FETCH_ROWS = 1 << 16


def _rows_in_batches(
    con: duckdb.DuckDBPyConnection, query: str, params: dict
) -> Iterator[tuple[Any, ...]]:
    """The rows of ``query``, fetched ``FETCH_ROWS`` at a time (never the whole result)."""
    cursor = con.execute(query, params)
    while batch := cursor.fetchmany(FETCH_ROWS):
        yield from batch


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

"""Snapshots: the state every K events, so that any moment costs one row and a short fold.

``build_snapshots`` folds the whole run once with ``StateProjection`` (the only fold),
storing every ``snapshot_every`` events the state at that point *and* the block of
events up to the next snapshot (compressed). The state at any moment is then one row
plus a fold of at most ``snapshot_every`` events (``btlog.replay.database``). Building
them runs every event through Python once: the dominant cost of a long run.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from dataclasses import dataclass, field
from typing import Any, cast

import duckdb
import orjson
import pyarrow as pa
import zstandard

from btlog.events import BlackboardWrite, TreeMutation
from btlog.record import format as fmt
from btlog.replay.tables import insert_arrow
from btlog.state import State, StateProjection
from btlog.status import Status
from btlog.tree.model import Tree

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
    large: set[int] = field(default_factory=set)

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

    def note_large(self, origins: dict[tuple[str, str], int], lo: int, hi: int) -> None:
        """Update ``origins`` ((scope, key) → seq of the write that set a large value)
        with this batch's writes with ``lo <= seq < hi``."""
        for write in self.writes:
            if lo <= write.seq < hi:
                if write.seq in self.large:
                    origins[(write.scope, write.key)] = write.seq
                else:
                    origins.pop((write.scope, write.key), None)

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

    def block(self, lo: int, hi: int) -> bytes:
        """The status changes and writes with ``lo <= seq < hi``, compressed (mutations
        are kept apart, in ``_mutations``)."""
        i, j = bisect_left(self.seq, lo), bisect_left(self.seq, hi)
        write_seqs = [w.seq for w in self.writes] if self.mutations else self._other_seqs
        writes = [
            list(w) for w in self.writes[bisect_left(write_seqs, lo) : bisect_left(write_seqs, hi)]
        ]
        columns = [
            c[i:j] for c in (self.seq, self.t_ns, self.tick, self.uid, self.prev, self.status)
        ]
        data = orjson.dumps({"status": columns, "writes": writes}, default=repr)
        return zstandard.ZstdCompressor(level=1).compress(data)

    @classmethod
    def from_block(cls, data: bytes, mutations: list[TreeMutation]) -> EventBatch:
        """The batch of a ``block``, with the given mutations of its range."""
        message = orjson.loads(zstandard.ZstdDecompressor().decompress(data))
        writes = [BlackboardWrite(*row) for row in message["writes"]]
        seq, t_ns, tick, uid, prev, status = message["status"]
        return cls(seq, t_ns, tick, uid, prev, status, writes, mutations)


def fetch_events(
    con: duckdb.DuckDBPyConnection,
    run_id: str,
    lo: int,
    hi: int,
    mutations: list[TreeMutation],
    prefix: str = "",
) -> EventBatch:
    """The events with ``lo <= seq < hi`` of a run, from the tables (``prefix``: the
    catalog, e.g. ``"run0."``)."""
    params = {"run_id": run_id, "lo": lo, "hi": hi}
    table = con.sql(
        f"""SELECT seq, t_ns, tick, uid, enum_code(prev_status),
            enum_code(status) FROM {prefix}transitions
        WHERE run_id = $run_id AND seq >= $lo AND seq < $hi ORDER BY seq""",
        params=params,
    ).to_arrow_table()
    columns = [column.to_pylist() for column in table.columns]
    rows = con.execute(
        f"""SELECT seq, t_ns, tick, scope, key, value, type, writer_uid
        FROM {prefix}blackboard WHERE run_id = $run_id AND seq >= $lo AND seq < $hi
        ORDER BY seq""",
        params,
    ).fetchall()
    loads = orjson.loads
    writes = [
        BlackboardWrite(
            seq, t, tick, scope, key, None if value is None else loads(value), kind, writer
        )
        for seq, t, tick, scope, key, value, kind, writer in rows
    ]
    large = {row[0] for row in rows if row[5] is not None and len(row[5]) > INLINE_VALUE_BYTES}
    seq, t_ns, tick, uid, prev, status = columns
    inside = [m for m in mutations if lo <= m.seq < hi]
    return EventBatch(seq, t_ns, tick, uid, prev, status, writes, inside, large)


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
    con: duckdb.DuckDBPyConnection, run_id: str, tree: Tree, events: int, every: int
) -> int:
    """Fold the whole run once. Every ``every`` events (from seq 0) store a row in
    ``_snapshots``: the state *before* that event, and the block of the next ``every``
    events (so one row gives any state up to the next snapshot). Returns the row count."""
    mutations = load_mutations(con, run_id)
    projection = StateProjection(tree)
    batch_size = max(every, FOLD_BATCH // every * every)
    rows: list[tuple] = []
    origins: dict[tuple[str, str], int] = {}
    for lo in range(0, events, batch_size):
        hi = min(lo + batch_size, events)
        batch = fetch_events(con, run_id, lo, hi, mutations)
        for start in range(lo, hi, every):
            stop = min(start + every, hi)
            first, block = batch.first_keys(start, stop), batch.block(start, stop)
            rows.append(_snapshot_row(projection.state, origins, start, first, block))
            batch.fold(projection, start, stop)
            batch.note_large(origins, start, stop)
    if events % every == 0:
        empty = EventBatch([], [], [], [], [], [], []).block(0, 0)
        rows.append(_snapshot_row(projection.state, origins, events, None, empty))
    _insert_snapshots(con, run_id, rows)
    return len(rows)


def _snapshot_row(
    state: State,
    origins: dict[tuple[str, str], int],
    seq: int,
    first: tuple[int, int] | None,
    block: bytes,
) -> tuple:
    first_t, first_tick = (None, None) if first is None else first
    return (seq, state.t_ns, state.tick, first_t, first_tick, snapshot_json(state, origins), block)


def snapshot_json(state: State, origins: dict[tuple[str, str], int]) -> str:
    """The state as stored in a snapshot row: ``State.to_json`` with each large value
    (``origins``: (scope, key) → seq of the write that set it) left out — its place kept
    with null — and named in ``blackboard_refs`` by that seq instead."""
    data = state.to_json()
    if origins:
        blackboard = {scope: dict(entries) for scope, entries in state.blackboard.items()}
        refs: dict[str, dict[str, int]] = {}
        for (scope, key), seq in origins.items():
            blackboard[scope][key] = None
            refs.setdefault(scope, {})[key] = seq
        data["blackboard"], data["blackboard_refs"] = blackboard, refs
    return orjson.dumps(data, default=repr).decode()


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


def _insert_snapshots(con: duckdb.DuckDBPyConnection, run_id: str, rows: list[tuple]) -> None:
    names = ("seq", "t_ns", "tick", "first_t_ns", "first_tick", "state", "events")
    types = (pa.int64(), pa.int64(), pa.int64(), pa.int64(), pa.int64(), pa.string(), pa.binary())
    columns = list(zip(*rows, strict=True))
    table = pa.table({n: pa.array(c, t) for n, c, t in zip(names, columns, types, strict=True)})
    insert_arrow(con, "_snapshots", run_id, table)

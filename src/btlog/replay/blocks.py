"""A snapshot's block of events: the events between two snapshots, stored in its row.

A block holds the status changes as fixed-width columns (``_BLOCK_COLUMNS``), cut from one
Arrow read of ``transitions`` so that nothing is done per row in Python, followed by the
block's blackboard writes as JSON; the whole is zstd-compressed. ``event_blocks`` writes
the blocks of a run, ``EventBatch.from_block`` reads one back and folds it into a
``StateProjection``, given the tree mutations of its range (blocks do not hold them).
"""

from __future__ import annotations

import struct
from array import array
from bisect import bisect_left, bisect_right
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import duckdb
import orjson
import zstandard

from btlog.events import BlackboardWrite, TreeMutation
from btlog.state import StateProjection
from btlog.status import Status

if TYPE_CHECKING:  # pyarrow builds the read model; a warm answer reads it without pyarrow
    import pyarrow as pa

#: Status codes as stored (DuckDB's ``enum_code`` of the status enum): the order of ``Status``.
STATUS_BY_CODE = tuple(Status)


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
        on_status, codes = projection.on_status, STATUS_BY_CODE
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
        raw = zstandard.ZstdDecompressor().decompress(data)
        view = memoryview(raw)
        (count,) = _BLOCK_HEAD.unpack_from(view)
        at, columns = _BLOCK_HEAD.size, []
        for _name, _sql, code in _BLOCK_COLUMNS:
            end = at + count * struct.calcsize(code)
            values = array(code)
            values.frombytes(view[at:end])
            columns.append(values.tolist())
            at = end
        writes = [BlackboardWrite(*row) for row in _write_rows_of(raw, at)]
        seq, t_ns, tick, uid, prev, status = columns
        return cls(seq, t_ns, tick, uid, prev, status, writes, mutations)


#: A block's writes longer than this are parsed a row at a time: orjson (yyjson) would
#: reserve several times a document's size to parse it whole.
_PARSED_WHOLE_BYTES = 8 << 20


def _write_rows_of(raw: bytes, at: int) -> list:
    """The write rows of a block, its JSON list starting at ``raw[at]``. A long one is
    parsed a row at a time: its rows are one a line (compact JSON has no raw newline)."""
    if len(raw) - at <= _PARSED_WHOLE_BYTES:
        return orjson.loads(memoryview(raw)[at:])
    view, rows = memoryview(raw), []
    start = raw.find(b"\n", at) + 1
    if start == 0:  # one line: a block written before rows went one a line
        return orjson.loads(view[at:])
    while start < len(raw):
        end = raw.find(b"\n", start)
        end = len(raw) - 1 if end < 0 else end - 1  # before the "," (or the last "]")
        rows.append(orjson.loads(view[start:end]))
        start = end + 2
    return rows


def _seq_of(event: BlackboardWrite | TreeMutation) -> int:
    return event.seq


def _apply_other(projection: StateProjection, event: BlackboardWrite | TreeMutation) -> None:
    if isinstance(event, BlackboardWrite):
        projection.on_write(*event)
    else:
        projection.on_mutation(event)


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


def event_blocks(
    con: duckdb.DuckDBPyConnection, run_id: str, every: int, count: int, first: int = 0
) -> list[bytes]:
    """The ``events`` of the ``count`` snapshot rows from snapshot ``first`` on (the rows
    of one segment: only its events are read), zstd-compressed: the count of status
    changes (8 bytes), the status changes as fixed-width columns (``_BLOCK_COLUMNS``,
    native byte order), then the writes as a JSON list. The columns are cut from one
    Arrow read of ``transitions`` (in seq order, as the rows are stored, or sorted), the
    writes' JSON from DuckDB's (``_write_rows``), so nothing is done per row in Python."""
    import pyarrow.compute as pa_compute

    columns = ", ".join(f"{sql} AS {name}" for name, sql, _code in _BLOCK_COLUMNS)
    start, stop = first * every, (first + count) * every
    params = {"run_id": run_id, "k": every, "lo": start, "hi": stop}
    within = "run_id = $run_id AND seq >= $lo AND seq < $hi"
    rows = con.sql(
        f"SELECT {columns} FROM transitions WHERE {within}",
        params={"run_id": run_id, "lo": start, "hi": stop},
    ).to_arrow_table()
    seqs = rows["seq"]
    if (
        len(seqs) > 1
        and not pa_compute.all(pa_compute.less(seqs.slice(0, len(seqs) - 1), seqs.slice(1))).as_py()
    ):
        rows = rows.sort_by("seq")  # rows are stored in seq order unless a file was not
    counts = dict(
        con.execute(
            f"SELECT seq // $k, count(*) FROM transitions WHERE {within} GROUP BY ALL",
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
    compressor = zstandard.ZstdCompressor(level=1)
    writes = _write_rows(con, params)
    pending = next(writes, None)
    blocks, lo = [], 0
    for index in range(first, first + count):
        hi = lo + counts.get(index, 0)
        parts: list[bytes | memoryview] = [_BLOCK_HEAD.pack(hi - lo)]
        parts.extend(buffer[lo * width : hi * width] for buffer, width in buffers)
        if pending is not None and pending[0] == index:
            parts.extend(pending[1])
            pending = next(writes, None)
        else:
            parts.append(b"[]")
        blocks.append(_compressed(compressor, parts))
        lo = hi
    return blocks


#: Write rows fetched from DuckDB at a time (a row may hold a value of megabytes).
_WRITE_ROWS_PER_BATCH = 4096


def _write_rows(
    con: duckdb.DuckDBPyConnection, params: dict
) -> Iterator[tuple[int, list[bytes | memoryview]]]:
    """(block index, the block's write rows as the parts of one JSON list) for each block
    with writes in ``$lo <= seq < $hi`` (``params``: those, ``run_id`` and ``k``), in
    order. DuckDB writes each row's JSON, preceded by a comma and a newline (so a long
    block can be parsed a row at a time), and the rows are streamed in small batches: a
    block's parts are slices of the batches' string buffers, never one string of the
    whole block."""
    import pyarrow as pa
    import pyarrow.compute as pa_compute

    reader = con.sql(
        """SELECT seq // $k AS block, ',' || chr(10) || json_array(seq, t_ns, tick, scope, key,
            value, type, writer_uid)::VARCHAR AS row
        FROM blackboard WHERE run_id = $run_id AND seq >= $lo AND seq < $hi ORDER BY seq""",
        params=params,
    ).to_arrow_reader(_WRITE_ROWS_PER_BATCH)
    current: int | None = None
    parts: list[bytes | memoryview] = []
    for batch in reader:
        blocks, texts = batch.column(0), batch.column(1)
        data = texts.buffers()[2]
        offsets = memoryview(texts.buffers()[1]).cast(
            "q" if pa.types.is_large_string(texts.type) else "i"
        )[texts.offset :]
        starts = [0, *(pa_compute.indices_nonzero(_changes(blocks)).to_pylist())]
        for number, first in enumerate(starts):
            block = blocks[first].as_py()
            last = starts[number + 1] if number + 1 < len(starts) else len(blocks)
            if block != current:
                if current is not None:
                    yield current, _json_list(parts)
                current, parts = block, []
            parts.append(memoryview(data)[offsets[first] : offsets[last]])
    if current is not None:
        yield current, _json_list(parts)


def _changes(blocks: pa.Array) -> pa.Array:
    """For each row, whether its block differs from the previous row's (False first)."""
    import pyarrow as pa
    import pyarrow.compute as pa_compute

    if len(blocks) < 2:
        return pa.array([False] * len(blocks))
    differs = pa_compute.not_equal(blocks.slice(1), blocks.slice(0, len(blocks) - 1))
    return pa.concat_arrays([pa.array([False]), differs])


def _json_list(parts: list[bytes | memoryview]) -> list[bytes | memoryview]:
    """Rows each preceded by a comma, as a JSON list: the first comma becomes ``[``."""
    return [b"[", parts[0][1:], *parts[1:], b"]"]


def _compressed(compressor: zstandard.ZstdCompressor, parts: list[bytes | memoryview]) -> bytes:
    """``parts`` joined and compressed, streamed through the compressor (a block of a
    few hundred MB of writes is never copied whole)."""
    stream = compressor.compressobj(size=sum(len(part) for part in parts))
    out = [stream.compress(part) for part in parts]
    out.append(stream.flush())
    return b"".join(out)

"""``export --to btlog`` in bounded memory: the FileLogger2 file written as the recording
is read, one ``/btlog/events`` message at a time.

``btlog.sinks.btcpp_filelog.export_filelog`` takes a whole ``Recording`` (every event a
Python object: gigabytes for a day-long run). Here the recording's messages are walked in
file order (``btlog.record.reader.iter_messages``) and each binary events message's
columns (``btlog.record.columns``) become FileLogger2 records without a Python object a
row, so memory holds one message whatever the run's length.

This is only right when the file's events come in seq order, as the recorder writes
them: that is checked as the walk goes (each message's seqs increasing and after the
previous message's). Anything else — chunks out of seq order, the tree after the first
events, a message that does not decode, metadata missing or of another schema version —
makes ``stream_filelog`` return None after removing what it wrote; the caller then
exports through ``open_recording`` as before (unbounded memory, the same bytes, the same
errors). A run whose tree changed, a uid FileLogger2 cannot hold, a bad start time or
an event out of FileLogger2's time range are refused with ``export_filelog``'s messages,
in its order, once the whole file has been walked.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import orjson

from btlog.events import BlackboardWrite, StatusChange
from btlog.record import columns
from btlog.record import format as fmt
from btlog.record.reader import MALFORMED_MESSAGE, iter_messages, read_metadata, tree_of
from btlog.record.walk import RecordingError
from btlog.sinks.btcpp_filelog import ExportResult, start_us_of, tree_xml
from btlog.sources import FILELOG_MAGIC
from btlog.sources.btcpp_filelog import VERSION
from btlog.sources.btcpp_records import MAX_UID, MAX_US, encode_record
from btlog.sources.builder import SourceError
from btlog.status import Status

#: The largest status byte FileLogger2 is given (``Status``'s values).
_MAX_STATUS = max(Status)


class _NotStreamable(Exception):
    """The file is not in the normal case: export it the old way."""


@dataclass
class StreamedExport:
    """A streamed export's result and the warnings of reading the recording."""

    result: ExportResult
    warnings: list[str] = field(default_factory=list)


@dataclass
class _State:
    """What the walk has seen so far."""

    where: str
    out: IO[bytes] | None = None
    tree_seen: bool = False
    last_seq: int = -1
    events: int = 0
    gap_free: bool = True
    transitions: int = 0
    writes: int = 0
    mutations: int = 0
    #: the first refusal found (uid too large, bad start time, event time out of range)
    refusals: dict[int, str] = field(default_factory=dict)


def stream_filelog(path: str | os.PathLike, output: str | os.PathLike) -> StreamedExport | None:
    """Write the recording ``path`` as the FileLogger2 file ``output`` while reading it;
    None (``output`` removed) when the file is not in seq order or not a sound recording,
    for the caller to fall back to ``export_filelog(open_recording(path), output)``."""
    state = _State(os.fspath(path))
    try:
        return _stream(state, read_metadata(state.where), output)
    except SourceError:
        _remove(output, state)
        raise
    except (_NotStreamable, RecordingError, *MALFORMED_MESSAGE, struct.error):
        _remove(output, state)
        return None


def _remove(output: str | os.PathLike, state: _State) -> None:
    if state.out is not None:
        state.out.close()
        state.out = None
        Path(output).unlink(missing_ok=True)


def _stream(state: _State, metadata: dict[str, Any], output: str | os.PathLike) -> StreamedExport:
    where = state.where
    try:
        start_us = start_us_of(metadata.get("started_at"), where)
    except SourceError as error:
        start_us = 0
        state.refusals[2] = str(error)
    stream = iter_messages(where)
    state.out = open(output, "wb")  # noqa: SIM115 - closed by _remove or below
    for topic, _log_time, data in stream:
        if topic == fmt.EVENTS_TOPIC:
            if not state.tree_seen:
                raise _NotStreamable
            _events(state, data)
        elif topic == fmt.TREE_TOPIC:
            if not state.tree_seen:
                _header(state, tree_of(where, orjson.loads(data)), start_us)
        elif topic == fmt.MUTATIONS_TOPIC:
            mutation = fmt.decode_mutation(orjson.loads(data))
            _order(state, [mutation.seq])
            state.mutations += 1
        elif topic == fmt.TICKS_TOPIC:
            fmt.decode_ticks(data)  # read as the reader reads them: a bad one falls back
        elif topic == fmt.ANSWERS_TOPIC:
            orjson.loads(data)
    if not state.tree_seen:
        raise _NotStreamable
    warnings = stream.warnings
    if not state.gap_free:
        warnings.append(f"{where}: the events' seqs are not 0, 1, 2, … without gaps")
    if stream.truncated:
        last = f"up to seq {state.last_seq}" if state.events else "(none)"
        warnings.insert(0, f"{where}: truncated recording; read {state.events} events {last}")
    if state.mutations:
        changed = "once" if state.mutations == 1 else f"{state.mutations} times"
        raise SourceError(
            f"{where}: the tree changed {changed} during the run ('Can you …?'); "
            "a FileLogger2 file holds one tree"
        )
    if state.refusals:
        raise SourceError(state.refusals[min(state.refusals)])
    state.out.close()
    state.out = None
    return StreamedExport(ExportResult(Path(output), state.transitions, state.writes), warnings)


def _header(state: _State, tree: Any, start_us: int) -> None:
    """The file's head: magic, version, the tree's XML and the start time."""
    too_big = [n.uid for n in tree if n.uid > MAX_UID]
    if too_big:
        state.refusals[1] = f"{state.where}: uid {too_big[0]} does not fit FileLogger2's 16 bits"
    xml = tree_xml(tree)
    assert state.out is not None
    state.out.write(FILELOG_MAGIC + bytes([VERSION]) + struct.pack("<i", len(xml)) + xml)
    state.out.write(struct.pack("<q", start_us))
    state.tree_seen = True


def _order(state: _State, seqs: list[int]) -> None:
    """Check the seqs of one message (sorted) follow the previous message's."""
    if not seqs:
        return
    if seqs[0] <= state.last_seq:
        raise _NotStreamable
    if state.gap_free and seqs != list(range(state.last_seq + 1, state.last_seq + 1 + len(seqs))):
        state.gap_free = False
    state.last_seq = seqs[-1]
    state.events += len(seqs)


def _events(state: _State, data: bytes) -> None:
    """One ``/btlog/events`` message: its transitions appended as FileLogger2 records."""
    if not columns.is_binary(data):
        _json_events(state, data)
        return
    message = columns.locate(data, 0, len(data))
    if message.magic != columns.EVENTS_MAGIC:
        raise _NotStreamable
    view = memoryview(data)
    spans = message.columns
    seqs = _column(view, spans[0], "q")
    writes = [BlackboardWrite(*row) for row in columns.writes_of(data, message)]
    if seqs != sorted(seqs):
        raise _NotStreamable
    every = sorted(seqs + [w.seq for w in writes]) if writes else seqs
    _order(state, every)
    state.writes += len(writes)
    count = message.count
    if not count:
        return
    t_us = [t // 1000 for t in _column(view, spans[1], "q")]
    uids = bytes(view[spans[3][0] : spans[3][1]])
    statuses = bytes(view[spans[5][0] : spans[5][1]])
    prevs = bytes(view[spans[4][0] : spans[4][1]])
    uid_values = _column(view, spans[3], "i")
    if (
        min(uid_values) < 0
        or max(uid_values) > MAX_UID
        or max(statuses) > _MAX_STATUS
        or max(prevs) > _MAX_STATUS
    ):
        raise _NotStreamable  # what the old path does with these is its own affair
    if min(t_us) < 0 or max(t_us) > MAX_US:
        bad = next(k for k, t in enumerate(t_us) if not 0 <= t <= MAX_US)
        _refuse_time(state, seqs[bad], t_us[bad])
        return
    state.transitions += count
    if state.refusals or state.mutations:
        return
    times = struct.pack(f"<{count}q", *t_us)
    out = bytearray(9 * count)
    for byte in range(6):
        out[byte::9] = times[byte::8]
    out[6::9] = uids[0::4]
    out[7::9] = uids[1::4]
    out[8::9] = statuses
    assert state.out is not None
    state.out.write(out)


def _refuse_time(state: _State, seq: int, t_us: int) -> None:
    state.refusals.setdefault(3, f"{state.where}: event {seq} at {t_us} µs is out of range")


def _json_events(state: _State, data: bytes) -> None:
    """An events message of schema version 1 or 2, row by row (small, old recordings)."""
    events = fmt.decode_events(data)
    _order(state, [e.seq for e in events])
    records = bytearray()
    for event in events:
        if isinstance(event, BlackboardWrite):
            state.writes += 1
        elif isinstance(event, StatusChange):
            t_us = event.t_ns // 1000
            if not 0 <= t_us <= MAX_US:
                _refuse_time(state, event.seq, t_us)
                return
            records += encode_record(t_us, event.uid, event.status)
            state.transitions += 1
    if not state.refusals and not state.mutations:
        assert state.out is not None
        state.out.write(records)


def _column(view: memoryview, span: tuple[int, int], code: str) -> list[int]:
    """The values of one little-endian column."""
    start, end = span
    return list(struct.unpack_from(f"<{(end - start) // struct.calcsize(code)}{code}", view, start))

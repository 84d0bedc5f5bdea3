"""The binary layout of ``/btlog/events`` and ``/btlog/ticks`` (schema version 3).

A reader loads millions of status changes a second only if it does not parse them. So
since schema version 3 the status changes and tick records travel as fixed-width
little-endian **columns**: a reader copies each column into an Arrow array as it is,
without looking at a row (``btlog.replay.scan``). A real run's recording is also about
half the size (4.5 against 8.3 bytes an event on ``bench_replay``'s run; see
``benchmarks/RESULTS.md``, where a synthetic run compresses worse). Blackboard writes
carry arbitrary values and stay JSON, inside the same message; the tree, mutations and
answers stay JSON messages.

A message is a 24-byte head, the columns one after the other, then the writes::

    offset  bytes  field
    0       4      magic: b"BTev" (events) or b"BTtk" (ticks)
    4       4      u32  n, the rows of the columns
    8       4      u32  w, the bytes of the writes (events; 0 for ticks)
    12      4      u32  flags: bit 0 set on the run's teardown ticks
    16      8      i64  tick: the last tick the message covers
    24      ...    the columns, each n values (below)
    ...     w      events: the write rows as one JSON array, as in schema version 2

Events columns: seq i64, t_ns i64, tick i64, uid i32, prev i8, status i8; ticks
columns: tick i64, start_ns i64, end_ns i64, root_status i8. Statuses are numbered as
BehaviorTree.CPP numbers them (0 IDLE, 1 RUNNING, 2 SUCCESS, 3 FAILURE, 4 SKIPPED).
The same text is in ``schemas/columns.md``, the schema record of both channels.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import lru_cache

import orjson

#: The channel message encoding (and schema encoding) of the binary topics.
ENCODING = "btlog.columns"
EVENTS_MAGIC = b"BTev"
TICKS_MAGIC = b"BTtk"
HEAD = struct.Struct("<4sIIIq")
TEARDOWN = 1

Layout = tuple[tuple[str, str], ...]
#: (column name, struct code) of each topic, in message order.
EVENT_COLUMNS: Layout = (
    ("seq", "q"),
    ("t_ns", "q"),
    ("tick", "q"),
    ("uid", "i"),
    ("prev_status", "b"),
    ("status", "b"),
)
TICK_COLUMNS: Layout = (("tick", "q"), ("start_ns", "q"), ("end_ns", "q"), ("root_status", "b"))
#: Bytes of one row across the columns.
EVENT_ROW_BYTES = struct.calcsize("<qqqibb")
TICK_ROW_BYTES = struct.calcsize("<qqqb")


@lru_cache(maxsize=512)
def _layout(codes: str, count: int) -> struct.Struct:
    """The struct packing ``count`` rows of the columns ``codes`` column after column."""
    return struct.Struct("<" + "".join(f"{count}{code}" for code in codes))


_EVENT_CODES = "".join(code for _name, code in EVENT_COLUMNS)
_TICK_CODES = "".join(code for _name, code in TICK_COLUMNS)


def pack_events(tick: int, fields: list, writes: list) -> bytes:
    """An events message: ``fields`` holds the status changes' six fields one row after
    the other (flat, as the recorder buffers them), ``writes`` the write rows."""
    count = len(fields) // 6
    body = b""
    if count:
        body = _layout(_EVENT_CODES, count).pack(
            *fields[0::6], *fields[1::6], *fields[2::6], *fields[3::6], *fields[4::6], *fields[5::6]
        )
    written = orjson.dumps(writes) if writes else b""
    return HEAD.pack(EVENTS_MAGIC, count, len(written), 0, tick) + body + written


def pack_ticks(rows: list, teardown: bool = False) -> bytes:
    """A ticks message of ``(tick, start_ns, end_ns, root_status)`` rows."""
    count = len(rows)
    columns = list(zip(*rows, strict=True)) if rows else [(), (), (), ()]
    body = _layout(_TICK_CODES, count).pack(*columns[0], *columns[1], *columns[2], *columns[3])
    last = rows[-1][0] if rows else 0
    return HEAD.pack(TICKS_MAGIC, count, 0, TEARDOWN if teardown else 0, last) + body


@dataclass(frozen=True)
class Message:
    """Where the parts of one binary message are: ``columns`` holds ``(start, end)`` of
    each column in the buffer, ``writes`` that of the write rows' JSON."""

    magic: bytes
    count: int
    tick: int
    teardown: bool
    columns: tuple[tuple[int, int], ...]
    writes: tuple[int, int]


def locate(buffer: bytes | memoryview, start: int, end: int) -> Message:
    """The parts of the binary message ``buffer[start:end]``; ValueError when its head
    or its length does not match a btlog message."""
    if end - start < HEAD.size:
        raise ValueError(f"a binary message of {end - start} bytes is shorter than its head")
    magic, count, written, flags, tick = HEAD.unpack_from(buffer, start)
    if magic == EVENTS_MAGIC:
        layout = EVENT_COLUMNS
    elif magic == TICKS_MAGIC:
        layout = TICK_COLUMNS
    else:
        raise ValueError(f"a binary message starts with {bytes(magic)!r}, not a btlog magic")
    columns, position = [], start + HEAD.size
    for _name, code in layout:
        width = struct.calcsize(code) * count
        columns.append((position, position + width))
        position += width
    if position + written != end:
        raise ValueError(
            f"a {magic.decode()} message of {count} rows and {written} bytes of writes "
            f"is {end - start} bytes long, expected {position + written - start}"
        )
    return Message(magic, count, tick, bool(flags & TEARDOWN), tuple(columns), (position, end))


def is_binary(data: bytes | memoryview, start: int = 0) -> bool:
    """True when the message at ``start`` has a binary head (JSON starts with ``{``)."""
    return bytes(data[start : start + 4]) in (EVENTS_MAGIC, TICKS_MAGIC)


def unpack(data: bytes, magic: bytes) -> tuple[Message, list[tuple]]:
    """The parts and the rows (tuples, column values in order) of a whole binary message
    whose magic must be ``magic``; ValueError otherwise."""
    message = locate(data, 0, len(data))
    if message.magic != magic:
        raise ValueError(f"expected a {magic.decode()} message, found {message.magic.decode()}")
    codes = _EVENT_CODES if magic == EVENTS_MAGIC else _TICK_CODES
    count = message.count
    values = _layout(codes, count).unpack_from(data, HEAD.size)
    columns = [values[k * count : (k + 1) * count] for k in range(len(codes))]
    return message, list(zip(*columns, strict=True))


def writes_of(data: bytes, message: Message) -> list:
    """The write rows of an events message."""
    start, end = message.writes
    return orjson.loads(data[start:end]) if end > start else []

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
import sys
from dataclasses import dataclass
from functools import lru_cache
from itertools import chain
from operator import add, mul

import orjson

from btlog.events import CHANGE

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


_I64 = struct.Struct("<q")
#: Packing many Python ints as native ``long`` converts each int several times faster than
#: ``q`` (which goes through ``_PyLong_AsByteArray`` once an int passes 2**30, as times
#: in nanoseconds do); it gives the same bytes where ``long`` is 8 bytes and little-endian.
_NATIVE_I64 = "l" if struct.calcsize("@l") == 8 and sys.byteorder == "little" else None


@lru_cache(maxsize=512)
def _i64_packer(count: int) -> struct.Struct:
    if _NATIVE_I64 is not None:
        return struct.Struct(f"@{count}{_NATIVE_I64}")
    return struct.Struct(f"<{count}q")


def _i64s(values: list[int]) -> bytes:
    """``values`` as little-endian i64s."""
    return _i64_packer(len(values)).pack(*values)


def _changes_columns(changes: list[bytes]) -> bytes:
    """The uid, prev and status columns of packed changes (``btlog.events.CHANGE``, 6
    bytes a row): the rows joined, then each byte of a row moved to its column by
    extended slices, which copies bytes without looking at a Python object."""
    count = len(changes)
    rows = b"".join(changes)
    if len(rows) != 6 * count:
        raise ValueError(f"{count} packed changes take {len(rows)} bytes, not {6 * count}")
    out = bytearray(6 * count)
    uids = 4 * count
    for byte in range(4):
        out[byte:uids:4] = rows[byte::6]
    out[uids : uids + count] = rows[4::6]
    out[uids + count :] = rows[5::6]
    return bytes(out)


def _merged_times(segments: list, times: list[int]) -> list[int]:
    """Every change's time, in order, when some segments have one time for all their
    changes and the others take theirs from ``times``."""
    merged: list[int] = []
    timed = 0
    for k in range(0, len(segments), 4):
        run, t_ns = segments[k + 2], segments[k + 3]
        if t_ns is None:
            merged += times[timed : timed + run]
            timed += run
        else:
            merged += [t_ns] * run
    return merged


def pack_events(
    tick: int, segments: list, changes: list[bytes], times: list[int], writes: list
) -> bytes:
    """An events message. The status changes come as the recorder buffers them:
    ``changes`` packed (uid, prev, status: ``btlog.events.CHANGE``), ``segments`` the
    runs of consecutive seqs in one tick, flat (``seq, tick, count, t_ns``), which give
    the seq, time and tick columns (a segment whose ``t_ns`` is None takes its changes'
    times, in order, from ``times``); ``writes`` holds the write rows."""
    count = len(changes)
    body = b""
    if count:
        # the segments' fields as columns; the loops over them run in C (map, chain)
        firsts, runs = segments[0::4], segments[2::4]
        shared_times = segments[3::4]
        seqs = list(chain.from_iterable(map(range, firsts, map(add, firsts, runs))))
        ticks = b"".join(map(mul, map(_I64.pack, segments[1::4]), runs))
        if not times:  # every segment has its time (an executor with a simulated clock)
            at = b"".join(map(mul, map(_I64.pack, shared_times), runs))
        elif shared_times.count(None) == len(shared_times):  # each change has its own
            at = _i64s(times)
        else:
            at = _i64s(_merged_times(segments, times))
        if len(seqs) != count or len(at) != 8 * count:
            raise ValueError(
                f"segments of {len(seqs)} status changes and {len(at) // 8} times for "
                f"{count} changes"
            )
        body = b"".join((_i64s(seqs), at, ticks, _changes_columns(changes)))
    written = orjson.dumps(writes) if writes else b""
    return HEAD.pack(EVENTS_MAGIC, count, len(written), 0, tick) + body + written


def add_timed_change(segments: list, seq: int, tick: int) -> None:
    """Count one change that comes with its own time (``seq`` in ``tick``) in the flat
    ``segments`` (``seq, tick, count, t_ns``): the last segment grows when it holds
    changes with their own times and this is its next seq in the same tick."""
    if (
        segments
        and segments[-1] is None
        and segments[-4] + segments[-2] == seq
        and segments[-3] == tick
    ):
        segments[-2] += 1
    else:
        segments += (seq, tick, 1, None)


def pack_event_rows(tick: int, rows: list, writes: list) -> bytes:
    """An events message of whole rows ``(seq, t_ns, tick, uid, prev, status)`` (any
    seqs), for writers that have them, such as a conversion."""
    segments: list = []
    changes, times = [], []
    for seq, t_ns, row_tick, uid, prev, status in rows:
        changes.append(CHANGE.pack(uid, prev, status))
        times.append(t_ns)
        add_timed_change(segments, seq, row_tick)
    return pack_events(tick, segments, changes, times, writes)


def pack_ticks(rows: list, teardown: bool = False) -> bytes:
    """A ticks message of ``(tick, start_ns, end_ns, root_status)`` rows."""
    count = len(rows)
    columns = list(zip(*rows, strict=True)) if rows else [(), (), (), ()]
    body = _layout(_TICK_CODES, count).pack(*columns[0], *columns[1], *columns[2], *columns[3])
    last = rows[-1][0] if rows else 0
    return HEAD.pack(TICKS_MAGIC, count, 0, TEARDOWN if teardown else 0, last) + body


#: The bytes of one row of each column, by message magic (``locate`` runs once a message).
_WIDTHS = {
    EVENTS_MAGIC: tuple(struct.calcsize(code) for _name, code in EVENT_COLUMNS),
    TICKS_MAGIC: tuple(struct.calcsize(code) for _name, code in TICK_COLUMNS),
}


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
    widths = _WIDTHS.get(magic)
    if widths is None:
        raise ValueError(f"a binary message starts with {bytes(magic)!r}, not a btlog magic")
    columns, position = [], start + HEAD.size
    for width in widths:
        stop = position + width * count
        columns.append((position, stop))
        position = stop
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

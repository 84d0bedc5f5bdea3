"""Cutting a recording's messages into row batches for bulk loading, without decoding.

Python touches each *message* here (one per tick or per ~1000 grouped events), never
each row; Arrow and C++ parsers (``btlog.replay.load``) touch the rows. The file's
records come from the one walker, ``btlog.record.walk`` (cut files, damaged chunks).

Schema version 3 (binary columns, ``btlog.record.columns``): each column of a message is
appended to the batch's bytes of that column, as it is; the write rows' JSON is kept
whole, per message. Versions 1 and 2 (JSON): each ``/btlog/events`` payload is cut into
its two row lists: status rows hold only integers and status names, so the status list
is the bytes between ``,"status":[`` and ``],"writes":[``; blackboard rows carry
arbitrary JSON values, so each message's write list is kept whole. Tick rows are cut
like status rows. Anything else the fast path does not recognise (another key order,
whitespace, the teardown's ticks) is kept for the general decoding.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import orjson
from mcap.opcode import Opcode
from mcap.records import Channel

from btlog.record import columns
from btlog.record import format as fmt
from btlog.record.reader import seq_of
from btlog.record.walk import HEAD, MAGIC, MESSAGE_HEAD, OPENED_CHUNK, Walk, mapped, records

_EVENTS_HEAD = b'{"tick":'
_STATUS_KEY = b',"status":['
_WRITES_KEY = b'],"writes":['
_TICKS_HEAD = b'{"ticks":['
_TAIL = b"]}"
_CHANNEL_ID = struct.Struct("<H")
_MESSAGE = int(Opcode.MESSAGE)
#: Bytes of rows gathered before they are handed to the loaders (while the walk goes on).
BATCH_BYTES = 48 << 20


@dataclass
class Columns:
    """Rows of binary messages, still bytes: each column's parts (slices of the
    messages' buffers, not copied) until ``data`` joins them, once per batch. Growing one
    bytearray a message instead copied each byte about eight times over (its
    reallocations), the most costly step of a load."""

    layout: tuple[tuple[str, str], ...]
    count: int = 0
    parts: list[list[memoryview]] = field(default_factory=list)
    #: bytes held (kept as columns are added: the scan checks it after every message)
    size: int = 0

    def __post_init__(self) -> None:
        self.parts = [[] for _ in self.layout]
        self._widths = [struct.calcsize(code) for _name, code in self.layout]
        self._row_bytes = sum(self._widths)

    def append(self, view: memoryview, start: int, count: int) -> None:
        """Append ``count`` rows whose columns lie one after the other from ``start``."""
        for column, width in zip(self.parts, self._widths, strict=True):
            stop = start + width * count
            column.append(view[start:stop])
            start = stop
        self.count += count
        self.size += self._row_bytes * count

    def data(self) -> list[bytes]:
        """Each column's bytes, its parts joined (they are let go)."""
        joined = [b"".join(column) for column in self.parts]
        self.parts = [[] for _ in self.layout]
        return joined


@dataclass
class RowBatch:
    """Rows of consecutive messages, still bytes: binary status and tick rows as columns;
    JSON status and tick rows as comma-joined row lists (``[…],[…],``); write rows as
    one row list per message."""

    status: bytearray = field(default_factory=bytearray)
    writes: list[bytes | memoryview] = field(default_factory=list)
    ticks: bytearray = field(default_factory=bytearray)
    status_columns: Columns = field(default_factory=lambda: Columns(columns.EVENT_COLUMNS))
    tick_columns: Columns = field(default_factory=lambda: Columns(columns.TICK_COLUMNS))

    def __bool__(self) -> bool:
        return bool(
            self.status
            or self.writes
            or self.ticks
            or self.status_columns.count
            or self.tick_columns.count
        )

    @property
    def size(self) -> int:
        """Bytes of rows held (what bounds a batch)."""
        return (
            len(self.status) + len(self.ticks) + self.status_columns.size + self.tick_columns.size
        )


@dataclass
class Collected:
    """What a scan found besides the bulk rows: metadata, tree, the rare messages, the
    messages the fast path did not recognise, and what the walk noticed."""

    walk: Walk
    metadata: dict[str, str] | None = None
    tree: dict | None = None
    mutations: list[dict] = field(default_factory=list)
    answers: list[dict] = field(default_factory=list)
    other_events: list[bytes] = field(default_factory=list)
    other_ticks: list[bytes] = field(default_factory=list)
    #: messages of channels the file never defines, skipped (opened chunks: ``records``;
    #: told last by ``warnings_of``, once for the parts of a file read in parts)
    unknown_channel: int = 0
    #: a channel record of the data section gave a channel another topic than the
    #: summary's (or one it does not have): what a part after it reads depends on it
    redefined: bool = False


def warnings_of(collected: Collected) -> list[str]:
    """What a scan noticed, as warnings: the walk's, then the messages skipped."""
    warnings = list(collected.walk.warnings)
    if collected.unknown_channel:
        warnings.append(
            f"{collected.walk.path}: {collected.unknown_channel} messages of channels the "
            "file never defines skipped"
        )
    return warnings


class McapScan:
    """Scans a recording, handing each ``RowBatch`` of about ``BATCH_BYTES`` to
    ``on_batch`` as soon as it is full."""

    def __init__(
        self,
        path: str,
        on_batch: Callable[[RowBatch], None],
        start: int = len(MAGIC),
        stop: int | None = None,
    ) -> None:
        self.path = path
        #: the part of the file to scan: its records from byte ``start`` to ``stop``
        self.start, self.stop = start, stop
        self.out = Collected(Walk(path))
        self.topics: dict[int, str] = {}
        self.events_channel: bytes | None = None
        self.ticks_channel: bytes | None = None
        self.batch = RowBatch()
        self.on_batch = on_batch

    def run(self) -> Collected:
        """Scan the whole file; the last batch is handed over too."""
        with mapped(self.path) as (data, size):
            walked = records(data, size, self.out.walk, True, self.start, self.stop)
            self._scan(walked)
        if self.batch:
            self.on_batch(self.batch)
            self.batch = RowBatch()
        self.out.mutations.sort(key=seq_of)  # chunks may come in any order
        self.out.answers.sort(key=seq_of)
        return self.out

    def _scan(self, walked: Iterator[tuple[int, Any, int, int]]) -> None:
        """The records of the file; an opened chunk's are cut by ``_chunk``."""
        for opcode, buffer, body, end in walked:
            if opcode == OPENED_CHUNK:
                self._chunk(buffer)
            else:
                self._record(opcode, buffer, body, end)

    def _chunk(self, buffer: bytes) -> None:
        """The records of an opened chunk, walked here without a generator step each (this
        loop runs once per message of the run)."""
        head, position, size = HEAD.unpack_from, 0, len(buffer)
        while position + HEAD.size <= size:
            opcode, length = head(buffer, position)
            body = position + HEAD.size
            end = position = body + length
            if end > size:
                return
            self._record(opcode, buffer, body, end)

    def _hand_over(self) -> None:
        """Hand the batch over and start a new one."""
        self.on_batch(self.batch)
        self.batch = RowBatch()

    def _record(self, opcode: int, buffer: Any, body: int, end: int) -> None:
        """One record, as the walk (or ``_chunk``) gives it."""
        if opcode == _MESSAGE:
            if type(buffer) is not bytes:  # a message outside chunks: rare, copied
                buffer, body, end = buffer[body:end], 0, end - body
            channel_id = buffer[body : body + 2]
            if channel_id == self.events_channel:
                self._events(buffer, body + MESSAGE_HEAD, end)
            elif channel_id == self.ticks_channel and self._binary_ticks(
                buffer, body + MESSAGE_HEAD, end
            ):
                pass
            else:
                self._message(buffer, body, end)
            if self.batch.size >= BATCH_BYTES:
                self._hand_over()
        elif opcode == Opcode.CHANNEL:
            found = self.out.walk.parse(opcode, buffer, body, end)
            if found is not None:
                self._channel(found)
        elif opcode == Opcode.METADATA and self.out.metadata is None:
            record = self.out.walk.parse(opcode, buffer, body, end)
            if record is not None and record.name == fmt.METADATA_NAME:
                self.out.metadata = record.metadata

    def _events(self, buffer: bytes, start: int, end: int) -> None:
        if buffer[start : start + 4] == columns.EVENTS_MAGIC:
            view, rows, count, written, _flags = _binary(buffer, start, end, _EVENT_ROW)
            self.batch.status_columns.append(view, rows, count)
            if written > 2:  # ``[[…],[…]]``: the rows without the brackets
                stop = end - written
                self.batch.writes.append(view[stop + 1 : end - 1])
            return
        find = buffer.find
        status = find(_STATUS_KEY, start + 8, start + 40) + 11
        writes = find(_WRITES_KEY, status, end) if status > 10 else -1
        if (
            writes < 0
            or not buffer.startswith(_EVENTS_HEAD, start)
            or not buffer.endswith(_TAIL, start, end)
        ):
            self.out.other_events.append(bytes(buffer[start:end]))
            return
        view = memoryview(buffer)
        if writes > status:
            self.batch.status += view[status:writes]
            self.batch.status += b","
        if end - 2 > writes + 12:
            self.batch.writes.append(view[writes + 12 : end - 2])

    def _binary_ticks(self, buffer: bytes, start: int, end: int) -> bool:
        """A binary ticks message, cut where it lies (False for another kind)."""
        if buffer[start : start + 4] != columns.TICKS_MAGIC:
            return False
        view, rows, count, _written, flags = _binary(buffer, start, end, _TICK_ROW)
        if flags & columns.TEARDOWN:
            self.out.other_ticks.append(bytes(buffer[start:end]))
        else:
            self.batch.tick_columns.append(view, rows, count)
        return True

    def _channel(self, channel: Channel) -> None:
        if not self.out.walk.priming and self.topics.get(channel.id) != channel.topic:
            self.out.redefined = True
        self.topics[channel.id] = channel.topic
        if channel.topic == fmt.EVENTS_TOPIC:
            self.events_channel = _CHANNEL_ID.pack(channel.id)
        elif channel.topic == fmt.TICKS_TOPIC:
            self.ticks_channel = _CHANNEL_ID.pack(channel.id)

    def _message(self, buffer: bytes, body: int, end: int) -> None:
        topic = self.topics.get(_CHANNEL_ID.unpack_from(buffer, body)[0])
        if topic is None:
            self.out.unknown_channel += 1
            return
        payload = bytes(buffer[body + MESSAGE_HEAD : end])
        out = self.out
        if topic == fmt.TICKS_TOPIC:
            if self._binary_ticks(payload, 0, len(payload)):
                pass
            elif payload.startswith(_TICKS_HEAD) and payload.endswith(_TAIL):
                if len(payload) > len(_TICKS_HEAD) + 2:
                    self.batch.ticks += memoryview(payload)[len(_TICKS_HEAD) : -2]
                    self.batch.ticks += b","
            else:
                out.other_ticks.append(payload)
        elif topic == fmt.MUTATIONS_TOPIC:
            out.mutations.append(orjson.loads(payload))
        elif topic == fmt.ANSWERS_TOPIC:
            out.answers.append(orjson.loads(payload))
        elif topic == fmt.TREE_TOPIC and out.tree is None:
            out.tree = orjson.loads(payload)


_EVENT_ROW, _TICK_ROW = columns.EVENT_ROW_BYTES, columns.TICK_ROW_BYTES


def _binary(
    buffer: bytes, start: int, end: int, row_bytes: int
) -> tuple[memoryview, int, int, int, int]:
    """Where the parts of the binary message ``buffer[start:end]`` lie: (a view of the
    buffer, its first row's offset, its rows, its bytes of writes, its flags). A message
    whose lengths do not match is ``columns.locate``'s ValueError, which says how."""
    if end - start >= columns.HEAD.size:
        _magic, count, written, flags, _tick = columns.HEAD.unpack_from(buffer, start)
        rows = start + columns.HEAD.size
        if rows + count * row_bytes + written == end:
            return memoryview(buffer), rows, count, written, flags
    columns.locate(buffer, start, end)  # raises, naming what does not match
    raise ValueError(f"a binary message of {end - start} bytes does not match its head")

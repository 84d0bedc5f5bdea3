"""The messages of a broken recording in the order ``recover`` saves them, in bounded memory.

A recording's messages are in seq order within their topic (ticks in tick order) when its
chunks are in file order, the normal case of a file cut short: ``in_file_order`` then
yields them as they come, one chunk in memory at a time, and raises ``OutOfOrder`` at the
first message that breaks the order. Otherwise ``in_seq_order`` gives every topic rank in
turn (the tree, events and mutations, ticks, answers, other topics) in seq order: a first
pass notes each chunk's lowest seq of the rank, then the chunks are opened in that order,
a chunk only once the messages before its lowest seq are out, so that what is held is the
chunks whose seqs overlap (one or two in a file whose chunks were moved or written twice).

Each message comes with its ``Facts`` (its rank, first seq or tick, the events and ticks
it counts, its seq range), read from the binary columns without decoding a row.
"""

from __future__ import annotations

import heapq
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import orjson
from mcap.opcode import Opcode
from mcap.records import Message

from btlog.record import columns
from btlog.record import format as fmt
from btlog.record.reader import seq_of
from btlog.record.walk import (
    MESSAGE_HEAD,
    DamagedChunk,
    Walk,
    chunk_records,
    inner_records,
    top_records,
)
from btlog.status import Status

#: The rank of each topic's messages in a recovered file (events and mutations share
#: the seq order); other topics come last.
RANKS = {
    fmt.TREE_TOPIC: 0,
    fmt.EVENTS_TOPIC: 1,
    fmt.MUTATIONS_TOPIC: 1,
    fmt.TICKS_TOPIC: 2,
    fmt.ANSWERS_TOPIC: 3,
}
OTHER_RANK = 4
_LAST_STATUS = max(Status)
_MESSAGE = struct.Struct("<HIQQ")
#: What a message that does not follow the btlog format raises when read.
MALFORMED = (orjson.JSONDecodeError, AttributeError, TypeError, LookupError, ValueError)


class OutOfOrder(Exception):
    """The file's messages are not in seq order within their topic (``in_file_order``)."""


@dataclass(frozen=True)
class Facts:
    """What ``recover`` needs of one message: its ``rank`` and ``key`` (its first seq,
    first tick for ticks; -1 when unreadable or without one), the ``events`` and
    ``ticks`` it counts, its seqs' ``first`` and ``last`` (None: no seq), and whether it
    follows the btlog format (``readable``)."""

    rank: int
    key: int
    events: int = 0
    ticks: int = 0
    first: int | None = None
    last: int | None = None
    readable: bool = True


def facts(topic: str, data: bytes) -> Facts:
    """The ``Facts`` of a ``topic`` message whose payload is ``data``."""
    rank = RANKS.get(topic, OTHER_RANK)
    try:
        if topic == fmt.EVENTS_TOPIC:
            seqs = _range(event_seqs(data))
            return Facts(rank, seqs[0], seqs[2], 0, *seqs[:2]) if seqs else Facts(rank, -1)
        if topic == fmt.TICKS_TOPIC:
            ticks, counted = _ticks(data)
            return Facts(rank, min(ticks, default=-1), 0, counted)
        if topic == fmt.MUTATIONS_TOPIC:
            seq = orjson.loads(data).get("seq")
            if isinstance(seq, int):
                return Facts(rank, seq, 1, 0, seq, seq)
            return Facts(rank, -1, 1)
        if topic == fmt.ANSWERS_TOPIC:
            return Facts(rank, seq_of(orjson.loads(data)))
    except MALFORMED:
        return Facts(rank, -1, readable=False)
    return Facts(rank, -1)


def event_seqs(data: bytes) -> Any:
    """The seqs of an ``/btlog/events`` message (status changes, then writes): a
    memoryview of the binary seq column (no row decoded) plus the writes', or a list."""
    if not columns.is_binary(data):
        events = fmt.parse_events(data)
        return [row[0] for rows in (events.status, events.writes) for row in rows]
    message = columns.locate(data, 0, len(data))
    if message.magic != columns.EVENTS_MAGIC:
        raise ValueError(f"an events message starts with {message.magic!r}")
    start, end = message.columns[0]
    seqs = memoryview(data)[start:end].cast("q")
    writes = columns.writes_of(data, message)
    return [*seqs, *(row[0] for row in writes)] if writes else seqs


def _range(seqs: Any) -> tuple[int, int, int] | None:
    """(first, last, count) of some seqs; None when there are none."""
    return (min(seqs), max(seqs), len(seqs)) if len(seqs) else None


def _ticks(data: bytes) -> tuple[Any, int]:
    """The ticks of an ``/btlog/ticks`` message and how many count (not teardown)."""
    if not columns.is_binary(data):
        records = fmt.decode_ticks(data)
        return [r.tick for r in records], sum(not r.teardown for r in records)
    message = columns.locate(data, 0, len(data))
    if message.magic != columns.TICKS_MAGIC:
        raise ValueError(f"a ticks message starts with {message.magic!r}")
    start, end = message.columns[0]
    return memoryview(data)[start:end].cast("q"), 0 if message.teardown else message.count


Item = tuple[Message, str, Facts]


class Source:
    """The messages of a mapped MCAP file whose channels ``topics`` names, read chunk
    by chunk (a damaged chunk skipped, as the walk that surveyed the file did)."""

    def __init__(self, data: Any, size: int, walk: Walk, topics: dict[int, str]) -> None:
        self.data, self.size, self.walk, self.topics = data, size, walk, topics

    def segments(self) -> Iterator[tuple[int, int, int]]:
        """``(opcode, body, end)`` of each chunk and top-level message, in file order."""
        quiet = Walk(self.walk.path)  # its notes were the survey's
        for opcode, body, end in top_records(self.data, self.size, quiet):
            if opcode in (Opcode.CHUNK, Opcode.MESSAGE):
                yield opcode, body, end

    def items(self, segment: tuple[int, int, int]) -> Iterator[Item]:
        """The messages of one segment with their topic and facts, in file order."""
        opcode, body, end = segment
        if opcode == Opcode.MESSAGE:
            found: Any = ((opcode, self.data, body, end),)
        else:
            try:
                found = inner_records(chunk_records(self.data, body, end))
            except DamagedChunk:
                return
        for kind, buffer, start, stop in found:
            if kind != Opcode.MESSAGE:
                continue
            message = self._message(buffer, start, stop)
            topic = self.topics.get(message.channel_id)
            if topic is not None:
                yield message, topic, facts(topic, message.data)

    def _message(self, buffer: Any, body: int, end: int) -> Message:
        if end - body < MESSAGE_HEAD:  # damaged: the walk's error names it
            parsed: Message = self.walk.parse(Opcode.MESSAGE, buffer, body, end)
            return parsed
        channel, sequence, log_time, publish_time = _MESSAGE.unpack_from(buffer, body)
        return Message(
            channel_id=channel,
            sequence=sequence,
            log_time=log_time,
            publish_time=publish_time,
            data=bytes(buffer[body + MESSAGE_HEAD : end]),
        )

    def in_file_order(self) -> Iterator[Item]:
        """Every message in file order; ``OutOfOrder`` at the first whose key is below
        the one before it of its rank."""
        last: dict[int, int] = {}
        for segment in self.segments():
            for item in self.items(segment):
                rank, key = item[2].rank, item[2].key
                if key < last.get(rank, -1):
                    raise OutOfOrder(f"key {key} after {last[rank]} (rank {rank})")
                last[rank] = key
                yield item

    def in_seq_order(self) -> Iterator[Item]:
        """Every message, rank after rank, in key order within a rank (ties in file
        order), holding only the chunks whose keys overlap (see the module)."""
        segments = list(self.segments())
        lowest: list[dict[int, int]] = []
        for segment in segments:
            found: dict[int, int] = {}
            for _message, _topic, known in self.items(segment):
                found[known.rank] = min(found.get(known.rank, known.key), known.key)
            lowest.append(found)
        for rank in sorted({rank for found in lowest for rank in found}):
            order = sorted((found[rank], i) for i, found in enumerate(lowest) if rank in found)
            yield from self._merged(rank, order, segments)

    def _merged(
        self, rank: int, order: list[tuple[int, int]], segments: list[tuple[int, int, int]]
    ) -> Iterator[Item]:
        heap: list[tuple[int, int, int, Item]] = []
        opened = 0
        while opened < len(order) or heap:
            while opened < len(order) and (not heap or order[opened][0] <= heap[0][0]):
                index = order[opened][1]
                opened += 1
                for position, item in enumerate(self.items(segments[index])):
                    if item[2].rank == rank:
                        heapq.heappush(heap, (item[2].key, index, position, item))
            yield heapq.heappop(heap)[3]


class Sifter:
    """Drops a message met before (same channel, time and bytes: a chunk written twice)
    and refuses two different events with one seq, remembering only the messages whose
    keys or seqs can still meet a later one (the messages come in key order per rank)."""

    def __init__(self) -> None:
        self._same_key: dict[int, tuple[int, set[tuple[int, int, bytes]]]] = {}
        self._open: list[tuple[int, int, str, bytes]] = []

    def fresh(self, message: Message, known: Facts) -> bool:
        """False when ``message`` came before (drop it, it is a copy)."""
        key, seen = self._same_key.get(known.rank, (None, set()))
        if key != known.key:
            seen = set()
            self._same_key[known.rank] = (known.key, seen)
        identity = (message.channel_id, message.log_time, message.data)
        if identity in seen:
            return False
        seen.add(identity)
        return True

    def twice(self, topic: str, data: bytes, known: Facts) -> int | None:
        """A seq that ``data`` shares with itself or an earlier message (None: none)."""
        if known.first is None or known.last is None:
            return None
        self._open = [kept for kept in self._open if kept[1] >= known.first]
        overlapping = [kept for kept in self._open if kept[0] <= known.last]
        if overlapping or known.events > known.last - known.first + 1:
            mine = sorted(_seqs(topic, data))
            repeated = next((a for a, b in pairwise(mine) if a == b), None)
            if repeated is not None:
                return repeated
            for _first, _last, other, payload in overlapping:
                common = set(mine).intersection(_seqs(other, payload))
                if common:
                    return min(common)
        self._open.append((known.first, known.last, topic, data))
        return None


def _seqs(topic: str, data: bytes) -> list[int]:
    if topic == fmt.EVENTS_TOPIC:
        return list(event_seqs(data))
    return [orjson.loads(data)["seq"]]


def check_message(topic: str, data: bytes) -> None:
    """Raise (``MALFORMED``) unless a ``topic`` message follows the btlog format; the
    binary columns are checked by their lengths and status values, no row decoded."""
    if topic in (fmt.EVENTS_TOPIC, fmt.TICKS_TOPIC) and columns.is_binary(data):
        message = columns.locate(data, 0, len(data))
        events = topic == fmt.EVENTS_TOPIC
        if message.magic != (columns.EVENTS_MAGIC if events else columns.TICKS_MAGIC):
            raise ValueError(f"a {topic} message starts with {message.magic!r}")
        for start, end in message.columns[4:] if events else message.columns[3:]:
            values = memoryview(data)[start:end].cast("b")
            if len(values) and (min(values) < 0 or max(values) > _LAST_STATUS):
                raise ValueError(f"a status {min(values)}..{max(values)} out of 0..{_LAST_STATUS}")
        if events:
            columns.writes_of(data, message)
    elif topic == fmt.EVENTS_TOPIC:
        fmt.parse_events(data)
    elif topic == fmt.TICKS_TOPIC:
        fmt.decode_ticks(data)
    elif topic == fmt.MUTATIONS_TOPIC:
        fmt.decode_mutation(orjson.loads(data))
    elif topic == fmt.ANSWERS_TOPIC:
        orjson.loads(data)

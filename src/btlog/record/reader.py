"""The reader: a recording back as events, ticks, the tree and the run's metadata.

An MCAP file is a sequence of records (``opcode``, ``length``, body); the messages live
inside compressed chunks, and a finished file ends with a summary (an index of the
chunks) and a footer. Two ways to read it follow from that:

- a finished file is read through its index (mcap's ``SeekingReader``);
- a file cut short (the recorder was killed) has no summary, and mcap's seeking reader
  then finds nothing. It is read front to back instead, over only its *complete prefix*:
  a first pass walks the record headers (9 bytes each, no decompression) to the last
  record whose body is entirely in the file, and mcap's ``StreamReader`` reads up to
  there. A chunk is whole or not read at all, so what comes back is every message of
  every chunk that reached the disk — with the recorder's flushing, a gap-free prefix of
  the run's events — and a warning says where it stopped.

Bad input (a missing, empty or non-MCAP file, a file that is not a btlog recording, a
schema version this btlog does not read) raises ``RecordingError`` with one line naming
the file and the problem.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from operator import attrgetter
from pathlib import Path
from typing import IO, Any

import orjson
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Message, Metadata
from mcap.stream_reader import StreamReader

import btlog
from btlog.events import BlackboardWrite, StatusChange, TickRecord, TreeMutation
from btlog.record import format as fmt
from btlog.tree.model import Tree

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
_FOOTER_SIZE = 9 + 8 + 8 + 4
#: What reading a damaged (not merely cut) record may raise: mcap's own errors, but also
#: whatever its parsing and the decompressors hit on bad bytes (struct.error, ZstdError,
#: OverflowError, …). Only mcap's reading is guarded by it, never btlog's decoding.
DAMAGE_ERRORS = (Exception,)


class RecordingError(ValueError):
    """A file that cannot be read as a btlog recording; the message names file and problem."""


# -- the records of a file ------------------------------------------------------------------
class _Prefix:
    """A read-only view of the first ``limit`` bytes of a binary file."""

    def __init__(self, file: IO[bytes], limit: int) -> None:
        self._file = file
        self._left = limit

    def read(self, size: int = -1) -> bytes:
        size = self._left if size is None or size < 0 else min(size, self._left)
        data = self._file.read(size)
        self._left -= len(data)
        return data


def _complete_prefix(file: IO[bytes], size: int) -> tuple[int, bool]:
    """(bytes of whole records from the start, whether the file ends with footer + magic)."""
    position = len(MAGIC)
    while True:
        file.seek(position)
        head = file.read(_RECORD_HEAD.size)
        if len(head) < _RECORD_HEAD.size:
            return position, False
        opcode, length = _RECORD_HEAD.unpack(head)
        end = position + _RECORD_HEAD.size + length
        if end > size:
            return position, False
        if opcode == Opcode.FOOTER:
            file.seek(end)
            if file.read(len(MAGIC)) == MAGIC:
                return end + len(MAGIC), True
            return end, False
        position = end


@dataclass
class Scan:
    """What reading a file found besides its records: whether it was cut, and warnings."""

    path: str
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)


def open_mcap(path: str | os.PathLike) -> tuple[IO[bytes], int]:
    """Open ``path`` and check it starts as an MCAP file; RecordingError otherwise.
    Returns the open file (the caller closes it) and its size."""
    name = os.fspath(path)
    try:
        file = open(name, "rb")  # noqa: SIM115
    except FileNotFoundError:
        raise RecordingError(f"{name}: no such file") from None
    except IsADirectoryError:
        raise RecordingError(f"{name}: is a directory, not a recording") from None
    except OSError as error:
        raise RecordingError(f"{name}: cannot open: {error.strerror}") from None
    size = os.fstat(file.fileno()).st_size
    magic = file.read(len(MAGIC))
    if size == 0 or magic != MAGIC:
        file.close()
        problem = "empty file" if size == 0 else "not an MCAP file (bad magic)"
        raise RecordingError(f"{name}: {problem}")
    return file, size


def _indexed_reader(file: IO[bytes], size: int) -> SeekingReader | None:
    """A seeking reader when the file ends with a valid footer and summary, else None."""
    if size < len(MAGIC) * 2 + _FOOTER_SIZE:
        return None
    file.seek(size - len(MAGIC) - _FOOTER_SIZE)
    tail = file.read(_FOOTER_SIZE + len(MAGIC))
    if tail[0] != Opcode.FOOTER or tail[-len(MAGIC) :] != MAGIC:
        return None
    try:
        file.seek(0)
        reader = SeekingReader(file, validate_crcs=True)
        summary = reader.get_summary()
    except DAMAGE_ERRORS:
        return None
    if summary is None or not summary.chunk_indexes:
        return None
    return reader


def _indexed_records(reader: SeekingReader) -> Iterator[Any]:
    yield from reader.iter_metadata()
    yield from reader.iter_attachments()
    for _schema, channel, message in reader.iter_messages(log_time_order=False):
        yield channel.topic, message


def raw_records(file: IO[bytes], size: int, scan: Scan) -> Iterator[Any]:
    """Every mcap record of the file's complete prefix, in file order (chunks opened).

    Stops cleanly at the cut of a truncated file and at a damaged record, noting it in
    ``scan``. Used by the streaming read and by ``recover``.
    """
    limit, finished = _complete_prefix(file, size)
    scan.truncated = not finished
    file.seek(0)
    try:
        yield from StreamReader(_Prefix(file, limit), validate_crcs=True).records
    except EndOfFile:
        if finished:
            scan.truncated = True
            scan.warnings.append(f"{scan.path}: unexpected end of the file")
    except DAMAGE_ERRORS as error:
        scan.truncated = True
        scan.warnings.append(
            f"{scan.path}: damaged record, reading stopped there: {type(error).__name__}: {error}"
        )


def _streamed_records(file: IO[bytes], size: int, scan: Scan) -> Iterator[Any]:
    """Metadata, attachments and messages as ``(topic, Message)``, front to back."""
    topics: dict[int, str] = {}
    for record in raw_records(file, size, scan):
        if isinstance(record, Message):
            topic = topics.get(record.channel_id)
            if topic is not None:
                yield topic, record
        elif isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Metadata | Attachment):
            yield record


def _records(path: str | os.PathLike, scan: Scan) -> Iterator[Any]:
    """Metadata, attachments and ``(topic, Message)`` of ``path``, by index if it has one."""
    file, size = open_mcap(path)
    with file:
        reader = _indexed_reader(file, size)
        if reader is None:
            yield from _streamed_records(file, size, scan)
            return
        try:
            yield from _indexed_records(reader)
        except DAMAGE_ERRORS as error:
            scan.truncated = True
            scan.warnings.append(
                f"{scan.path}: damaged record, reading stopped there: "
                f"{type(error).__name__}: {error}"
            )


# -- public reading API ------------------------------------------------------------------
class MessageStream:
    """The messages of a recording as ``(topic, log_time, data)``, in file order.

    Iterate once; afterwards ``truncated`` tells whether the file was cut short and
    ``warnings`` says what was noticed. Metadata and attachments are skipped.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = os.fspath(path)
        file, _size = open_mcap(self.path)  # bad input fails here, not at iteration
        file.close()
        self._scan = Scan(self.path)
        self._records = _records(self.path, self._scan)

    def __iter__(self) -> Iterator[tuple[str, int, bytes]]:
        for record in self._records:
            if type(record) is tuple:
                topic, message = record
                yield topic, message.log_time, message.data

    @property
    def truncated(self) -> bool:
        """True when the file was cut short (known once iterated)."""
        return self._scan.truncated

    @property
    def warnings(self) -> list[str]:
        """What was noticed while reading (known once iterated)."""
        return self._scan.warnings


def iter_messages(path: str | os.PathLike) -> MessageStream:
    """The messages of ``path`` as ``(topic, log_time, data)``, for bulk consumers.

    A truncated file yields every complete message and stops; the returned
    ``MessageStream`` then has ``truncated`` set. A missing, empty or non-MCAP file
    raises ``RecordingError`` at once.
    """
    return MessageStream(path)


def decode_metadata(path: str, record: dict[str, str]) -> dict[str, Any]:
    """The ``btlog.run`` record with its JSON values decoded; checks the schema version."""
    metadata: dict[str, Any] = dict(record)
    for key in fmt.JSON_METADATA:
        if key in metadata:
            try:
                metadata[key] = orjson.loads(metadata[key])
            except orjson.JSONDecodeError:
                raise RecordingError(f"{path}: metadata {key!r} is not JSON") from None
    version = metadata.get("schema_version")
    if version not in btlog.READABLE_SCHEMA_VERSIONS:
        found = "no schema version" if version is None else f"schema version {version!r}"
        readable = ", ".join(repr(v) for v in btlog.READABLE_SCHEMA_VERSIONS)
        raise RecordingError(f"{path}: {found}; this btlog reads schema versions {readable}")
    return metadata


def read_metadata(path: str | os.PathLike) -> dict[str, Any]:
    """The run's ``btlog.run`` metadata (JSON values decoded), without reading events."""
    name = os.fspath(path)
    file, size = open_mcap(name)
    with file:
        record = _find_metadata(file, size)
    if record is None:
        raise RecordingError(f"{name}: not a btlog recording (no {fmt.METADATA_NAME} metadata)")
    return decode_metadata(name, record.metadata)


def _find_metadata(file: IO[bytes], size: int) -> Metadata | None:
    """The ``btlog.run`` record, through the index when there is one."""
    reader = _indexed_reader(file, size)
    records = reader.iter_metadata() if reader is not None else _metadata_prefix(file, size)
    try:
        return next((r for r in records if r.name == fmt.METADATA_NAME), None)
    except DAMAGE_ERRORS:
        return None


def _metadata_prefix(file: IO[bytes], size: int) -> Iterator[Metadata]:
    """The metadata records of the complete prefix, chunks left compressed."""
    limit, _finished = _complete_prefix(file, size)
    file.seek(0)
    try:
        for record in StreamReader(_Prefix(file, limit), emit_chunks=True).records:
            if isinstance(record, Metadata):
                yield record
    except EndOfFile:  # the end of the complete prefix
        return


@dataclass
class Recording:
    """A run read back from its file.

    ``events`` holds StatusChange, BlackboardWrite and TreeMutation records in ``seq``
    order; ``tree`` is the tree at the start (mutations are among the events).
    """

    path: Path
    metadata: dict[str, Any]
    tree: Tree
    events: list[StatusChange | BlackboardWrite | TreeMutation]
    ticks: list[TickRecord]
    answers: list[dict]
    attachments: dict[str, bytes]
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)

    @property
    def last_seq(self) -> int | None:
        """The seq of the last event (None for a run without events)."""
        return self.events[-1].seq if self.events else None

    @property
    def transitions(self) -> list[StatusChange]:
        """Only the status changes."""
        return [e for e in self.events if type(e) is StatusChange]


@dataclass
class _Contents:
    """What ``open_recording`` collects while reading the records."""

    metadata: dict[str, str] | None = None
    tree: dict | None = None
    events: list = field(default_factory=list)
    ticks: list = field(default_factory=list)
    answers: list = field(default_factory=list)
    attachments: dict[str, bytes] = field(default_factory=dict)

    def add(self, record: Any) -> None:
        if type(record) is tuple:
            self._message(*record)
        elif isinstance(record, Metadata):
            if record.name == fmt.METADATA_NAME and self.metadata is None:
                self.metadata = record.metadata
        elif isinstance(record, Attachment):
            self.attachments[record.name] = record.data

    def _message(self, topic: str, message: Message) -> None:
        if topic == fmt.EVENTS_TOPIC:
            self.events.extend(fmt.decode_events(orjson.loads(message.data)))
        elif topic == fmt.TICKS_TOPIC:
            self.ticks.extend(fmt.decode_ticks(orjson.loads(message.data)))
        elif topic == fmt.MUTATIONS_TOPIC:
            self.events.append(fmt.decode_mutation(orjson.loads(message.data)))
        elif topic == fmt.ANSWERS_TOPIC:
            self.answers.append(orjson.loads(message.data))
        elif topic == fmt.TREE_TOPIC and self.tree is None:
            self.tree = orjson.loads(message.data)


def open_recording(path: str | os.PathLike) -> Recording:
    """Read the recording at ``path``; a truncated file is read up to its cut, with a
    warning. Raises ``RecordingError`` for anything that is not a readable recording."""
    name = os.fspath(path)
    scan = Scan(name)
    contents = _Contents()
    try:
        for record in _records(name, scan):
            contents.add(record)
    except (
        orjson.JSONDecodeError,
        KeyError,
        TypeError,
        ValueError,
        AttributeError,
        IndexError,
    ) as error:
        if isinstance(error, RecordingError):
            raise
        raise RecordingError(
            f"{name}: a message does not follow the btlog format: {type(error).__name__}: {error}"
        ) from None
    return _assemble(name, contents, scan)


def _assemble(name: str, contents: _Contents, scan: Scan) -> Recording:
    if contents.tree is None:
        cut = " (the file is cut before it)" if scan.truncated else ""
        raise RecordingError(f"{name}: not a btlog recording: no {fmt.TREE_TOPIC} message{cut}")
    if contents.metadata is None:
        raise RecordingError(f"{name}: not a btlog recording: no {fmt.METADATA_NAME} metadata")
    metadata = decode_metadata(name, contents.metadata)
    events = contents.events
    warnings = scan.warnings
    if not _gap_free(events):  # the recorder writes in seq order; anything else is sorted
        events.sort(key=attrgetter("seq"))
        if not _gap_free(events):
            warnings.append(f"{name}: the events' seqs are not 0, 1, 2, … without gaps")
    if scan.truncated:
        last = f"up to seq {events[-1].seq}" if events else "(none)"
        warnings.insert(0, f"{name}: truncated recording; read {len(events)} events {last}")
    return Recording(
        Path(name),
        metadata,
        _tree(name, contents.tree),
        events,
        contents.ticks,
        contents.answers,
        contents.attachments,
        scan.truncated,
        warnings,
    )


def _tree(name: str, message: dict) -> Tree:
    try:
        return Tree.from_description(message)
    except (KeyError, TypeError, StopIteration) as error:
        raise RecordingError(
            f"{name}: the {fmt.TREE_TOPIC} message is not a tree: {type(error).__name__}: {error}"
        ) from None


def _gap_free(events: list) -> bool:
    """True when the seqs are exactly 0, 1, 2, … in list order."""
    return [event.seq for event in events] == list(range(len(events)))

"""The one walk over an MCAP file's records, shared by every reader of recordings.

An MCAP file is the magic bytes, then records (``opcode: u8``, ``length: u64``, body);
messages live inside chunks (compressed, with a CRC of their uncompressed records), and
a finished file ends with a summary and a footer. ``records`` walks the file front to
back and yields every record, chunks opened, as ``(opcode, buffer, body, end)``: the
record's body is ``buffer[body:end]``. It is the only place btlog frames records:

- a file **cut short** (a killed recorder) stops at its last whole record: ``truncated``;
- a **damaged chunk** (bad layout, decompression error, CRC mismatch) is skipped with a
  warning naming the file and the chunk's byte offset, and the walk goes on;
- **damaged framing** (an unknown opcode, a length pointing past the end of a file that
  has more records after it) is resynchronised: the walk searches forward for the next
  chunk whose layout and CRC check out, and says which bytes it skipped.

Reading does not depend on the order of the chunks in the file: a finished file's
summary (its CRC checked) gives the schemas and channels first, so a message is never
lost for coming before its channel's record; without a sound summary (a cut file), a
message whose channel has not been seen yet is held until its channel record comes. A
summary whose CRC fails is not used.
Readers order what they read by seq, not by file position.

``Walk`` collects what was noticed (``truncated``, ``warnings``, ``dropped``).
``Walk.parse`` turns a record into the ``mcap`` package's record object when a reader
wants one (a damaged record is a ``RecordingError`` naming file and byte offset); the
bulk ingestion reads message bodies straight from the buffer instead.
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from io import BytesIO
from typing import IO, Any

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, DataEnd, Header, Message, Metadata, Schema

MAGIC = b"\x89MCAP0\r\n"
HEAD = struct.Struct("<BQ")
#: Bytes of a message record body before its payload: channel id, sequence, log and
#: publish times.
MESSAGE_HEAD = 2 + 4 + 8 + 8
_CHUNK_HEAD = struct.Struct("<QQQI")  # start, end, uncompressed size, uncompressed CRC
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_U16 = struct.Struct("<H")
#: A footer record: opcode, length (20), summary start, summary offset start, summary CRC.
_FOOTER = struct.Struct("<BQQQI")
_KNOWN = frozenset(int(opcode) for opcode in Opcode)
#: The pseudo-opcode of a chunk's uncompressed records given as one item (``records``).
OPENED_CHUNK = -1
#: The records ``parse`` builds (the others, indexes and summary records, are skipped).
_PARSED: dict[int, Any] = {
    Opcode.HEADER: Header,
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.MESSAGE: Message,
    Opcode.METADATA: Metadata,
    Opcode.ATTACHMENT: Attachment,
    Opcode.DATA_END: DataEnd,
}


class RecordingError(ValueError):
    """A file that cannot be read as a btlog recording; the message names file and problem."""


class DamagedChunk(ValueError):
    """A chunk whose layout, compression or CRC does not check out."""


@dataclass(frozen=True)
class Dropped:
    """Bytes of the file a walk could not read: ``length`` bytes from ``offset``."""

    offset: int
    length: int
    reason: str


@dataclass
class Walk:
    """What walking one file noticed: whether it was cut short or damaged, and warnings."""

    path: str
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)
    dropped: list[Dropped] = field(default_factory=list)
    #: the byte offset of the chunk whose records are being walked (None: top level)
    chunk: int | None = None
    #: True while the records walked are the summary's (after the data end record)
    summary: bool = False
    #: True while the records walked are a sound summary's schemas and channels, given
    #: first (``records``)
    priming: bool = False

    def drop(self, offset: int, length: int, reason: str) -> None:
        """Note unreadable bytes, with the one warning every reader prints for them."""
        self.dropped.append(Dropped(offset, length, reason))
        self.warnings.append(
            f"{self.path}: damaged data at byte {offset} ({length} bytes) skipped: {reason}"
        )

    def parse(self, opcode: int, buffer: Any, body: int, end: int) -> Any:
        """``parse`` of a record this walk yielded. A record that does not parse (damaged
        bytes the chunk CRCs do not cover) is a ``RecordingError`` naming the file and
        the record's byte offset; but an attachment whose CRC fails and a damaged record
        of the summary (copies of what the data section holds) are skipped with a
        warning (None)."""
        where = f"at byte {body - HEAD.size}"
        if self.chunk is not None:
            where += f" of the chunk at byte {self.chunk}"
        try:
            record = parse(opcode, buffer, body, end)
            if opcode == Opcode.ATTACHMENT and not _attachment_sound(buffer, body, end):
                raise ValueError("CRC mismatch")
            return record
        except (McapError, struct.error, ValueError, UnicodeDecodeError, OverflowError) as error:
            kind = Opcode(opcode).name.lower().replace("_", " ")
            problem = "its fields overrun it" if isinstance(error, McapError) else str(error)
            if self.summary or opcode == Opcode.ATTACHMENT:
                self.drop(body - HEAD.size, end - body + HEAD.size, f"{kind} record: {problem}")
                return None
            raise RecordingError(
                f"{self.path}: damaged {kind} record {where}: {problem or type(error).__name__}"
            ) from None


def _attachment_sound(buffer: Any, body: int, end: int) -> bool:
    """False when an attachment record's CRC (of its fields before it) does not match."""
    (crc,) = _U32.unpack_from(buffer, end - 4)
    return not crc or zlib.crc32(buffer[body : end - 4]) == crc


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


@contextmanager
def mapped(path: str | os.PathLike) -> Iterator[tuple[mmap.mmap, int]]:
    """The file at ``path`` mapped read-only, and its size (checked by ``open_mcap``)."""
    file, size = open_mcap(path)
    with file:
        data = mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            yield data, size
        finally:
            data.close()


def top_records(
    data: mmap.mmap | bytes, size: int, walk: Walk, start: int = len(MAGIC), stop: int | None = None
) -> Iterator[tuple[int, int, int]]:
    """``(opcode, body, end)`` of every top-level record up to the footer, chunks left
    closed; damaged framing is resynchronised on the next sound chunk (see the module).
    ``start`` and ``stop``: only the records from byte ``start`` (where a record starts)
    to byte ``stop`` (a part of the file, ``btlog.replay.parts``)."""
    position = start
    while position + HEAD.size <= size:
        if stop is not None and position >= stop:
            return
        opcode, length = HEAD.unpack_from(data, position)
        body = position + HEAD.size
        end = body + length
        if opcode in _KNOWN and end <= size and _framed(opcode, data, body, end):
            if opcode == Opcode.FOOTER:
                walk.truncated = data[end : end + len(MAGIC)] != MAGIC
                return
            yield opcode, body, end
            position = end
            continue
        resumed = _next_chunk(data, position + 1, size)
        if resumed is None:
            if opcode not in _KNOWN:
                walk.drop(position, size - position, f"unknown record opcode {opcode:#x}")
            break
        reason = f"unknown record opcode {opcode:#x}" if opcode not in _KNOWN else "bad length"
        walk.drop(position, resumed - position, f"record framing damaged ({reason})")
        position = resumed
    walk.truncated = True


def records(
    data: mmap.mmap | bytes,
    size: int,
    walk: Walk,
    opened: bool = False,
    start: int = len(MAGIC),
    stop: int | None = None,
) -> Iterator[tuple[int, Any, int, int]]:
    """``(opcode, buffer, body, end)`` of every record of the file, the records inside
    each chunk instead of the chunk; a damaged chunk is skipped with a warning.

    The summary's schemas and channels come first (after the header) when the file has
    a sound summary (and the summary section is then not walked again); a message of a
    channel not yet seen is held back and comes right after its channel's record.

    ``opened``: a chunk of a file with a sound summary comes as one item,
    ``(OPENED_CHUNK, records, 0, len(records))``, its uncompressed records for the
    caller to walk (``inner_records``, or a loop of its own that cuts millions of
    messages without a generator step each); every channel is then known already, so
    nothing is held back: a message of a channel the file never defines is the
    caller's to skip. Without a sound summary, chunks come record by record as usual.

    ``start`` and ``stop``: the records of that part of the file only (``top_records``);
    the summary's schemas and channels still come first."""
    state = _summary(data, size)
    summary = state if isinstance(state, tuple) else None
    known: set[int] = set()
    held: dict[int, list[bytes]] = {}
    primed = summary is None
    in_summary = False
    for item in _file_records(data, size, walk, opened, start, stop):
        if item[0] == OPENED_CHUNK and summary is None:
            walked: Iterable[tuple[int, Any, int, int]] = inner_records(item[1])
        else:
            walked = (item,)
        for opcode, buffer, body, end in walked:
            if in_summary:  # given already, first (or damaged: not used)
                continue
            if not primed:  # the summary's schemas and channels, after the header
                primed = True
                if opcode == Opcode.HEADER:
                    yield opcode, buffer, body, end
                walk.priming = True
                for found in _summary_records(data, summary or (0, 0)):
                    if found[0] == Opcode.CHANNEL:
                        known.add(_U16.unpack_from(data, found[1])[0])
                    yield found[0], data, found[1], found[2]
                walk.priming = False
                if opcode == Opcode.HEADER:
                    continue
            in_summary = opcode == Opcode.DATA_END and state is not False
            if in_summary and state is True:
                walk.warnings.append(
                    f"{walk.path}: the summary after byte {body - HEAD.size} fails its CRC; "
                    "read without it"
                )
            walk.summary = walk.summary or opcode == Opcode.DATA_END
            if end - body >= 2 and opcode in (Opcode.MESSAGE, Opcode.CHANNEL):
                (channel,) = _U16.unpack_from(buffer, body)
                if opcode == Opcode.MESSAGE and channel not in known:
                    held.setdefault(channel, []).append(bytes(buffer[body:end]))
                    continue
                yield opcode, buffer, body, end
                if opcode == Opcode.CHANNEL:
                    known.add(channel)
                    for message in held.pop(channel, ()):
                        yield Opcode.MESSAGE, message, 0, len(message)
                continue
            yield opcode, buffer, body, end
    walk.chunk = None
    if held:
        count = sum(len(messages) for messages in held.values())
        walk.warnings.append(
            f"{walk.path}: {count} messages of channels the file never defines skipped"
        )


def _file_records(
    data: mmap.mmap | bytes,
    size: int,
    walk: Walk,
    opened: bool = False,
    start: int = len(MAGIC),
    stop: int | None = None,
) -> Iterator[tuple[int, Any, int, int]]:
    """The records of the file (from ``start`` to ``stop``) in file order, chunks opened
    (``walk.chunk`` tells which chunk the records come from); ``opened``: each chunk's
    records as one ``OPENED_CHUNK`` item (see ``records``)."""
    for opcode, body, end in top_records(data, size, walk, start, stop):
        if opcode != Opcode.CHUNK:
            walk.chunk = None
            yield opcode, data, body, end
            continue
        try:
            buffer = chunk_records(data, body, end)
        except DamagedChunk as error:
            walk.drop(body - HEAD.size, end - body + HEAD.size, f"chunk: {error}")
            continue
        walk.chunk = body - HEAD.size
        if opened:
            yield OPENED_CHUNK, buffer, 0, len(buffer)
        else:
            yield from inner_records(buffer)
        walk.chunk = None


def sound_summary(data: mmap.mmap | bytes, size: int) -> tuple[int, int] | None:
    """``(start, end)`` of the file's summary section when the file ends with a footer
    whose summary CRC checks out (a summary without CRC is not trusted); else None."""
    summary = _summary(data, size)
    return summary if isinstance(summary, tuple) else None


def _summary(data: mmap.mmap | bytes, size: int) -> tuple[int, int] | bool:
    """``(start, end)`` of a sound summary; True when the footer names a summary whose
    CRC fails (damaged: not to be used); False when there is none to check."""
    footer = size - len(MAGIC) - _FOOTER.size
    if footer < len(MAGIC) or data[size - len(MAGIC) : size] != MAGIC:
        return False
    opcode, length, start, offsets, crc = _FOOTER.unpack_from(data, footer)
    if opcode != Opcode.FOOTER or length != _FOOTER.size - HEAD.size or not crc:
        return False
    if not len(MAGIC) <= start < footer:
        return start != 0  # 0: a file without summary
    if zlib.crc32(data[start : footer + _FOOTER.size - 4]) != crc:
        return True
    end = offsets if start <= offsets <= footer else footer
    return start, end


def chunk_starts(data: mmap.mmap | bytes, size: int) -> list[int]:
    """The byte offsets of the file's chunk records, in file order, where a reader of a
    part of the file may start (``btlog.replay.parts``); empty when the file is to be
    read whole.

    A summary's CRC tells it was written whole, not that it tells the truth, so its
    chunk indexes are used only when they list exactly the chunk records that walking
    the file's records from its start finds (``top_records``: each chunk's own lengths
    checked), each once and with its length, and that walk reaches the footer without
    damage: then the records from one offset to the next are those a walk of the whole
    file meets there, none read twice or skipped (and only chunks before the data end
    record: what follows it is the summary's). Anything else (no sound summary, an
    offset into a chunk, past the end or into the summary, one listed twice, a wrong
    length, damaged framing) is empty: one walk of the whole file."""
    summary = sound_summary(data, size)
    if summary is None:
        return []
    listed = _chunk_indexes(data, summary)
    walk, data_end = Walk(""), False
    found: list[tuple[int, int]] = []
    for opcode, body, end in top_records(data, size, walk):
        if opcode == Opcode.DATA_END:  # what follows is the summary's, never a part's
            data_end = True
        elif opcode == Opcode.CHUNK and not data_end:
            found.append((body - HEAD.size, end - body + HEAD.size))
    if walk.dropped or walk.truncated or not data_end or listed is None:
        return []
    if sorted(listed) != found:
        return []
    return [offset for offset, _length in found]


def summary_message_count(data: mmap.mmap | bytes, size: int) -> int | None:
    """The message count a sound summary's statistics record gives (None without one):
    a hint of the work of reading the file, never a fact about its content."""
    summary = sound_summary(data, size)
    if summary is None:
        return None
    position, stop = summary
    while position + HEAD.size <= stop:
        opcode, length = HEAD.unpack_from(data, position)
        body = position + HEAD.size
        if body + length > stop:
            return None
        if opcode == Opcode.STATISTICS and length >= 8:
            return int(_U64.unpack_from(data, body)[0])
        position = body + length
    return None


def _chunk_indexes(
    data: mmap.mmap | bytes, summary: tuple[int, int]
) -> list[tuple[int, int]] | None:
    """``(chunk start, chunk length)`` of each chunk index record of a sound summary, as
    listed; None when a record overruns the summary or a chunk index is too short."""
    position, stop = summary
    listed = []
    while position + HEAD.size <= stop:
        opcode, length = HEAD.unpack_from(data, position)
        body, end = position + HEAD.size, position + HEAD.size + length
        if end > stop or (opcode == Opcode.CHUNK_INDEX and length < 32):
            return None
        if opcode == Opcode.CHUNK_INDEX:
            listed.append(
                (_U64.unpack_from(data, body + 16)[0], _U64.unpack_from(data, body + 24)[0])
            )
        position = end
    return listed


def _summary_records(
    data: mmap.mmap | bytes, summary: tuple[int, int]
) -> Iterator[tuple[int, int, int]]:
    """``(opcode, body, end)`` of the schema and channel records of a sound summary."""
    position, stop = summary
    while position + HEAD.size <= stop:
        opcode, length = HEAD.unpack_from(data, position)
        body, end = position + HEAD.size, position + HEAD.size + length
        if end > stop:
            return
        if opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            yield opcode, body, end
        position = end


def inner_records(buffer: bytes) -> Iterator[tuple[int, bytes, int, int]]:
    """``(opcode, buffer, body, end)`` of the records of an opened chunk (whose CRC held)."""
    head, position, size = HEAD.unpack_from, 0, len(buffer)
    while position + HEAD.size <= size:
        opcode, length = head(buffer, position)
        body = position + HEAD.size
        end = body + length
        if end > size:
            return
        yield opcode, buffer, body, end
        position = end


def chunk_records(data: mmap.mmap | bytes, body: int, end: int) -> bytes:
    """The uncompressed records of the chunk ``data[body:end]``, its CRC checked."""
    try:
        _start, _end, size, crc = _CHUNK_HEAD.unpack_from(data, body)
        position = body + _CHUNK_HEAD.size
        (name_length,) = _U32.unpack_from(data, position)
        compression = bytes(data[position + 4 : position + 4 + name_length])
        position += 4 + name_length
        (length,) = _U64.unpack_from(data, position)
        if position + 8 + length != end:
            raise DamagedChunk("its records overrun the chunk")
        raw = data[position + 8 : end]
        if compression == b"zstd":
            records = zstandard.ZstdDecompressor().decompress(raw, max_output_size=size)
        elif compression == b"lz4":
            records = lz4.frame.decompress(raw)
        elif compression:
            raise DamagedChunk(f"unknown compression {compression.decode(errors='replace')!r}")
        else:
            records = bytes(raw)
    except (struct.error, zstandard.ZstdError, RuntimeError, ValueError) as error:
        if isinstance(error, DamagedChunk):
            raise
        raise DamagedChunk(f"{type(error).__name__}: {error}") from None
    if len(records) != size:
        raise DamagedChunk(f"{len(records)} bytes uncompressed, the header says {size}")
    if crc and zlib.crc32(records) != crc:
        raise DamagedChunk("CRC mismatch")
    return records


def parse(opcode: int, buffer: Any, body: int, end: int) -> Any:
    """The ``mcap`` record object of a record (None for indexes and summary records)."""
    kind = _PARSED.get(opcode)
    if kind is None:
        return None
    stream = ReadDataStream(BytesIO(buffer[body:end]))
    return kind.read(stream, end - body) if kind is Message else kind.read(stream)


def _framed(opcode: int, data: mmap.mmap | bytes, body: int, end: int) -> bool:
    """False when a chunk's or a message index's own lengths disagree with its record
    length (a damaged length would otherwise send the walk into the middle of the next
    record, or past a whole chunk: no CRC guards the records between chunks)."""
    if opcode == Opcode.MESSAGE_INDEX:  # channel id, then (time, offset) pairs
        if end - body < 6:
            return False
        (pairs,) = _U32.unpack_from(data, body + 2)
        return pairs % 16 == 0 and body + 6 + pairs == end
    if opcode != Opcode.CHUNK:
        return True
    try:
        position = body + _CHUNK_HEAD.size
        (name_length,) = _U32.unpack_from(data, position)
        (length,) = _U64.unpack_from(data, position + 4 + name_length)
    except struct.error:
        return False
    return position + 4 + name_length + 8 + length == end


def _next_chunk(data: mmap.mmap | bytes, start: int, size: int) -> int | None:
    """The offset of the first sound chunk record at or after ``start`` (None if none)."""
    opcode = bytes([Opcode.CHUNK])
    position = data.find(opcode, start, size)
    while position >= 0:
        if position + HEAD.size <= size:
            _op, length = HEAD.unpack_from(data, position)
            body, end = position + HEAD.size, position + HEAD.size + length
            if end <= size and _framed(Opcode.CHUNK, data, body, end):
                try:
                    chunk_records(data, body, end)
                    return position
                except DamagedChunk:
                    pass
        position = data.find(opcode, position + 1, size)
    return None

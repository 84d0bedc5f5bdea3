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

``Walk`` collects what was noticed (``truncated``, ``warnings``, ``dropped``).
``parse`` turns a record into the ``mcap`` package's record object when a reader wants
one; the bulk ingestion reads message bodies straight from the buffer instead.
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from io import BytesIO
from typing import IO, Any

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
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
_KNOWN = frozenset(int(opcode) for opcode in Opcode)
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

    def drop(self, offset: int, length: int, reason: str) -> None:
        """Note unreadable bytes, with the one warning every reader prints for them."""
        self.dropped.append(Dropped(offset, length, reason))
        self.warnings.append(
            f"{self.path}: damaged data at byte {offset} ({length} bytes) skipped: {reason}"
        )


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


def top_records(data: mmap.mmap | bytes, size: int, walk: Walk) -> Iterator[tuple[int, int, int]]:
    """``(opcode, body, end)`` of every top-level record up to the footer, chunks left
    closed; damaged framing is resynchronised on the next sound chunk (see the module)."""
    position = len(MAGIC)
    while position + HEAD.size <= size:
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


def records(data: mmap.mmap | bytes, size: int, walk: Walk) -> Iterator[tuple[int, Any, int, int]]:
    """``(opcode, buffer, body, end)`` of every record of the file in order, the records
    inside each chunk instead of the chunk; a damaged chunk is skipped with a warning."""
    for opcode, body, end in top_records(data, size, walk):
        if opcode != Opcode.CHUNK:
            yield opcode, data, body, end
            continue
        try:
            buffer = chunk_records(data, body, end)
        except DamagedChunk as error:
            walk.drop(body - HEAD.size, end - body + HEAD.size, f"chunk: {error}")
            continue
        yield from inner_records(buffer)


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
    """False when a chunk's own lengths disagree with its record length (a damaged
    length would otherwise send the walk into the middle of the next record)."""
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

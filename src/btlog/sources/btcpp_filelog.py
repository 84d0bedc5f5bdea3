"""BehaviorTree.CPP v4 ``FileLogger2`` files (``.btlog``, what Groot2 opens).

The layout (``src/loggers/bt_file_logger_v2.cpp``), little-endian throughout:

- the magic ``BTCPP4-FileLogger2`` and one version byte (1);
- an i32 length N and N bytes of tree XML (``WriteTreeToXML`` with ``_uid``/``_fullpath``
  and the ``<TreeNodesModel>``);
- an i64: the start time in µs since the Unix epoch;
- 9-byte transition records until the end (``btlog.sources.btcpp_records``).

BT.CPP writes the records from a thread, so a file copied while the robot runs may end in
the middle of a record: the whole records are imported, with a warning.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from btlog.sources import FILELOG_MAGIC
from btlog.sources.btcpp_records import RECORD_SIZE, decode_records, record_at
from btlog.sources.btcpp_tree import tree_from_file, tree_from_log_xml
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    RecordingBuilder,
    Source,
    SourceError,
    wall_start,
)
from btlog.status import Status
from btlog.tree.model import Tree
from btlog.tree.registry import Registry

FORMAT = "btcpp-filelog2"
VERSION = 1
_HEAD = len(FILELOG_MAGIC) + 1


#: Bytes of records read at a time (a whole number of records): the import's memory
#: does not grow with the file.
BLOCK = RECORD_SIZE * 65536


@dataclass
class FileLog:
    """A FileLogger2 file's header (version, tree XML, start time in µs and where it lies)
    and where its records lie; the records are read from the file when iterated."""

    file: str
    version: int
    xml: bytes
    start_us: int
    count: int
    trailing: int
    start_offset: int = 0
    records_offset: int = 0

    def __len__(self) -> int:
        return self.count

    def transitions(self, block: int = BLOCK) -> Iterator[tuple[int, int, Status]]:
        """``(µs since start, uid, status)`` for each whole record, in file order, read
        ``block`` bytes (rounded to whole records) at a time: the records the file held
        when it was opened."""
        per_block = max(1, block // RECORD_SIZE)
        try:
            with open(self.file, "rb") as stream:
                stream.seek(self.records_offset)
                for first in range(0, self.count, per_block):
                    want = min(per_block, self.count - first) * RECORD_SIZE
                    data = stream.read(want)
                    yield from decode_records(data, self.file, self.records_offset, first)
                    if len(data) < want:
                        at = record_at(first + len(data) // RECORD_SIZE, self.records_offset)
                        raise SourceError(f"{self.file}: the file was cut while read, at {at}")
        except OSError as error:
            raise SourceError(f"{self.file}: cannot read the file: {error.strerror}") from None


def read_filelog(path: str | os.PathLike) -> FileLog:
    """Parse a FileLogger2 file's header (``SourceError`` naming the file and the bad
    value); its records are read when ``FileLog.transitions`` is iterated."""
    file = os.fspath(path)
    try:
        with open(path, "rb") as stream:
            size = os.fstat(stream.fileno()).st_size
            head = stream.read(_HEAD + 4)
            if not head.startswith(FILELOG_MAGIC):
                raise SourceError(f"{file}: not a FileLogger2 log (magic {head[:18]!r})")
            if len(head) < _HEAD + 4:
                raise SourceError(f"{file}: ends inside the header ({len(head)} bytes)")
            version = head[len(FILELOG_MAGIC)]
            if version != VERSION:
                raise SourceError(f"{file}: FileLogger2 version {version}; btlog reads version 1")
            (length,) = struct.unpack_from("<i", head, _HEAD)
            body = _HEAD + 4
            if length <= 0 or body + length + 8 > size:
                raise SourceError(
                    f"{file}: XML length {length} does not fit in the file ({size} bytes)"
                )
            xml = stream.read(length)
            (start_us,) = struct.unpack("<q", stream.read(8))
    except OSError as error:
        raise SourceError(f"{file}: cannot read the file: {error.strerror}") from None
    records = size - (body + length + 8)
    count, trailing = divmod(records, RECORD_SIZE)
    return FileLog(file, version, xml, start_us, count, trailing, body + length, body + length + 8)


def import_filelog(
    path: str | os.PathLike,
    output: str | os.PathLike,
    tree_file: str | os.PathLike | None = None,
    registry: Registry | None = None,
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS,
) -> BuildResult:
    """Import a FileLogger2 file into the recording ``output``."""
    log = read_filelog(path)
    tree = log_tree(log, tree_file, registry)
    warnings: list[str] = []
    started = wall_start(log.start_us, f"{log.file} (byte {log.start_offset})", warnings)
    source = Source.of_file(FORMAT, path, version=log.version, records=len(log))
    builder = RecordingBuilder(
        output,
        tree,
        source,
        started_at=started,
        attachments=[("btcpp-tree.xml", log.xml)],
        tick_gap_ns=tick_gap_ns,
    )
    builder.warnings.extend(warnings)
    try:
        for number, (t_us, uid, status) in enumerate(log.transitions()):
            try:
                builder.transition(t_us * 1000, uid, status)
            except SourceError as error:
                raise SourceError(f"{error} ({record_at(number, log.records_offset)})") from None
    except BaseException:
        builder.close()
        Path(output).unlink(missing_ok=True)
        raise
    if log.trailing:
        builder.warnings.append(
            f"{log.file}: the file ends inside a record ({log.trailing} of 9 bytes); "
            f"imported the {len(log)} whole records"
        )
    return builder.close()


def log_tree(log: FileLog, tree_file: str | os.PathLike | None, registry: Registry | None) -> Tree:
    """The log's tree, or the user's ``tree_file`` once it is checked against it."""
    tree = tree_from_log_xml(log.xml, f"{log.file} (embedded XML)", registry)
    if tree_file is None:
        return tree
    return tree_from_file(tree_file, tree, registry)

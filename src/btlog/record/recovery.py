"""Recovery: rewrite a truncated recording into a valid, indexed MCAP file.

A recorder killed mid-run leaves a file with no summary: readable front to back (the
reader does so, with a warning), but not by tools that need the index (seeking readers,
``mcap info``, Foxglove). ``recover`` reads every complete record of the broken file —
schemas, channels, the ``btlog.run`` metadata, the attachments and every message of every
whole chunk — and writes them, unchanged, into a new file that the MCAP writer finishes
with a summary: the messages in seq order within their topic (whatever the order of the
chunks), each once (a chunk or message written twice is dropped, and counted), the tree
rebuilt from its XML attachment when its message was lost. The result is read back
before it replaces the target; a file with nothing to recover (no ``btlog.run``
metadata, no tree and no tree file attached) is refused in one line. A damaged chunk
(bad CRC, bad framing) is dropped and every intact chunk after it kept
(``btlog.record.walk``); the report says which bytes were dropped and which seqs are
missing from what was saved. The new file is written beside the target and moved into
place at the end, so the target may be the broken file itself. Memory stays bounded
whatever the run's length: the messages are copied a chunk at a time, in file order
when the file has them in seq order, else merged chunk by chunk (``btlog.record.salvage``).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import orjson
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.well_known import SchemaEncoding
from mcap.writer import Writer

from btlog.errors import one_line
from btlog.record import format as fmt
from btlog.record.background import name_file
from btlog.record.reader import (
    MALFORMED_MESSAGE,
    RecordingError,
    _records,
    decode_metadata,
    tree_of,
)
from btlog.record.recorder import DEFAULT_COMPRESSION, start_time_ns
from btlog.record.salvage import (
    MALFORMED,
    Facts,
    Item,
    OutOfOrder,
    Sifter,
    Source,
    check_message,
)
from btlog.record.walk import Dropped, Walk, mapped, records
from btlog.schema import schema_text
from btlog.tree.loader import load_tree


@dataclass
class RecoveryReport:
    """What ``recover`` saved: counts of events, ticks and messages, and the last seq."""

    source: Path
    target: Path
    truncated: bool
    messages: int = 0
    events: int = 0
    ticks: int = 0
    last_seq: int | None = None
    warnings: list[str] = field(default_factory=list)
    #: bytes of the source that could not be read (damaged chunks or framing)
    dropped: list[Dropped] = field(default_factory=list)
    #: ``(first, last)`` seq ranges absent from what was saved, below ``last_seq``
    missing: list[tuple[int, int]] = field(default_factory=list)
    #: messages dropped because the file held them twice (a chunk written twice)
    duplicates: int = 0
    #: the attached tree file the lost ``/btlog/tree`` message was rebuilt from
    tree_rebuilt: str = ""
    _ranges: list[tuple[int, int]] = field(default_factory=list, repr=False)

    def summary(self) -> str:
        """One line for a person."""
        state = "truncated" if self.truncated else "complete"
        last = "no events" if self.last_seq is None else f"last seq {self.last_seq}"
        line = (
            f"{self.source} ({state}) -> {self.target}: {self.events} events, "
            f"{self.ticks} ticks, {self.messages} messages saved; {last}"
        )
        if self.dropped:
            spans = ", ".join(f"{d.length} bytes at byte {d.offset}" for d in self.dropped)
            line += f"; dropped {len(self.dropped)} damaged part(s): {spans}"
        if self.duplicates:
            line += f"; {self.duplicates} duplicated messages dropped"
        if self.tree_rebuilt:
            line += f"; the tree rebuilt from the attached {self.tree_rebuilt}"
        if self.missing:
            seqs = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in self.missing)
            line += f"; seqs missing: {seqs}"
        return line

    def __str__(self) -> str:
        return self.summary()

    def note_seqs(self, first: int, last: int) -> None:
        """Note that the seqs ``first..last`` of one message were saved."""
        ranges = self._ranges  # merged as they come (they come in seq order): a few
        if ranges and ranges[-1][0] <= first <= ranges[-1][1] + 1:
            ranges[-1] = (ranges[-1][0], max(last, ranges[-1][1]))
        else:
            ranges.append((first, last))
        if self.last_seq is None or last > self.last_seq:
            self.last_seq = last

    def find_missing(self) -> None:
        """Fill ``missing``: the holes between the saved seq ranges (from seq 0)."""
        covered = -1
        for first, last in sorted(self._ranges):
            if first > covered + 1:
                self.missing.append((covered + 1, first - 1))
            covered = max(covered, last)


class _Copier:
    """Copies records into an MCAP writer, renumbering schemas and channels (each once:
    a finished file repeats them in its summary), and counts what it saves."""

    def __init__(self, writer: Writer, report: RecoveryReport) -> None:
        self.writer = writer
        self.report = report
        self.schemas: dict[int, int] = {0: 0}
        self.channels: dict[int, tuple[int, str]] = {}
        self.sifter = Sifter()

    def copy(self, record: object) -> None:
        if isinstance(record, Schema) and record.id not in self.schemas:
            self.schemas[record.id] = self.writer.register_schema(
                record.name, record.encoding, record.data
            )
        elif isinstance(record, Channel) and record.id not in self.channels:
            new_id = self.writer.register_channel(
                record.topic,
                record.message_encoding,
                self.schemas.get(record.schema_id, 0),
                record.metadata,
            )
            self.channels[record.id] = (new_id, record.topic)
        elif isinstance(record, Metadata):
            self.writer.add_metadata(record.name, record.metadata)
        elif isinstance(record, Attachment):
            self.writer.add_attachment(
                record.create_time, record.log_time, record.name, record.media_type, record.data
            )

    def message(self, message: Message, topic: str, known: Facts) -> None:
        """Copy one message (a copy met before dropped and counted; two different events
        with one seq refused)."""
        channel = self.channels.get(message.channel_id)
        if channel is None:
            return
        if not self.sifter.fresh(message, known):
            self.report.duplicates += 1
            return
        try:
            twice = self.sifter.twice(topic, message.data, known)
        except MALFORMED:
            twice = None
        if twice is not None:
            raise RecordingError(
                f"{self.report.source}: what can be saved is not a recording: two different "
                f"events have seq {twice}"
            )
        self.writer.add_message(
            channel[0], message.log_time, message.data, message.publish_time, message.sequence
        )
        report = self.report
        report.messages += 1
        if not known.readable:
            report.warnings.append(
                f"{report.source}: a {topic} message is not "
                "in the btlog format (copied, not counted)"
            )
            return
        report.events += known.events
        report.ticks += known.ticks
        if known.first is not None and known.last is not None:
            report.note_seqs(known.first, known.last)


def recover(broken: str | os.PathLike, fixed: str | os.PathLike) -> RecoveryReport:
    """Rewrite every complete record of ``broken`` into the valid MCAP file ``fixed``:
    the messages in seq order (whatever the order of the chunks), each once (duplicated
    chunks or messages are dropped, and counted), the tree rebuilt from the XML
    attachment when its message was lost. The result is read back before it replaces
    ``fixed``.

    Works on a complete file too (a re-indexed copy). Raises ``RecordingError`` when
    ``broken`` is not an MCAP file, or holds nothing to recover (no ``btlog.run``
    metadata, no tree), or what it holds does not make a readable recording.
    """
    source, target = Path(broken), Path(fixed)
    walk = Walk(str(source))
    with mapped(source) as (data, size):
        header, others, used = _survey(data, size, walk)
        if header is None:
            raise RecordingError(f"{source}: not an MCAP file (no header record)")
        metadata = next(
            (r for r in others if isinstance(r, Metadata) and r.name == fmt.METADATA_NAME), None
        )
        if metadata is None:
            damage = "".join(
                f"; {d.length} damaged bytes at byte {d.offset}" for d in walk.dropped[:1]
            )
            raise RecordingError(
                f"{source}: nothing to recover: no {fmt.METADATA_NAME} metadata{damage}"
            )
        topics = {r.id: r.topic for r in others if isinstance(r, Channel)}
        tree: list[Message] = []
        rebuilt = RecoveryReport(source, target, truncated=walk.truncated)
        if not any(topics.get(channel) == fmt.TREE_TOPIC for channel in used):
            others, message = _with_rebuilt_tree(source, others, metadata, rebuilt)
            tree = [message]
            topics[message.channel_id] = fmt.TREE_TOPIC
        messages = Source(data, size, walk, topics)
        for order in (messages.in_file_order, messages.in_seq_order):
            report = RecoveryReport(source, target, truncated=walk.truncated)
            report.warnings.extend(walk.warnings)
            report.dropped.extend(walk.dropped)
            report.tree_rebuilt = rebuilt.tree_rebuilt if tree else ""
            try:
                _rewrite(target, header.library, report, others, _with(tree, order))
                break
            except OutOfOrder:
                continue
    report.find_missing()
    return report


def _with(first: list[Message], order: Callable[[], Iterator[Item]]) -> Iterator[Item]:
    """The messages ``first`` (the rebuilt tree), then those of ``order``."""
    for message in first:
        yield message, fmt.TREE_TOPIC, Facts(0, -1)
    yield from order()


def _survey(data: object, size: int, walk: Walk) -> tuple[Header | None, list, set[int]]:
    """The file's header (None if its first record is not one), its other records but
    messages (schemas, channels, metadata, attachments) and the channels its messages
    use; the walk notes a cut, damaged bytes and warnings."""
    header: Header | None = None
    others: list = []
    used: set[int] = set()
    first = True
    for opcode, buffer, body, end in records(data, size, walk):  # type: ignore[arg-type]
        if opcode == Opcode.MESSAGE and end - body >= 2:
            used.add(int.from_bytes(buffer[body : body + 2], "little"))
            first = False
            continue
        record = walk.parse(opcode, buffer, body, end)
        if record is None:
            continue
        if first and isinstance(record, Header):
            header = record
        elif isinstance(record, Schema | Channel | Metadata | Attachment):
            others.append(record)
        first = False
    return header, others, used


def _with_rebuilt_tree(
    source: Path, others: list, metadata: Metadata, report: RecoveryReport
) -> tuple[list, Message]:
    """``others`` (the tree's channel registered if it was lost too) and a
    ``/btlog/tree`` message made from the tree files attached; RecordingError when there
    are none or they do not load."""
    files = {r.name: r.data for r in others if isinstance(r, Attachment)}
    if not files:
        raise RecordingError(
            f"{source}: nothing to recover: the {fmt.TREE_TOPIC} message is lost and no tree "
            "file is attached to rebuild it from"
        )
    main = Path(metadata.metadata.get("tree_file", "")).name
    main = main if main in files else next(iter(files))
    with tempfile.TemporaryDirectory(prefix="btlog-recover-") as folder:
        for name, data in files.items():
            (Path(folder) / Path(name).name).write_bytes(data)
        try:
            tree = load_tree(
                Path(folder) / Path(main).name,
                main_tree=metadata.metadata.get("main_tree") or None,
                accept_unknown=True,
            )
        except (ValueError, OSError) as error:
            raise RecordingError(
                f"{source}: the {fmt.TREE_TOPIC} message is lost and the attached {main} "
                f"does not load: {one_line(error)}"
            ) from None
    channels = [r for r in others if isinstance(r, Channel)]
    channel = next((c for c in channels if c.topic == fmt.TREE_TOPIC), None)
    if channel is None:
        schema_id = max((r.id for r in others if isinstance(r, Schema)), default=0) + 1
        name, schema_file, encoding = fmt.TOPICS[fmt.TREE_TOPIC]
        text = schema_text(schema_file)
        schema = Schema(id=schema_id, name=name, encoding=SchemaEncoding.JSONSchema, data=text)
        channel = Channel(
            id=max((c.id for c in channels), default=0) + 1,
            topic=fmt.TREE_TOPIC,
            message_encoding=encoding,
            schema_id=schema_id,
            metadata={},
        )
        others = [*others, schema, channel]
    start = start_time_ns(metadata.metadata.get("started_at", ""))
    description = tree.describe()
    for node in description["nodes"]:  # the files as attached, not where they were loaded
        if isinstance(node.get("file"), str) and node["file"].startswith(folder):
            node["file"] = Path(node["file"]).name
    data = fmt.dumps(description)
    message = Message(
        channel_id=channel.id, sequence=0, log_time=start, publish_time=start, data=data
    )
    report.tree_rebuilt = main
    return others, message


def _rewrite(
    target: Path, library: str, report: RecoveryReport, others: list, messages: Iterator[Item]
) -> None:
    """Write ``others`` then ``messages`` into ``target`` through a temporary file in the
    same folder, read back (a file nothing can read never replaces ``target``)."""
    temporary = target.with_name(f".{target.name}.{os.getpid()}.recovering")
    try:
        with open(temporary, "wb") as out:
            writer = Writer(out, compression=DEFAULT_COMPRESSION)
            writer.start(profile="", library=library)
            copier = _Copier(writer, report)
            for record in others:
                copier.copy(record)
            for message, topic, known in messages:
                copier.message(message, topic, known)
            writer.finish()
        _check_readable(report.source, temporary)
        os.replace(temporary, target)
    except OSError as error:
        Path(temporary).unlink(missing_ok=True)
        raise name_file(error, str(target)) from None
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def _check_readable(source: Path, written: Path) -> None:
    """RecordingError naming ``source`` unless ``written`` reads as a recording: its
    records whole, its ``btlog.run`` metadata and tree sound, every message in the
    btlog format (read a message at a time; the binary columns checked, not decoded)."""
    name = str(written)
    walk = Walk(name)
    metadata = tree = None
    try:
        for record in _records(written, walk):
            if type(record) is tuple:
                topic, message = record
                if topic == fmt.TREE_TOPIC and tree is None:
                    tree = orjson.loads(message.data)
                else:
                    check_message(topic, message.data)
            elif isinstance(record, Metadata) and record.name == fmt.METADATA_NAME:
                metadata = metadata or record.metadata
        if metadata is None:
            raise RecordingError(f"{name}: not a btlog recording: no {fmt.METADATA_NAME} metadata")
        decode_metadata(name, metadata)
        tree_of(name, tree, walk)
    except (RecordingError, *MALFORMED_MESSAGE) as error:
        problem = str(error).replace(name, "the result")
        if not isinstance(error, RecordingError):
            kind = type(error).__name__
            problem = f"a message does not follow the btlog format: {kind}: {problem}"
        raise RecordingError(f"{source}: what can be saved is not a recording: {problem}") from None

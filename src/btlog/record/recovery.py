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
place at the end, so the target may be the broken file itself. The messages are held in
memory while they are put in order.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import orjson
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.well_known import SchemaEncoding
from mcap.writer import Writer

from btlog.errors import one_line
from btlog.record import format as fmt
from btlog.record.background import name_file
from btlog.record.reader import RecordingError, open_recording, raw_records, seq_of
from btlog.record.recorder import DEFAULT_COMPRESSION, start_time_ns
from btlog.record.walk import Dropped, Walk
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
        self._ranges.append((first, last))
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

    def copy(self, record: object) -> None:
        if isinstance(record, Message):
            self._message(record)
        elif isinstance(record, Schema) and record.id not in self.schemas:
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

    def _message(self, message: Message) -> None:
        channel = self.channels.get(message.channel_id)
        if channel is None:
            return
        channel_id, topic = channel
        self.writer.add_message(
            channel_id, message.log_time, message.data, message.publish_time, message.sequence
        )
        self.report.messages += 1
        try:
            self._count(topic, message.data)
        except (orjson.JSONDecodeError, AttributeError, TypeError, LookupError, ValueError):
            self.report.warnings.append(
                f"{self.report.source}: a {topic} message is not "
                "in the btlog format (copied, not counted)"
            )

    def _count(self, topic: str, data: bytes) -> None:
        if topic == fmt.EVENTS_TOPIC:
            events = fmt.parse_events(data)
            seqs = [row[0] for rows in (events.status, events.writes) for row in rows]
            self.report.events += len(seqs)
            if seqs:
                self.report.note_seqs(min(seqs), max(seqs))
        elif topic == fmt.MUTATIONS_TOPIC:
            self.report.events += 1
            seq = orjson.loads(data).get("seq")
            if isinstance(seq, int):
                self.report.note_seqs(seq, seq)
        elif topic == fmt.TICKS_TOPIC:
            self.report.ticks += sum(not r.teardown for r in fmt.decode_ticks(data))


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
    records = list(raw_records(source, walk))
    if not records or not isinstance(records[0], Header):
        raise RecordingError(f"{source}: not an MCAP file (no header record)")
    report = RecoveryReport(source, target, truncated=walk.truncated)
    report.warnings.extend(walk.warnings)
    report.dropped.extend(walk.dropped)
    others = [r for r in records[1:] if not isinstance(r, Message)]
    metadata = next(
        (r for r in others if isinstance(r, Metadata) and r.name == fmt.METADATA_NAME), None
    )
    if metadata is None:
        damage = "".join(
            f"; {d.length} damaged bytes at byte {d.offset}" for d in report.dropped[:1]
        )
        raise RecordingError(
            f"{source}: nothing to recover: no {fmt.METADATA_NAME} metadata{damage}"
        )
    topics = {r.id: r.topic for r in others if isinstance(r, Channel)}
    messages = _in_order(records[1:], topics, report)
    if not any(topics.get(m.channel_id) == fmt.TREE_TOPIC for m in messages):
        others, messages = _with_rebuilt_tree(source, others, messages, metadata, report)
    _rewrite([*others, *messages], target, records[0].library, report)
    report.find_missing()
    return report


#: The rank of each topic's messages in a recovered file (events and mutations share
#: the seq order).
_RANKS = {
    fmt.TREE_TOPIC: 0,
    fmt.EVENTS_TOPIC: 1,
    fmt.MUTATIONS_TOPIC: 1,
    fmt.TICKS_TOPIC: 2,
    fmt.ANSWERS_TOPIC: 3,
}


def _in_order(records: list, topics: dict[int, str], report: RecoveryReport) -> list[Message]:
    """The messages of ``records``, each once, in seq order within their topic."""
    seen: set[tuple[int, int, bytes]] = set()
    keyed = []
    for index, record in enumerate(records):
        if not isinstance(record, Message):
            continue
        identity = (record.channel_id, record.log_time, record.data)
        if identity in seen:
            report.duplicates += 1
            continue
        seen.add(identity)
        topic = topics.get(record.channel_id, "")
        keyed.append(((_RANKS.get(topic, 4), _first_number(topic, record.data), index), record))
    keyed.sort(key=lambda pair: pair[0])
    return [record for _key, record in keyed]


def _first_number(topic: str, data: bytes) -> int:
    """The first seq (tick for ticks) a message holds; -1 if it cannot be read."""
    try:
        if topic == fmt.EVENTS_TOPIC:
            events = fmt.parse_events(data)
            return min(
                (row[0] for rows in (events.status, events.writes) for row in rows), default=-1
            )
        if topic == fmt.TICKS_TOPIC:
            return min((t.tick for t in fmt.decode_ticks(data)), default=-1)
        if topic in (fmt.MUTATIONS_TOPIC, fmt.ANSWERS_TOPIC):
            return seq_of(orjson.loads(data))
    except (orjson.JSONDecodeError, AttributeError, TypeError, LookupError, ValueError):
        pass
    return -1


def _with_rebuilt_tree(
    source: Path, others: list, messages: list[Message], metadata: Metadata, report: RecoveryReport
) -> tuple[list, list[Message]]:
    """``others`` and ``messages`` with a ``/btlog/tree`` message made from the tree files
    attached (the tree's channel registered if it was lost too); RecordingError when
    there are none or they do not load."""
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
    return others, [message, *messages]


def _rewrite(records: list, target: Path, library: str, report: RecoveryReport) -> None:
    """Write ``records`` into ``target`` through a temporary file in the same folder,
    read back (a file nothing can read never replaces ``target``)."""
    temporary = target.with_name(f".{target.name}.{os.getpid()}.recovering")
    try:
        with open(temporary, "wb") as out:
            writer = Writer(out, compression=DEFAULT_COMPRESSION)
            writer.start(profile="", library=library)
            copier = _Copier(writer, report)
            for record in records:
                copier.copy(record)
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
    """RecordingError naming ``source`` unless ``written`` reads as a recording whose
    events have distinct seqs."""
    try:
        recording = open_recording(written)
    except RecordingError as error:
        problem = str(error).replace(str(written), "the result")
        raise RecordingError(f"{source}: what can be saved is not a recording: {problem}") from None
    seqs = [event.seq for event in recording.events]
    twice = next((a for a, b in pairwise(seqs) if a == b), None)
    if twice is not None:
        raise RecordingError(
            f"{source}: what can be saved is not a recording: two different events have seq {twice}"
        )

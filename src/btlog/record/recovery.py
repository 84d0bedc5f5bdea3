"""Recovery: rewrite a truncated recording into a valid, indexed MCAP file.

A recorder killed mid-run leaves a file with no summary: readable front to back (the
reader does so, with a warning), but not by tools that need the index (seeking readers,
``mcap info``, Foxglove). ``recover`` reads every complete record of the broken file —
schemas, channels, the ``btlog.run`` metadata, the attachments and every message of every
whole chunk — and writes them, unchanged and in the same order, into a new file that the
MCAP writer finishes with a summary. A damaged chunk (bad CRC, bad framing) is dropped and
every intact chunk after it kept (``btlog.record.walk``); the report says which bytes were
dropped and which seqs are missing from what was saved. The new file is written beside
the target and moved into place at the end, so the target may be the broken file itself.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import orjson
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import Writer

from btlog.record import format as fmt
from btlog.record.reader import RecordingError, raw_records
from btlog.record.recorder import DEFAULT_COMPRESSION
from btlog.record.walk import Dropped, Walk


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
    """Rewrite every complete record of ``broken`` into the valid MCAP file ``fixed``.

    Works on a complete file too (a re-indexed copy). Raises ``RecordingError`` when
    ``broken`` is not an MCAP file at all.
    """
    source, target = Path(broken), Path(fixed)
    walk = Walk(str(source))
    records = raw_records(source, walk)
    header = next(records, None)
    if not isinstance(header, Header):
        raise RecordingError(f"{source}: not an MCAP file (no header record)")
    report = RecoveryReport(source, target, truncated=False)
    _rewrite(records, target, header.library, report)
    report.truncated = walk.truncated
    report.warnings.extend(walk.warnings)
    report.dropped.extend(walk.dropped)
    report.find_missing()
    return report


def _rewrite(records: Iterator[object], target: Path, library: str, report: RecoveryReport) -> None:
    """Write ``records`` into ``target`` through a temporary file in the same folder."""
    temporary = target.with_name(f".{target.name}.{os.getpid()}.recovering")
    try:
        with open(temporary, "wb") as out:
            writer = Writer(out, compression=DEFAULT_COMPRESSION)
            writer.start(profile="", library=library)
            copier = _Copier(writer, report)
            for record in records:
                copier.copy(record)
            writer.finish()
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise

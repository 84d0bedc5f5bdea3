"""The reader: a recording back as events, ticks, the tree and the run's metadata.

The file is walked by ``btlog.record.walk`` (the one record walker): a file cut short
(the recorder was killed) is read up to its last whole record — with the recorder's
flushing, a gap-free prefix of the run's events — and a damaged chunk is skipped;
warnings say both. What is read does not depend on the order of the chunks in the file:
events, ticks and answers are put in seq (tick) order.

Bad input (a missing, empty or non-MCAP file, a file that is not a btlog recording, a
schema version this btlog does not read) raises ``RecordingError`` with one line naming
the file and the problem.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from itertools import pairwise
from operator import attrgetter
from pathlib import Path
from typing import Any

import orjson
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Message, Metadata

import btlog
from btlog.events import BlackboardWrite, StatusChange, TickRecord, TreeMutation
from btlog.record import format as fmt
from btlog.record.walk import (
    RecordingError,
    Walk,
    mapped,
    open_mcap,
    records,
    top_records,
)
from btlog.tree.model import Tree, TreeDescriptionError

#: What decoding a message that does not follow the btlog format raises.
MALFORMED_MESSAGE = (
    orjson.JSONDecodeError,
    KeyError,
    TypeError,
    ValueError,
    AttributeError,
    IndexError,
)


def raw_records(path: str | os.PathLike, walk: Walk) -> Iterator[Any]:
    """Every record of the file as ``mcap`` record objects, in file order, chunks opened
    (see ``btlog.record.walk``: a cut file stops at its cut, damaged chunks are skipped,
    both noted in ``walk``). Used by the reader and by ``recover``."""
    with mapped(path) as (data, size):
        for opcode, buffer, body, end in records(data, size, walk):
            record = walk.parse(opcode, buffer, body, end)
            if record is not None:
                yield record


def _records(path: str | os.PathLike, walk: Walk) -> Iterator[Any]:
    """Metadata, attachments and messages as ``(topic, Message)``, front to back."""
    topics: dict[int, str] = {}
    for record in raw_records(path, walk):
        if isinstance(record, Message):
            topic = topics.get(record.channel_id)
            if topic is not None:
                yield topic, record
        elif isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Metadata | Attachment):
            yield record


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
        self._walk = Walk(self.path)
        self._records = _records(self.path, self._walk)

    def __iter__(self) -> Iterator[tuple[str, int, bytes]]:
        for record in self._records:
            if type(record) is tuple:
                topic, message = record
                yield topic, message.log_time, message.data

    @property
    def truncated(self) -> bool:
        """True when the file was cut short (known once iterated)."""
        return self._walk.truncated

    @property
    def warnings(self) -> list[str]:
        """What was noticed while reading (known once iterated)."""
        return self._walk.warnings


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
    record = None
    walk = Walk(name)
    with mapped(name) as (data, size):
        for opcode, body, end in top_records(data, size, walk):
            if opcode == Opcode.METADATA:
                found = walk.parse(opcode, data, body, end)
                if found is not None and found.name == fmt.METADATA_NAME:
                    record = found
                    break
    if record is None:
        raise RecordingError(f"{name}: not a btlog recording (no {fmt.METADATA_NAME} metadata)")
    return decode_metadata(name, record.metadata)


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
            self.events.extend(fmt.decode_events(message.data))
        elif topic == fmt.TICKS_TOPIC:
            self.ticks.extend(fmt.decode_ticks(message.data))
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
    walk = Walk(name)
    contents = _Contents()
    try:
        for record in _records(name, walk):
            contents.add(record)
    except MALFORMED_MESSAGE as error:
        if isinstance(error, RecordingError):
            raise
        raise RecordingError(
            f"{name}: a message does not follow the btlog format: {type(error).__name__}: {error}"
        ) from None
    return _assemble(name, contents, walk)


def stream_events(
    path: str | os.PathLike, on_ticks: Callable[[list[TickRecord]], None] | None = None
) -> tuple[Tree, Iterator[Any]] | None:
    """The tree and the events of a recording read front to back without holding them,
    for consumers that fold the events once (``btlog diff``, ``check --rerun``); the tick
    records are handed to ``on_ticks`` as they come. None when the file is not a tidy
    recording (no tree before the first event, seqs out of order, damaged bytes):
    ``open_recording`` then reads it whole and reports what is wrong."""
    name = os.fspath(path)
    walk = Walk(name)
    records = _records(name, walk)
    tree: dict | None = None
    for record in records:
        if type(record) is not tuple:
            continue
        topic, message = record
        if topic == fmt.TREE_TOPIC:
            tree = orjson.loads(message.data)
            break
        if topic in (fmt.EVENTS_TOPIC, fmt.MUTATIONS_TOPIC, fmt.TICKS_TOPIC):
            return None
    if tree is None:
        return None

    def events() -> Iterator[Any]:
        last = -1
        for record in records:
            if type(record) is not tuple:
                continue
            topic, message = record
            batch: list[StatusChange | BlackboardWrite | TreeMutation]
            if topic == fmt.EVENTS_TOPIC:
                batch = list(fmt.decode_events(message.data))
            elif topic == fmt.MUTATIONS_TOPIC:
                batch = [fmt.decode_mutation(orjson.loads(message.data))]
            else:
                if topic == fmt.TICKS_TOPIC and on_ticks is not None:
                    on_ticks(fmt.decode_ticks(message.data))
                continue
            for event in batch:
                if event.seq != last + 1:
                    raise UntidyRecording
                last = event.seq
                yield event
        if walk.dropped:
            raise UntidyRecording

    return tree_of(name, tree, walk), events()


class UntidyRecording(Exception):
    """Raised by ``stream_events``' iterator when the file turns out not to be tidy (read
    it with ``open_recording`` instead)."""


def _assemble(name: str, contents: _Contents, walk: Walk) -> Recording:
    if contents.tree is None:
        tree_of(name, None, walk)
    if contents.metadata is None:
        raise RecordingError(f"{name}: not a btlog recording: no {fmt.METADATA_NAME} metadata")
    metadata = decode_metadata(name, contents.metadata)
    events = contents.events
    warnings = walk.warnings
    if not _gap_free(events):  # the recorder writes in seq order; anything else is sorted
        events.sort(key=attrgetter("seq"))
        if not _gap_free(events):
            warnings.append(f"{name}: the events' seqs are not 0, 1, 2, … without gaps")
    ticks = contents.ticks
    if any(a.tick > b.tick for a, b in pairwise(ticks)):
        ticks.sort(key=attrgetter("tick", "teardown"))
    answers = sorted(contents.answers, key=seq_of)
    if walk.truncated:
        last = f"up to seq {events[-1].seq}" if events else "(none)"
        warnings.insert(0, f"{name}: truncated recording; read {len(events)} events {last}")
    return Recording(
        Path(name),
        metadata,
        tree_of(name, contents.tree, walk),
        events,
        ticks,
        answers,
        contents.attachments,
        walk.truncated,
        warnings,
    )


def tree_of(name: str, message: dict | None, walk: Walk | None = None) -> Tree:
    """The tree of a recording's ``/btlog/tree`` message; RecordingError naming ``name``
    when there is none (and why, when ``walk`` knows: damaged bytes, a cut file) or it is
    not a tree."""
    if message is None:
        why = ""
        if walk is not None and walk.dropped:
            first = walk.dropped[0]
            why = (
                f" (damaged data at byte {first.offset}, {first.length} bytes, may have held "
                "it; 'btlog recover' rebuilds the tree from the XML attachment)"
            )
        elif walk is not None and walk.truncated:
            why = " (the file is cut before it)"
        raise RecordingError(f"{name}: not a btlog recording: no {fmt.TREE_TOPIC} message{why}")
    try:
        return Tree.from_description(message)
    except TreeDescriptionError as error:
        raise RecordingError(f"{name}: the {fmt.TREE_TOPIC} message: {error}") from None
    except (KeyError, TypeError, ValueError) as error:
        raise RecordingError(
            f"{name}: the {fmt.TREE_TOPIC} message is not a tree: {type(error).__name__}: {error}"
        ) from None


def seq_of(message: Any) -> int:
    """The seq of an answer or mutation message, for ordering (-1 when it has none)."""
    seq = message.get("seq") if isinstance(message, dict) else None
    return seq if isinstance(seq, int) else -1


def _gap_free(events: list) -> bool:
    """True when the seqs are exactly 0, 1, 2, … in list order."""
    return [event.seq for event in events] == list(range(len(events)))

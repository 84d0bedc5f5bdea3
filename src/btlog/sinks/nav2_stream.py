"""``btlog export --to nav2`` while reading the recording, in bounded memory.

The events are read in file order (``btlog.record.reader.iter_messages``) and each tick's
status changes become one ``/behavior_tree_log`` message as soon as the next tick's first
change comes; the tick's end time comes from a second reader of the ``/btlog/ticks``
messages, kept just ahead. The messages are those ``export_nav2`` writes from the whole
recording. A file whose events or ticks are not in order (chunks moved), or whose tree
comes after its events, makes ``stream_nav2`` return None after removing what it wrote;
the caller then exports through ``open_recording`` (unbounded memory, the same bytes).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import orjson
from mcap_ros2.writer import Writer

from btlog.events import BlackboardWrite, StatusChange
from btlog.record import format as fmt
from btlog.record.reader import (
    MALFORMED_MESSAGE,
    RecordingError,
    iter_messages,
    read_metadata,
    tree_of,
)
from btlog.record.recorder import start_time_ns
from btlog.sinks.btcpp_filelog import tree_xml
from btlog.sinks.nav2_rosbag import (
    _MAX_UID,
    LOG_MSGDEF,
    XML_MSGDEF,
    ExportResult,
    _stamp,
)
from btlog.sources.builder import SourceError
from btlog.sources.nav2_rosbag import LOG_TOPIC, LOG_TYPE, XML_TOPIC, XML_TYPE


class _NotStreamable(Exception):
    """The recording is not in order: export it whole instead."""


class _TickEnds:
    """The end time of each tick, read from the ``/btlog/ticks`` messages as needed (the
    last record of a tick wins, as in ``export_nav2``)."""

    def __init__(self, where: str) -> None:
        self._records = self._read(where)
        self._next: Any = next(self._records, None)

    @staticmethod
    def _read(where: str) -> Iterator[Any]:
        last = -1
        for topic, _time, data in iter_messages(where):
            if topic == fmt.TICKS_TOPIC:
                for record in fmt.decode_ticks(data):
                    if record.tick < last:
                        raise _NotStreamable
                    last = record.tick
                    yield record

    def end(self, tick: int) -> int:
        """The end time of ``tick`` (0 when it has no record)."""
        found = 0
        while self._next is not None and self._next.tick <= tick:
            if self._next.tick == tick:
                found = self._next.end_ns
            self._next = next(self._records, None)
        return found


def stream_nav2(
    path: str | os.PathLike, output: str | os.PathLike
) -> tuple[ExportResult, list[str]] | None:
    """Write the recording ``path`` as the ROS 2 MCAP bag ``output`` while reading it:
    (what was written, the reader's warnings); None (``output`` removed) when the file
    is not in order or not a sound recording. ``SourceError`` as ``export_nav2``."""
    where = os.fspath(path)
    try:
        with open(output, "wb") as stream:
            return _stream(where, read_metadata(where), Writer(stream), output)
    except SourceError:
        Path(output).unlink(missing_ok=True)
        raise
    except (_NotStreamable, RecordingError, KeyError, *MALFORMED_MESSAGE, struct.error):
        Path(output).unlink(missing_ok=True)
        return None


def _stream(
    where: str, metadata: dict[str, Any], writer: Writer, output: str | os.PathLike
) -> tuple[ExportResult, list[str]]:
    start = start_time_ns(metadata["started_at"])
    ends = _TickEnds(where)
    names: dict[int, str] | None = None
    log_schema: Any = None
    changes: list[StatusChange] = []
    messages = transitions = writes = events = 0
    last_seq = -1
    gap_free = True

    def flush() -> None:
        nonlocal messages, transitions
        sent = start + max(ends.end(changes[0].tick), changes[-1].t_ns)
        log = [
            {
                "timestamp": _stamp(start + change.t_ns),
                "node_name": names[change.uid] if names else "",
                "uid": change.uid,
                "previous_status": change.prev.name,
                "current_status": change.status.name,
            }
            for change in changes
        ]
        message = {"timestamp": _stamp(sent), "event_log": log}
        writer.write_message(LOG_TOPIC, log_schema, message, log_time=sent)
        messages += 1
        transitions += len(changes)
        changes.clear()

    stream = iter_messages(where)
    for topic, _time, data in stream:
        if topic == fmt.TREE_TOPIC and names is None:
            tree = tree_of(where, orjson.loads(data))
            too_big = [n.uid for n in tree if n.uid > _MAX_UID]
            if too_big:
                raise SourceError(f"{where}: uid {too_big[0]} does not fit the log's uint16")
            # BT.CPP's name(): the instance name, else the registration ID (what Nav2 logs)
            names = {node.uid: node.description for node in tree}
            xml_schema = writer.register_msgdef(XML_TYPE, XML_MSGDEF)
            log_schema = writer.register_msgdef(LOG_TYPE, LOG_MSGDEF)
            xml = {"data": tree_xml(tree).decode()}
            writer.write_message(XML_TOPIC, xml_schema, xml, log_time=start)
        elif topic == fmt.MUTATIONS_TOPIC:
            raise SourceError(f"{where}: the tree changed during the run; a Nav2 log has one tree")
        elif topic == fmt.EVENTS_TOPIC:
            if names is None:
                raise _NotStreamable
            for event in fmt.decode_events(data):
                if event.seq <= last_seq:
                    raise _NotStreamable
                gap_free = gap_free and event.seq == last_seq + 1
                last_seq, events = event.seq, events + 1
                if isinstance(event, StatusChange):
                    if changes and event.tick != changes[0].tick:
                        if event.tick < changes[0].tick:
                            raise _NotStreamable
                        flush()
                    changes.append(event)
                elif isinstance(event, BlackboardWrite):
                    writes += 1
    if names is None:
        raise _NotStreamable
    if changes:
        flush()
    writer.finish()
    warnings = stream.warnings
    if not gap_free:
        warnings.append(f"{where}: the events' seqs are not 0, 1, 2, … without gaps")
    if stream.truncated:
        last = f"up to seq {last_seq}" if events else "(none)"
        warnings.insert(0, f"{where}: truncated recording; read {events} events {last}")
    return ExportResult(Path(output), messages, transitions, writes), warnings

"""The recorder: a subscriber that appends a run's events to an MCAP file as they happen.

The cost that matters is per event, and an MCAP message costs microseconds while a Python
list append costs tens of nanoseconds. So the hot path only buffers. The recorder takes
status changes in batches (``Subscriber.on_status_batch``): each node appends its own
packed change (uid, prev, status: ``btlog.events.CHANGE``, looked up, not built) to the
executor's list, and the executor hands the list over with the batch's first ``seq``,
its tick and its time (or each change's time, when the clock is not simulated). So
nothing numbers, times or encodes a change one by one. The recorder keeps the changes
as they come and each batch as a segment ``(seq, tick, count, t_ns)``; ``on_status``,
for other callers, adds to the same. ``on_write`` builds one tuple. ``on_tick`` hands
the buffered rows, once about a thousand have gathered or they span about 100 ms of the
run's clock (``GROUP_NS``: a player showing a message at its log_time shows each event
within that of its time), to the recorder's own thread
(``btlog.record.background``), which encodes them as one ``/btlog/events`` message of
binary columns (``btlog.record.columns``: the seq, time and tick columns come from the
segments, the others from the packed changes) and does the MCAP writer's work — adding
messages, compressing and writing chunks — in the order it was asked for. Grouping
changes nothing for a reader: every row keeps its own ``seq``, ``t_ns`` and ``tick``.

Crash safety comes from flushing by wall time: a tick flushes (the MCAP writer's chunk is
closed and flushed to the file) when the *next* tick, expected as far away as the last
one was, would come after ``flush_interval`` seconds since the last flush. Chunks are the
unit a reader can recover from a cut file, so after ``kill -9`` at most the last interval
is lost, also when ticks are paced to the wall clock (a flush waits for the writer
thread: the data is in the file when it returns). Tick records are written together
with the events they end, in the same chunk, so a cut file never has events far ahead of
its ticks. ``close()`` writes the rest and the summary (the index that makes the file
seekable).

What the file holds and how each message is laid out is ``btlog.record.format``.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
import uuid
from collections.abc import Callable, Iterable, Mapping
from datetime import UTC, datetime, timedelta
from typing import Any

import orjson
from mcap.well_known import SchemaEncoding
from mcap.writer import CompressionType, Writer

import btlog
from btlog.events import Subscriber, TickRecord, TreeMutation, change_rows
from btlog.record import columns
from btlog.record import format as fmt
from btlog.record.background import BackgroundWriter, name_file
from btlog.schema import schema_text
from btlog.status import Status
from btlog.tree.model import Tree

#: Chunk compression of new recordings (see benchmarks/bench_recorder.py for the figures).
DEFAULT_COMPRESSION = CompressionType.ZSTD
#: Events gathered (over one or more ticks) before a ``/btlog/events`` message is written.
GROUP_EVENTS = 1024
#: The run time a ``/btlog/events`` message spans at most (when ticks are this far apart
#: or more, a message per tick): a player showing messages at their log_time shows each
#: event within this of its time.
GROUP_NS = 100_000_000
#: A suggested ``max_tick_events``: write a tick's events in parts past this many.
MAX_BUFFERED_EVENTS = 50_000
#: The MCAP chunk size: a chunk is also closed when it grows past this many bytes.
CHUNK_SIZE = 4 * 1024 * 1024
_NEVER = 1 << 62
XML_MEDIA_TYPE = "application/xml"

_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
_INT_MIN = -(2**63)
_INT_LIMIT = 2**64
#: Bytes a write row takes in a message, about: for the chunk size only.
_WRITE_BYTES = 64


def json_value(value: Any) -> Any:
    """``value`` if orjson can encode it, else its ``repr`` (never raises).

    Plain scalars pass at once; anything else is encoded now and kept as an
    ``orjson.Fragment``: the tick's message does not encode it again, and a container
    the node mutates later is recorded as it was when written.
    """
    kind = type(value)
    if kind is str or kind is bool or value is None:
        return value
    if kind is int:
        return value if _INT_MIN <= value < _INT_LIMIT else _safe_repr(value)
    if kind is float:
        return value if math.isfinite(value) else _safe_repr(value)
    try:
        return orjson.Fragment(orjson.dumps(value))
    except Exception:  # not JSON (TypeError), or a value whose own code fails
        return _safe_repr(value)


def _safe_repr(value: Any) -> str:
    try:
        return repr(value)
    except Exception:  # a broken __repr__ must not stop the run
        return f"<{type(value).__name__} object>"


def run_metadata(metadata: Mapping[str, Any]) -> dict[str, str]:
    """The ``btlog.run`` record: every value a string (JSON text for ``JSON_METADATA``
    keys given as objects), with the schema version, btlog's version, a run id and the
    start time filled in."""
    record = {
        "run_id": uuid.uuid4().hex,
        "started_at": datetime.now(UTC).isoformat(timespec="microseconds"),
        "btlog_version": btlog.__version__,
    }
    for key, value in metadata.items():
        record[str(key)] = _metadata_text(str(key), value)
    record["schema_version"] = btlog.SCHEMA_VERSION
    return record


def start_time_ns(started_at: str) -> int:
    """The ``started_at`` ISO-8601 time in nanoseconds since the epoch (now if unreadable)."""
    try:
        moment = datetime.fromisoformat(started_at)
    except ValueError:
        return time.time_ns()
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    return (moment - _EPOCH) // timedelta(microseconds=1) * 1000


def _metadata_text(key: str, value: Any) -> str:
    if key in fmt.JSON_METADATA and not isinstance(value, str):
        return orjson.dumps(value, default=repr).decode()
    if value is None:
        return ""
    return value if isinstance(value, str) else str(value)


class Recorder(Subscriber):
    """Records a run into the MCAP file ``path`` (see the module docstring).

    The file is created, and its head (header, schemas, channels, the ``btlog.run``
    metadata, the ``attachments`` — ``(name, bytes)`` of the tree's XML files — and the
    ``/btlog/tree`` message) written and flushed, at construction. Subscribe it to an
    executor; ``close()`` (or the executor's ``close()``, or leaving a ``with`` block)
    finishes the file and ends the recorder's writer thread (an error of the writer, such
    as a full disk, is raised by the next ``flush()`` or ``close()``). ``event_count`` and
    ``last_seq`` tell what has been handed to the writer so far; ``metadata`` is the
    ``btlog.run`` record as written.

    A tick's status changes are buffered until the tick ends. ``max_tick_events`` (e.g.
    ``MAX_BUFFERED_EVENTS``) bounds that buffer for trees that may loop many times within
    one tick: past it the events are written, and flushed when the interval has passed.
    It costs a length check per event (5–10 % of the recorder's time, measured), so it is
    off by default; blackboard writes are always bounded by ``MAX_BUFFERED_EVENTS``.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        tree: Tree,
        metadata: Mapping[str, Any],
        attachments: Iterable[tuple[str, bytes]] = (),
        flush_interval: float = 1.0,
        compression: CompressionType = DEFAULT_COMPRESSION,
        chunk_size: int = CHUNK_SIZE,
        max_tick_events: int | None = None,
        group_events: int = GROUP_EVENTS,
        group_ns: int = GROUP_NS,
    ) -> None:
        self.path = os.fspath(path)
        self.group_events = group_events
        self.group_ns = group_ns
        #: the start of the first tick whose events are buffered (None: none are), and
        #: the end of the last tick: the next tick is expected as far on
        self._group_start_ns: int | None = None
        self._last_end_ns = 0
        self.flush_interval = flush_interval
        self.max_tick_events = max_tick_events
        self.chunk_size = chunk_size
        self._chunk_bytes = 0
        self.metadata = run_metadata(metadata)
        #: the run's start on the wall clock: each message's MCAP log_time is this plus
        #: the run's clock (``t_ns``), so players show the run at its own pace
        self.start_ns = start_time_ns(self.metadata["started_at"])
        self.event_count = 0
        self.last_seq: int | None = None
        self._closed = False
        self._changes: list[bytes] = []  # packed (btlog.events.CHANGE)
        self._times: list[int] = []  # the times of changes in untimed segments
        self._segments: list = []  # seq, tick, count, t_ns (None: see _times), flat
        #: packed changes by uid, for ``on_status`` (``btlog.events.change_rows``)
        self._rows_by_uid: dict[int, tuple[tuple[bytes, ...], ...]] = {}
        self._write_rows: list[tuple] = []
        self._tick_rows: list[tuple] = []
        self._file = open(self.path, "wb")  # noqa: SIM115
        try:
            # Chunks end where the recorder decides (``_end_chunk_if_full``): never between
            # a tick's events and its tick record.
            self._writer = Writer(self._file, chunk_size=_NEVER, compression=compression)
            self._channels = self._start(tree, attachments)
        except BaseException as error:
            with contextlib.suppress(OSError):  # the error of the start says it
                self._file.close()
            raise name_file(error, self.path) from None
        #: the writer's calls from now on, run on the recorder's thread
        self._background = BackgroundWriter(self._writer, self.path)
        self._last_flush = self._last_tick_at = time.monotonic()
        if type(self).on_status is Recorder.on_status:  # a subclass's override wins
            self.on_status = self._status_appender()  # type: ignore[method-assign,assignment]

    def _start(self, tree: Tree, attachments: Iterable[tuple[str, bytes]]) -> dict[str, int]:
        writer = self._writer
        writer.start(profile="", library=f"btlog/{btlog.__version__}")
        channels = {}
        schemas: dict[tuple[str, str], int] = {}
        for topic, (schema_name, schema_file, encoding) in fmt.TOPICS.items():
            schema_encoding = (
                encoding if encoding == columns.ENCODING else SchemaEncoding.JSONSchema
            )
            key = (schema_name, schema_file)
            if key not in schemas:
                schemas[key] = writer.register_schema(
                    schema_name, schema_encoding, schema_text(schema_file)
                )
            channels[topic] = writer.register_channel(topic, encoding, schemas[key])
        writer.add_metadata(fmt.METADATA_NAME, self.metadata)
        now = time.time_ns()
        for name, data in attachments:
            writer.add_attachment(now, now, name, XML_MEDIA_TYPE, bytes(data))
        start = self.start_ns
        writer.add_message(channels[fmt.TREE_TOPIC], start, fmt.dumps(tree.describe()), now)
        writer.flush()
        return channels

    # -- the hot path -----------------------------------------------------------------
    def takes_status_batches(self) -> bool:
        """True unless the buffer is bounded (``max_tick_events``: each change must be
        counted as it comes) or a subclass overrides ``on_status``."""
        return self.max_tick_events is None and type(self).on_status is Recorder.on_status

    def on_status_batch(
        self, seq: int, tick: int, t_ns: int, changes: list[bytes], times: list[int] | None
    ) -> None:
        """Buffer a batch of status changes (see ``Subscriber.on_status_batch``)."""
        self._changes.extend(changes)
        if times is None:
            self._segments.extend((seq, tick, len(changes), t_ns))
        else:
            self._times.extend(times)
            self._segments.extend((seq, tick, len(changes), None))

    def on_status(
        self, seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
    ) -> None:
        """Buffer a status change, one call a change (an importer's way; replaced per
        instance by ``_status_appender``, the same without attribute look-ups)."""
        self._status_appender()(seq, t_ns, tick, uid, prev, status)

    def _status_appender(self) -> Callable[[int, int, int, int, Status, Status], None]:
        """``on_status`` as a closure over the buffers: the change is looked up (packed
        once per uid and pair of statuses), and the last segment grows when the change
        is the next seq of the same tick."""
        add_change, add_time = self._changes.append, self._times.append
        segments, rows_by_uid = self._segments, self._rows_by_uid
        limit, overflow, changes = self.max_tick_events, self._overflow, self._changes
        add_segment = columns.add_timed_change

        def on_status(
            seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
        ) -> None:
            try:
                rows = rows_by_uid[uid]
            except KeyError:
                rows = rows_by_uid[uid] = change_rows(uid)
            add_change(rows[prev][status])
            add_time(t_ns)
            add_segment(segments, seq, tick)
            if limit is not None and len(changes) > limit:
                overflow()

        on_status.__doc__ = Recorder.on_status.__doc__
        return on_status

    def on_write(
        self,
        seq: int,
        t_ns: int,
        tick: int,
        scope: str,
        key: str,
        value: Any,
        type_name: str,
        writer_uid: int | None,
    ) -> None:
        """Buffer a blackboard write (a value orjson cannot encode becomes its repr)."""
        rows = self._write_rows
        rows.append((seq, t_ns, tick, scope, key, json_value(value), type_name, writer_uid))
        if len(rows) > MAX_BUFFERED_EVENTS:
            self._overflow()

    def _overflow(self) -> None:
        """A long tick: write its events so far, and flush if the interval has passed."""
        if self._closed:  # events after close are dropped, not kept
            self._changes.clear()
            self._times.clear()
            self._segments.clear()
            self._write_rows.clear()
            return
        self._write_events()
        self._end_chunk_if_full()
        if time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()

    def on_tick(self, record: TickRecord) -> None:
        """Write the buffered events as one message once ``group_events`` have gathered
        (the MCAP writer costs ~10 µs a message, so small ticks are grouped) or once the
        next tick, expected as far on as this one, would end ``group_ns`` or more of run
        time after the first buffered tick began (so log_times follow the run's clock);
        flush when the interval has passed."""
        if self._closed:
            return
        tick, start_ns, end_ns, root_status, teardown = record
        row = (tick, start_ns, end_ns, root_status)
        if teardown:  # a message of its own, marked: the run's final halt
            self._write_events(tick)
            self._write_ticks()
            self._add_columns(
                fmt.TICKS_TOPIC,
                end_ns,
                columns.pack_ticks,
                ([row], True),
                columns.HEAD.size + columns.TICK_ROW_BYTES,
            )
            return
        self._tick_rows.append(row)
        buffered = len(self._changes) + len(self._write_rows)
        next_end, self._last_end_ns = 2 * end_ns - self._last_end_ns, end_ns
        if buffered and self._group_start_ns is None:
            self._group_start_ns = start_ns
        if buffered >= self.group_events or (
            buffered and next_end - self._group_start_ns >= self.group_ns  # type: ignore[operator]
        ):
            self._write_events(tick)
            self._write_ticks()
            self._end_chunk_if_full()
        now = time.monotonic()
        gap, self._last_tick_at = now - self._last_tick_at, now
        if now + gap - self._last_flush >= self.flush_interval:
            self.flush()

    # -- the rest ---------------------------------------------------------------------
    def on_mutation(self, mutation: TreeMutation) -> None:
        """Write the pending events, then the mutation (which has the next seq)."""
        if self._closed:
            return
        self._write_events()
        self._add(fmt.MUTATIONS_TOPIC, fmt.encode_mutation(mutation), mutation.t_ns)
        self.event_count += 1
        self.last_seq = mutation.seq

    def on_answer(
        self, seq: int, t_ns: int, tick: int, question: str, intent: str, answer: str
    ) -> None:
        """Record a question asked live and its answer (after the events it is about)."""
        if self._closed:
            return
        self._write_events()
        self._add(
            fmt.ANSWERS_TOPIC,
            {
                "seq": seq,
                "t_ns": t_ns,
                "tick": tick,
                "question": question,
                "intent": intent,
                "answer": answer,
            },
            t_ns,
        )

    def flush(self) -> None:
        """Write everything buffered and flush it to the file (closes the MCAP chunk);
        returns once it is in the file (the interval's promise; a chunk closed for its
        size is left to the writer thread)."""
        if self._closed:
            return
        self._write_events()
        self._write_ticks()
        self._background.flush()
        self._background.wait()
        self._chunk_bytes = 0
        self._last_flush = self._last_tick_at = time.monotonic()

    def on_close(self) -> None:
        """Write what is pending and finish the file (summary and footer)."""
        self.close()

    def close(self) -> None:
        """Finish the file; calling it again does nothing."""
        if self._closed:
            return
        try:
            self._write_events()
            self._write_ticks()
        finally:
            try:
                self._background.stop()  # the writer's finish, then the thread ends
            finally:
                self._closed = True
                try:
                    self._file.close()
                except OSError as error:
                    raise name_file(error, self.path) from None

    @property
    def writer_cpu_seconds(self) -> float | None:
        """The CPU time the recorder's own thread has used so far (None where the
        platform cannot tell, or once closed)."""
        return self._background.cpu_seconds

    @property
    def closed(self) -> bool:
        """True once the file is finished."""
        return self._closed

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- writing ----------------------------------------------------------------------
    def _end_chunk_if_full(self) -> None:
        """Close the MCAP chunk (and write it to the file) once it holds ``chunk_size``
        bytes of messages; called only where no tick is half written."""
        if self._chunk_bytes >= self.chunk_size:
            self._background.flush()
            self._chunk_bytes = 0

    def _write_events(self, tick: int | None = None) -> None:
        """One ``/btlog/events`` message with the buffered rows (``tick`` defaults to the
        last row's), encoded on the writer's thread."""
        changes, times, segments = self._changes, self._times, self._segments
        writes = self._write_rows
        if not changes and not writes:
            return
        if changes:  # the last change's seq, t_ns, tick
            first, last_tick, count, t_ns = segments[-4:]
            last = (first + count - 1, times[-1] if t_ns is None else t_ns, last_tick)
            if writes and writes[-1][0] > last[0]:
                last = writes[-1]
        else:
            last = writes[-1]
        rows = len(changes)
        self._add_columns(
            fmt.EVENTS_TOPIC,
            last[1],
            columns.pack_events,
            (
                last[2] if tick is None else tick,
                segments.copy(),
                changes.copy(),
                times.copy(),
                writes.copy(),
            ),
            columns.HEAD.size + rows * columns.EVENT_ROW_BYTES + len(writes) * _WRITE_BYTES,
        )
        self.event_count += rows + len(writes)
        self.last_seq = last[0]
        self._group_start_ns = None
        changes.clear()
        times.clear()
        segments.clear()
        writes.clear()

    def _write_ticks(self) -> None:
        rows = self._tick_rows
        if rows:
            size = columns.HEAD.size + len(rows) * columns.TICK_ROW_BYTES
            self._add_columns(fmt.TICKS_TOPIC, rows[-1][2], columns.pack_ticks, (rows,), size)
            self._tick_rows = []

    def _add_columns(
        self, topic: str, t_ns: int, encode: Callable[..., bytes], args: tuple, size: int
    ) -> None:
        """Queue a binary message, encoded by ``encode(*args)`` on the writer's thread
        (``size``: its bytes, about, for the chunk size)."""
        self._background.add_encoded(
            self._channels[topic], self.start_ns + t_ns, encode, args, time.time_ns()
        )
        self._chunk_bytes += size

    def _add(self, topic: str, message: dict, t_ns: int) -> None:
        """Write one JSON message whose log_time is the run's start plus ``t_ns``."""
        data = fmt.dumps(message)
        self._background.add_message(
            self._channels[topic], self.start_ns + t_ns, data, time.time_ns()
        )
        self._chunk_bytes += len(data)

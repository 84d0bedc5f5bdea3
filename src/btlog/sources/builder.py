"""Turn another tool's log of a run into an ordinary btlog recording.

Every importer (BT.CPP's FileLogger2 and SQLite logs, a live Groot2 connection, Nav2's
rosbags) hands the same three things to a ``RecordingBuilder``: the tree (loaded with
``accept_unknown=True``, so types btlog cannot run are kept with their kind), a stream
of status transitions with their times, and, when the source has them, blackboard
writes. The builder numbers the events (gap-free ``seq``), infers the ticks, and writes
the same topics a ``btlog run`` writes, through the same ``Recorder``; the metadata
``source`` says where the run came from (format, file, sha256 and the format's details).

Ticks are inferred, because BT.CPP's loggers record transitions, not ticks. The rule:

1. a new tick starts at the first transition, and at the first transition after the
   root returned to IDLE (BT.CPP resets a finished root at the end of its tick) or
   after the root completed (SUCCESS/FAILURE) when the source logs no reset;
2. a root that leaves IDLE starts a new tick, unless the tick began with the root IDLE
   and the root's change comes within ``tick_gap_ns`` (a root that sets its status
   after ticking its children, as Nav2's PipelineSequence does);
3. while the root stays RUNNING (it logs nothing then), a new tick starts at a new
   timestamp group: a transition more than ``tick_gap_ns`` (default 1 ms) after the
   previous one. Ticks in which nothing changed leave no trace and are not counted.

The tick's record runs from its first transition to its last; its root status is the
root's result in that tick (RUNNING while it runs). Blackboard writes belong to the
current tick (tick 0 before the first transition) and do not count for the gaps.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from btlog.events import (
    CHANGE,
    INSERT,
    Fanout,
    StatusBatch,
    Subscriber,
    TickRecord,
    TreeMutation,
    change_rows,
    type_name,
)
from btlog.record.recorder import Recorder
from btlog.sources.tick_gap import DEFAULT_TICK_GAP_NS
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from btlog.tree.model import Tree

#: The latest wall time a recording holds, in ns since the Unix epoch: its times are
#: signed 64-bit nanoseconds (2262-04-11), and an MCAP log time cannot precede 1970.
LATEST_NS = (1 << 63) - 1
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


class SourceError(ValueError):
    """Input that cannot be imported; ``str()`` is one line naming the file and value."""


@dataclass(frozen=True)
class Source:
    """Where an imported run came from (the recording's ``source`` metadata)."""

    format: str
    file: str
    sha256: str = ""
    details: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def of_file(
        cls,
        format: str,
        path: str | os.PathLike,
        files: Iterable[str | os.PathLike] | None = None,
        **details: Any,
    ) -> Source:
        """A source read from ``path``: a file, or a folder whose ``files`` (a bag's
        splits) are read in that order; the sha256 of their bytes is computed here."""
        digest = hashlib.sha256()
        for file in [path] if files is None else files:
            with open(file, "rb") as stream:
                for block in iter(lambda: stream.read(1 << 20), b""):
                    digest.update(block)
        return cls(format, os.fspath(path), digest.hexdigest(), details)

    def describe(self) -> dict[str, Any]:
        """The JSON-ready ``source`` metadata value; ``blackboard`` tells whether the
        source records blackboard values at all (False unless its details say so)."""
        head = {"format": self.format, "file": self.file, "sha256": self.sha256}
        return {**head, "blackboard": False, **self.details}


def state_at_first_entry(tree: Tree, first: Mapping[int, Status]) -> dict[int, Status]:
    """The state a log began in, as far as it tells (``first``: each node's previous
    status in its first entry): that status for each node the log names; RUNNING for
    every other ancestor of a node the log names (BT.CPP ticks a node only through its
    running ancestors, and a completed one has reset its children: an ancestor the log
    never names was RUNNING all along); IDLE for the rest."""
    state = {uid: status for uid, status in first.items() if status is not IDLE}
    for uid in list(first):
        node = tree.nodes[uid].parent
        while node is not None and node.uid not in state:
            if node.uid not in first:
                state[node.uid] = RUNNING
            node = node.parent
    return state


def never_named(tree: Tree, first: Mapping[int, Status], began: Mapping[int, Status]) -> str:
    """The nodes ``state_at_first_entry`` took as RUNNING though the log never names
    them, quoted and joined ('' when none)."""
    return ", ".join(repr(tree.nodes[uid].name) for uid in sorted(began) if uid not in first)


class OmittedCount:
    """Counts the changes (uid, previous status, status) that name a previous status
    their node's earlier changes did not leave it in: the changes
    ``RecordingBuilder.logged`` adds. From the state ``began``; or, without it, from
    the state ``state_at_first_entry`` gives (each node's first change starts from its
    own previous status, so it never counts), which lets a log be counted as it is read."""

    __slots__ = ("count", "inferred", "status")

    def __init__(self, began: Mapping[int, Status] | None = None) -> None:
        self.status: dict[int, Status] = dict(began or {})
        self.inferred = began is None
        self.count = 0

    def add(self, uid: int, prev: Status, new: Status) -> None:
        """Count one change."""
        last = self.status.get(uid)
        if last is None:
            last = prev if self.inferred else IDLE
        self.count += prev is not last
        self.status[uid] = new


def omitted_changes(
    changes: Iterable[tuple[int, Status, Status]], began: Mapping[int, Status]
) -> int:
    """How many of ``changes`` (uid, previous status, status), from the state ``began``,
    ``OmittedCount`` counts."""
    counter = OmittedCount(began)
    for uid, prev, new in changes:
        counter.add(uid, prev, new)
    return counter.count


@dataclass
class BuildResult:
    """What a builder wrote: the file, counts, the last root status and any warnings."""

    path: Path
    run_id: str
    transitions: int
    writes: int
    ticks: int
    final_status: Status
    warnings: list[str]


def wall_start(start_us: int, where: str, warnings: list[str]) -> datetime:
    """The start of a run a log gives in µs since the Unix epoch; when it is no time a
    recording can hold (before 1970, after 2262: a logger's clock never set, a damaged
    header), the epoch, with a warning naming ``where`` and the value."""
    if 0 <= start_us <= LATEST_NS // 1000:
        return _EPOCH + timedelta(microseconds=start_us)
    warnings.append(
        f"{where}: start time {start_us} µs since 1970 is not a time from 1970 to 2262; "
        "the run is recorded as starting at 1970-01-01T00:00:00Z (its times since the start "
        "are as logged)"
    )
    return _EPOCH


class RecordingBuilder:
    """Writes the MCAP recording ``output`` of ``tree`` from a stream of transitions.

    Call ``transition`` (and ``write``) in the source's order, with times in ns since
    the run's start; ``close`` finishes the file and returns a ``BuildResult``. The
    file is crash-safe as ``btlog run``'s (flushed at least every ``flush_interval``
    seconds of wall time, on tick boundaries or ``flush``). ``subscribers`` (e.g. a live
    ``StateProjection``) receive every event and tick after the recorder. Unknown uids and
    statuses, and times past 2262 (``LATEST_NS``), raise ``SourceError``; times going
    backwards are clamped, with a warning.
    """

    def __init__(
        self,
        output: str | os.PathLike,
        tree: Tree,
        source: Source,
        started_at: datetime | None = None,
        attachments: Iterable[tuple[str, bytes]] = (),
        metadata: Mapping[str, Any] | None = None,
        tick_gap_ns: int = DEFAULT_TICK_GAP_NS,
        flush_interval: float = 1.0,
        subscribers: Iterable[Subscriber] = (),
        explicit_ticks: bool = False,
    ) -> None:
        self.tree = tree
        #: the source says where ticks start (``start_tick``); none is inferred
        self.explicit_ticks = explicit_ticks
        self._tick_end: int | None = None
        #: the current tick's record is written (``end_tick``)
        self._ended = False
        self.source = source
        self.tick_gap_ns = tick_gap_ns
        self.warnings: list[str] = []
        self._status = {uid: IDLE for uid in tree.nodes}
        self._root = tree.root.uid
        self._seq = 0
        self._transitions = 0
        self._writes = 0
        self._tick = 0
        self._tick_start = 0
        self._tick_result: Status = IDLE
        self._boundary = True
        self._root_done = False
        self._last_t = 0
        self._last_transition_t = 0
        self._clamped = 0
        self._prev_mismatch = 0
        started = (started_at or datetime.now(UTC)).astimezone(UTC)
        record = {
            "started_at": started.isoformat(timespec="microseconds"),
            "tree_name": tree.name,
            "tree_file": "",
            "clock": "imported",
            "source": source.describe(),
            "tick_rule": "given" if explicit_ticks else f"inferred (gap {tick_gap_ns} ns)",
            **(metadata or {}),
        }
        self.recorder = Recorder(output, tree, record, attachments, flush_interval=flush_interval)
        #: the latest time since the start a recording of this start can hold
        self._latest_t = LATEST_NS - self.recorder.start_ns
        self._subscribers: list[Subscriber] = [self.recorder, *subscribers]
        #: transitions not yet numbered, while every subscriber takes them in batches
        #: (as the executor batches them: ``btlog.events.StatusBatch``)
        self._batch = self._batching()
        self._rows = {uid: change_rows(uid) for uid in tree.nodes}

    def _batching(self) -> StatusBatch | None:
        """A batch for the status changes when every subscriber takes batches."""
        subscribers = self._subscribers
        if not all(subscriber.takes_status_batches() for subscriber in subscribers):
            return None
        taker = subscribers[0] if len(subscribers) == 1 else Fanout(list(subscribers))
        return StatusBatch(taker, timed=True)

    def begin_mid_run(self, statuses: Mapping[int, Status]) -> int:
        """Before the first transition, for a log that begins mid-run: the state at its
        first entry (``state_at_first_entry``), as transitions from IDLE at time 0 in
        pre-order, in a tick of their own (the log's first entry starts the next one).
        Returns how many nodes were not IDLE."""
        if self._transitions:
            raise ValueError("begin_mid_run comes before the first transition")
        count = 0
        for node in self.tree:
            status = statuses.get(node.uid, IDLE)
            if status is not IDLE:
                self.transition(0, node.uid, status)
                count += 1
        if count:
            self._boundary = True
        return count

    def start_tick(self, t_ns: int) -> int:
        """A tick starts at ``t_ns`` (a source that knows its ticks: ``explicit_ticks``);
        the previous one ends. Returns the new tick's number."""
        t_ns = self._clamp(t_ns)
        self._last_t = t_ns
        self._next_tick(t_ns)
        return self._tick

    def end_tick(self, t_ns: int, root_status: Status | None = None) -> None:
        """The current tick ended at ``t_ns``, the root in ``root_status`` (when the
        source says: see ``packed``): its record is written now (events before the next
        tick still belong to it)."""
        if root_status is not None:
            self._tick_result = root_status
        self._tick_end = self._clamp(t_ns)
        self._last_t = self._tick_end
        if self._tick > 0 and not self._ended:
            self._end_tick()
            self._ended = True

    def logged(self, t_ns: int, uid: int, prev: Status, status: Status) -> None:
        """A change as a log states it, from ``prev``: when the node is not in ``prev``,
        the change the log left out (to ``prev``: a reset to IDLE a logger did not
        report) comes first, at the same time (``omitted_changes`` counts them)."""
        if uid in self._status and self._status[uid] is not prev:
            self.transition(t_ns, uid, prev)
        self.transition(t_ns, uid, status, prev)

    def flush_batch(self) -> None:
        """Number the batched status changes and hand them to the subscribers now."""
        self._settle()

    def subscribe(self, subscriber: Subscriber) -> None:
        """Deliver every later event and tick to ``subscriber`` too."""
        self._settle()
        self._subscribers.append(subscriber)
        self._batch = self._batching()

    def _settle(self) -> None:
        """Number the batched transitions and hand them to the recorder."""
        if self._batch is not None:
            self._seq += self._batch.hand_over(self._seq, self._tick, self._last_t)

    @property
    def tick(self) -> int:
        """The current (inferred) tick; 0 before the first transition."""
        return self._tick

    @property
    def last_t_ns(self) -> int:
        """The time of the last event so far."""
        return self._last_t

    @property
    def seq(self) -> int:
        """The number of events so far (the next event's seq)."""
        self._settle()
        return self._seq

    def status_of(self, uid: int) -> Status:
        """The node's status after the transitions so far."""
        return self._status[uid]

    def transition(self, t_ns: int, uid: int, status: Status, prev: Status | None = None) -> None:
        """Node ``uid`` changed to ``status`` at ``t_ns``; ``prev`` (when the source
        has it) is checked against the status this stream gave the node."""
        if uid not in self._status:
            raise SourceError(f"{self.source.file}: node uid {uid} is not in the tree")
        if t_ns < self._last_t or t_ns > self._latest_t:  # the common case costs no call
            t_ns = self._clamp(t_ns)
        old = self._status[uid]
        if prev is not None and prev != old:
            self._prev_mismatch += 1
        if self._starts_tick(uid, old, status, t_ns):
            self._next_tick(t_ns)
        self._status[uid] = status
        if uid == self._root:
            self._root_changed(status)
        batch = self._batch
        if batch is not None:
            batch.changes.append(self._rows[uid][old][status])
            batch.times.append(t_ns)  # type: ignore[union-attr]
        else:
            for subscriber in self._subscribers:
                subscriber.on_status(self._seq, t_ns, self._tick, uid, old, status)
            self._seq += 1
        self._transitions += 1
        self._last_t = self._last_transition_t = t_ns

    def packed(self, changes: list[bytes], t_ns: int) -> None:
        """Status changes the source packed itself (``btlog.events.CHANGE`` rows, from
        ``change_rows``: uid, previous and new status), in order, all at ``t_ns``: a
        source that knows its ticks (``explicit_ticks``) and watches every change, as
        py_trees' recorder does (a tick's changes take the tick's time). They are handed
        on as they are, as one batch the subscribers take untimed (the list is the
        source's: it may clear it afterwards); the builder does not follow them
        (``status_of`` and the tick's root status are then the source's: ``end_tick``)."""
        if not changes:
            return
        t_ns = self._clamp(t_ns)
        batch = self._batch
        if batch is not None:
            self._settle()
            batch.taker.on_status_batch(self._seq, self._tick, t_ns, changes, None)
            self._seq += len(changes)
        else:
            tick, status = self._tick, self._status
            for change in changes:
                uid, prev, new = CHANGE.unpack(change)
                status[uid] = Status(new)
                for subscriber in self._subscribers:
                    subscriber.on_status(self._seq, t_ns, tick, uid, Status(prev), Status(new))
                self._seq += 1
        self._transitions += len(changes)
        self._last_t = self._last_transition_t = t_ns

    def write(
        self,
        t_ns: int,
        scope: str,
        key: str,
        value: Any,
        writer_uid: int | None = None,
        type_label: str | None = None,
    ) -> None:
        """Entry ``key`` of ``scope`` was set to ``value`` at ``t_ns`` (in the current tick)."""
        t_ns = self._clamp(t_ns)
        label = type_label or type_name(value)
        self._settle()
        for subscriber in self._subscribers:
            subscriber.on_write(self._seq, t_ns, self._tick, scope, key, value, label, writer_uid)
        self._seq += 1
        self._writes += 1
        self._last_t = t_ns

    def mutate(
        self,
        t_ns: int,
        op: str,
        parent_uid: int,
        after_uid: int | None,
        nodes: list[dict],
        question: str = "",
    ) -> TreeMutation:
        """The tree changed at ``t_ns`` (a ``TreeMutation``: ``nodes`` inserted, or
        pruned); inserted nodes start IDLE."""
        t_ns = self._clamp(t_ns)
        self._settle()
        mutation = TreeMutation(
            self._seq, t_ns, self._tick, op, parent_uid, after_uid, list(nodes), question
        )
        if op == INSERT:
            for record in nodes:
                uid = record["uid"]
                self._status[uid] = IDLE
                self._rows[uid] = change_rows(uid)
        for subscriber in self._subscribers:
            subscriber.on_mutation(mutation)
        self._seq += 1
        self._last_t = t_ns
        return mutation

    def flush(self) -> None:
        """Write what is buffered to the file now."""
        self._settle()
        self.recorder.flush()

    def close(self) -> BuildResult:
        """Finish the file (the last tick's record included)."""
        if self._tick > 0 and not self._ended:
            self._end_tick()
        self._settle()
        if self._clamped:
            self.warnings.append(
                f"{self._clamped} transitions were stamped earlier than the one before them; "
                "their times were raised to keep the order"
            )
        if self._prev_mismatch:
            self.warnings.append(
                f"{self._prev_mismatch} transitions name a previous status that differs "
                "from the node's last logged status (transitions missing from the source?)"
            )
        self.recorder.close()
        return BuildResult(
            Path(self.recorder.path),
            self.recorder.metadata["run_id"],
            self._transitions,
            self._writes,
            self._tick,
            self._tick_result,
            self.warnings,
        )

    def __enter__(self) -> RecordingBuilder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        if not self.recorder.closed:
            self.close()

    # -- ticks -------------------------------------------------------------------------
    def _clamp(self, t_ns: int) -> int:
        if t_ns > self._latest_t:
            raise SourceError(
                f"{self.source.file}: an event {t_ns / 1e9:.6f} s after the start "
                f"(#{self._transitions + self._writes + 1}) lies past 2262, "
                "the latest time a recording holds"
            )
        if t_ns < self._last_t:
            self._clamped += 1
            return self._last_t
        return t_ns

    def _starts_tick(self, uid: int, old: Status, status: Status, t_ns: int) -> bool:
        """The module docstring's rule."""
        if self.explicit_ticks:
            return False
        if self._boundary:
            return True
        if uid == self._root:
            if old == IDLE:
                # a root that sets its status after ticking its children (Nav2's
                # PipelineSequence) leaves IDLE within the tick that began with it IDLE
                gap = t_ns - self._last_transition_t
                return not (self._tick_result == IDLE and gap <= self.tick_gap_ns)
            if status == IDLE:
                return False  # the reset of a finished root ends its tick
        if self._root_done:
            return True
        return t_ns - self._last_transition_t > self.tick_gap_ns

    def _next_tick(self, t_ns: int) -> None:
        self._settle()
        if self._tick > 0 and not self._ended:
            self._end_tick()
        self._ended = False
        self._tick += 1
        self._tick_start = t_ns
        self._boundary = False
        self._root_done = False
        self._tick_result = self._status[self._root]

    def _end_tick(self) -> None:
        self._settle()
        end = self._last_transition_t
        if self._tick_end is not None:
            end = max(end, self._tick_end, self._tick_start)
            self._tick_end = None
        record = TickRecord(self._tick, self._tick_start, end, self._tick_result)
        for subscriber in self._subscribers:
            subscriber.on_tick(record)

    def _root_changed(self, status: Status) -> None:
        if status == IDLE:
            self._boundary = True
        elif status in (SUCCESS, FAILURE):
            self._tick_result = status
            self._root_done = True
        elif status == RUNNING:
            self._tick_result = RUNNING

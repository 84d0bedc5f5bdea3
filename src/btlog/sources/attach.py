"""Record a running BT.CPP process live (``btlog attach``), through ``btlog.sources.groot2``.

btlog asks for the tree (``T``), starts the publisher's recording (``r start``), then
polls the transitions (``t``) every ``poll_interval`` seconds (a poll starts on time
however long the one before took to record, at once when it took longer) and, with
``blackboard``, the blackboards (``B``) every ``blackboard_interval``: each change of an
entry is recorded as a write (no writer: the protocol has none), stamped with the time
of the last transition before the poll that saw it. Times are the publisher's, µs since its
``r start``; btlog's own clock for the run (gaps, live questions) is a monotonic clock
started when the publisher answered ``r start``.

A robot's link is not always good, so nothing is lost without saying so:

- **Silence.** A request unanswered within ``timeout`` seconds (the process hung or
  died, the network dropped) makes btlog reconnect: a first try after
  ``FIRST_RETRY`` s, then twice as long after each failed try, at most ``LAST_RETRY`` s
  apart, for up to ``reconnect`` seconds (0: never; then, or when the time is up, the
  recording ends with a warning, keeping everything polled until then). When the same
  publisher answers again (same tree id), polling goes on where it was.
- **Restart.** When a new publisher answers (a new tree id: the process started again)
  with the same tree, its recording is started and its times follow on from the moment
  it answered; every node the old process left non-IDLE is reset to IDLE there, as the
  old tree is gone. A restart with another tree ends the recording.
- **Losses in replies.** A ``t`` reply of ``BUFFER_LIMIT`` transitions may follow
  dropped ones (BT.CPP keeps no more); a reply ending inside a 9-byte record lost the
  transition it cut; a reply of another shape (``groot2.BadReply``), or naming a node or
  status the tree does not have, lost what it held.

Each of these is a **gap** in the recording — a write of ``btlog.events.GAP_SCOPE``
saying "no data from A to B" and why — which ``btlog explain`` and the viewer show, and
which ``attach`` warns about when it ends. Blackboard replies of the wrong shape are
skipped and counted in a warning (the next poll reads the values again).
"""

from __future__ import annotations

import hashlib
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from btlog.events import GAP_SCOPE, Gap
from btlog.explain.words import seconds
from btlog.sources.btcpp_records import decode_records
from btlog.sources.btcpp_tree import tree_from_log_xml
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    RecordingBuilder,
    Source,
    SourceError,
    wall_start,
)
from btlog.sources.groot2 import BUFFER_LIMIT, BadReply, Groot2Client, Silent, Transitions
from btlog.status import IDLE
from btlog.tree.model import SUBTREE, Tree
from btlog.tree.registry import Registry

FORMAT = "groot2"
#: Seconds before the first try to reconnect, and the longest wait between two tries.
FIRST_RETRY = 0.1
LAST_RETRY = 2.0
#: Gaps warned about one by one when ``attach`` ends (the rest are counted).
GAPS_TOLD = 10


def blackboard_names(tree: Tree) -> dict[str, str]:
    """BT.CPP's blackboard name of each subtree instance → btlog's scope."""
    names = {tree.name: ""}
    for node in tree:
        if node.kind == SUBTREE and node.children:
            names[node.children[0].scope] = node.children[0].scope
    return names


class AttachHooks:
    """What a caller of ``attach`` may do along the way (override what you need)."""

    def on_start(self, builder: RecordingBuilder) -> None:
        """The tree is known and the file started; nothing recorded yet."""

    def on_poll(self, builder: RecordingBuilder, t_ns: int) -> None:
        """After each poll; ``t_ns`` is the run's time now (since the start)."""

    def before_close(self, builder: RecordingBuilder) -> None:
        """Once, after the last poll, before the file is finished."""

    def on_fault(self, builder: RecordingBuilder, message: str) -> None:
        """As it happens: the publisher fell silent (btlog reconnects), or a gap was
        marked; ``message`` is one line for the user."""


@dataclass
class AttachResult:
    """A finished attach: the build result, polls made, polls that may have lost data,
    whether the publisher was gone at the end, the gaps, reconnections and restarts."""

    build: BuildResult
    polls: int = 0
    full_polls: int = 0
    gone: bool = False
    gaps: list[Gap] = field(default_factory=list)
    reconnects: int = 0
    restarts: int = 0


@dataclass
class AttachOptions:
    """How to attach: duration (None: until stopped), poll interval, blackboard polling,
    the timeout of each request and how long to try to reconnect (0: never)."""

    duration: float | None = None
    poll_interval: float = 0.01
    blackboard: bool = False
    blackboard_interval: float = 0.1
    timeout: float = 3.0
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS
    flush_interval: float = 1.0
    reconnect: float = 30.0


def attach(
    endpoint: str,
    output: str | Path,
    options: AttachOptions | None = None,
    registry: Registry | None = None,
    hooks: AttachHooks | None = None,
    stop: threading.Event | None = None,
) -> AttachResult:
    """Record the publisher at ``endpoint`` into ``output`` until the duration has passed,
    ``stop`` is set or Ctrl-C; the file is finished cleanly in every case."""
    options = options or AttachOptions()
    hooks = hooks or AttachHooks()
    client = Groot2Client(endpoint, options.timeout)
    try:
        xml = client.tree_xml()
        tree = tree_from_log_xml(xml, f"{endpoint} (tree)", registry)
        start_us = client.start()
        warnings: list[str] = []
        started = wall_start(start_us, endpoint, warnings)
        source = Source(
            FORMAT,
            endpoint,
            hashlib.sha256(xml).hexdigest(),
            {"blackboard": options.blackboard, "poll_interval_s": options.poll_interval},
        )
        builder = RecordingBuilder(
            output,
            tree,
            source,
            started_at=started,
            attachments=[("btcpp-tree.xml", xml)],
            tick_gap_ns=options.tick_gap_ns,
            flush_interval=options.flush_interval,
        )
        builder.warnings.extend(warnings)
        attachment = _Attachment(client, builder, xml, options, hooks)
        try:
            hooks.on_start(builder)
            attachment.run(stop)
        finally:
            attachment.finish()
        return attachment.result
    finally:
        client.close()


class _Ended(Exception):
    """The attach is over (the publisher is gone, the time is up, or it was stopped)."""


class _Attachment:
    """One attach in progress: the polls, reconnections, gaps and the file."""

    def __init__(
        self,
        client: Groot2Client,
        builder: RecordingBuilder,
        xml: bytes,
        options: AttachOptions,
        hooks: AttachHooks,
    ) -> None:
        self.zero = time.monotonic_ns()  # the run's clock: the publisher answered r start
        self.client, self.builder, self.xml = client, builder, xml
        self.options, self.hooks = options, hooks
        self.result = AttachResult(BuildResult(Path(builder.recorder.path), "", 0, 0, 0, IDLE, []))
        self.tree_id = client.tree_id
        self.names = blackboard_names(builder.tree)
        self.entries: dict[tuple[str, str], Any] = {}
        self.offset_ns = 0  # the current publisher's time zero on the run's clock
        self.last_reply_ns = 0  # when the publisher last answered
        self.last_transition_ns = 0
        self.bad_blackboards: list[str] = []
        self.connected = True
        self.stop: threading.Event | None = None
        self.began = time.monotonic()

    def now_ns(self) -> int:
        """The run's time now."""
        return time.monotonic_ns() - self.zero

    # -- the loop ----------------------------------------------------------------------
    def run(self, stop: threading.Event | None) -> None:
        """Poll until the duration has passed, ``stop`` is set, Ctrl-C or the end."""
        self.stop = stop
        options = self.options
        next_blackboard = next_poll = self.began
        next_flush = self.began + options.flush_interval
        try:
            while True:
                # polls start every poll_interval, however long recording a reply takes
                # (a publisher keeps only BUFFER_LIMIT transitions between two polls)
                next_poll += options.poll_interval
                self._poll_transitions()
                now = time.monotonic()
                if options.blackboard and now >= next_blackboard:
                    self._poll_blackboard()
                    next_blackboard = now + options.blackboard_interval
                self.hooks.on_poll(self.builder, self.now_ns())
                if now >= next_flush:  # crash safety even while the tree is idle
                    self.builder.flush()
                    next_flush = now + options.flush_interval
                now = time.monotonic()
                next_poll = max(next_poll, now)  # late: poll at once, without a burst after
                if self._wait(next_poll - now):
                    return
        except (KeyboardInterrupt, _Ended):
            return

    def _wait(self, seconds_: float) -> bool:
        """Wait; True once the attach should end (duration over, or ``stop`` set)."""
        if self.options.duration is not None:
            left = self.began + self.options.duration - time.monotonic()
            if left <= 0:
                return True
            seconds_ = min(seconds_, left)
        if self.stop is not None:
            return self.stop.wait(seconds_)
        time.sleep(seconds_)
        return False

    def _answered(self) -> None:
        """The publisher answered: a request of the same publisher, in shape."""
        self.last_reply_ns = self.now_ns()

    # -- transitions -------------------------------------------------------------------
    def _poll_transitions(self) -> None:
        try:
            reply = self.client.transitions()
        except BadReply as error:
            self._gap(self.last_reply_ns, self.now_ns(), f"{_what(error)}: what it held is lost")
            return
        except Silent as error:
            self._reconnect(error)
            return
        if self.client.tree_id != self.tree_id:  # a new process answered, not recording
            self._reconnect(None)
            return
        self._answered()
        self.result.polls += 1
        self._record(reply)

    def _record(self, reply: Transitions) -> None:
        """The reply's transitions, and the gaps it shows."""
        before = self.last_transition_ns
        where = f"{self.client.endpoint}: a transitions reply"
        builder, offset = self.builder, self.offset_ns
        nodes, transition = builder.tree.nodes, builder.transition
        kept = 0
        try:
            for t_us, uid, status in decode_records(reply.records, where):
                t_ns = offset + t_us * 1000
                if kept == 0 and reply.full:
                    self.result.full_polls += 1
                    self._gap(before, t_ns, _FULL)
                if uid not in nodes:
                    raise SourceError(f"{where} names node uid {uid}, which the tree does not have")
                transition(t_ns, uid, status)
                kept += 1
        except SourceError as error:  # a record naming no node, or a status out of range
            if kept:
                self.last_transition_ns = builder.last_t_ns
            lost = len(reply) - kept
            why = f"{_what(error)}: the {lost} transitions from there on are lost"
            self._gap(self.last_transition_ns, self.now_ns(), why)
            return
        if kept:
            self.last_transition_ns = builder.last_t_ns
        if reply.cut:
            why = (
                f"a transitions reply ended inside a record ({reply.cut} of 9 bytes): "
                "the transition it cut is lost"
            )
            self._gap(self.last_transition_ns, self.now_ns(), why)

    # -- blackboards -------------------------------------------------------------------
    def _poll_blackboard(self) -> None:
        try:
            dump = self.client.blackboards(list(self.names))
        except BadReply as error:
            self.bad_blackboards.append(str(error))
            return
        except Silent as error:
            self._reconnect(error)
            return
        if self.client.tree_id != self.tree_id:
            self._reconnect(None)
            return
        self._answered()
        t_ns, builder, entries = self.builder.last_t_ns, self.builder, self.entries
        seen = set()
        for name, board in dump.items():
            scope = self.names.get(str(name), str(name))
            for key, value in board.items():
                seen.add((scope, str(key)))
                if entries.get((scope, str(key)), _MISSING) != value:
                    entries[(scope, str(key))] = value
                    builder.write(t_ns, scope, str(key), value)
        for scope, key in [k for k in entries if k not in seen]:
            del entries[(scope, key)]
            builder.write(t_ns, scope, key, None, type_label="unset")

    # -- faults ------------------------------------------------------------------------
    def _reconnect(self, error: SourceError | None) -> None:
        """Connect again (``error``: the silence; None: a new publisher answered); mark
        the gap. Raises ``_Ended`` when it gives up or the attach should end."""
        self.connected = False
        since = self.last_reply_ns
        if self.options.reconnect <= 0:
            self._give_up(f"{_what(error)} (reconnecting is off)")
        deadline = time.monotonic() + self.options.reconnect
        delay, tries = (FIRST_RETRY if error is not None else 0.0), 0
        if error is not None:
            what = f"{_what(error)}; reconnecting for up to {self.options.reconnect:g} s"
            self.hooks.on_fault(self.builder, what)
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self._give_up(f"{_what(error)}; no answer for {self.options.reconnect:g} s")
            if delay and self._wait(min(delay, left)):  # the attach ends meanwhile
                quiet = seconds(self.now_ns() - since)
                self.builder.warnings.append(
                    f"the publisher had not answered for {quiet} s when the attach ended; "
                    f"the recording ends at {seconds(since)} s"
                )
                raise _Ended
            tries += 1
            try:
                restarted = self._connect_again()
                break
            except (Silent, BadReply) as failed:
                error = error or failed
                delay = min(max(delay * 2, FIRST_RETRY), LAST_RETRY)
        now = self.now_ns()
        self.connected = True
        self.result.reconnects += error is not None
        if restarted:
            self._restarted(since, now)
        else:
            quiet = seconds(now - since)
            why = (
                f"the publisher did not answer for {quiet} s (reconnected after {tries} "
                f"{'try' if tries == 1 else 'tries'}): transitions of that time may be missing"
            )
            self._gap(since, now, why)
        self._answered()

    def _connect_again(self) -> bool:
        """One try: a fresh connection, the tree asked for; True when a new publisher
        (with the same tree) answered and its recording was started."""
        self.client.reset()
        xml = self.client.tree_xml()
        if self.client.tree_id == self.tree_id:
            return False
        if xml != self.xml:
            at = seconds(self.last_reply_ns)
            self._give_up(f"the publisher restarted with another tree after {at} s")
        self.client.start()
        return True

    def _restarted(self, since: int, now: int) -> None:
        """A new process answers from ``now``: the old tree's nodes reset, its times
        follow on from there."""
        self.tree_id = self.client.tree_id
        self.offset_ns = now
        self.result.restarts += 1
        builder = self.builder
        for uid in sorted(builder.tree.nodes, reverse=True):  # children before parents
            if builder.status_of(uid) != IDLE:
                builder.transition(now, uid, IDLE)
        why = (
            "the publisher restarted (BT.CPP's process began again): what its tree did "
            "meanwhile is not recorded; its nodes were reset to IDLE"
        )
        self._gap(since, now, why)
        self.last_transition_ns = builder.last_t_ns

    def _give_up(self, why: str) -> None:
        self.result.gone = True
        self.builder.warnings.append(
            f"the publisher stopped answering: {why}; the recording ends at "
            f"{seconds(self.last_reply_ns)} s"
        )
        raise _Ended

    def _gap(self, from_ns: int, to_ns: int, why: str) -> None:
        """Mark the gap (one write; a gap that goes on where the last one began and for
        the same reason extends it)."""
        gaps = self.result.gaps
        from_ns = max(0, min(from_ns, to_ns))
        gap = Gap(from_ns, max(from_ns, to_ns), why)
        if gaps and (gaps[-1].from_ns, gaps[-1].why) == (gap.from_ns, gap.why):
            gaps[-1] = gap
        else:
            gaps.append(gap)
        self.builder.write(gap.to_ns, GAP_SCOPE, f"gap {len(gaps)}", gap.to_json())
        span = f"{seconds(gap.from_ns)} s to {seconds(gap.to_ns)} s"
        self.hooks.on_fault(self.builder, f"no data from {span}: {gap.why}")

    # -- the end -----------------------------------------------------------------------
    def finish(self) -> None:
        """Take the last transitions, stop the publisher's recording, finish the file."""
        builder = self.builder
        if self.connected and not self.result.gone:
            try:
                reply = self.client.transitions()
                if self.client.tree_id == self.tree_id:
                    self._record(reply)
                self.client.stop()
            except SourceError as error:  # the process went away: keep what was recorded
                builder.warnings.append(f"the publisher stopped answering: {_what(error)}")
        self.hooks.before_close(builder)
        builder.warnings.extend(self._summary())
        self.result.build = builder.close()

    def _summary(self) -> list[str]:
        """The warnings that tell what may be lost."""
        told = []
        result = self.result
        for gap in result.gaps[:GAPS_TOLD]:
            span = f"{seconds(gap.from_ns)} s to {seconds(gap.to_ns)} s"
            told.append(f"no data from {span}: {gap.why}")
        if len(result.gaps) > GAPS_TOLD:
            told.append(f"{len(result.gaps) - GAPS_TOLD} more gaps (each marked in the recording)")
        if result.full_polls:
            told.append(
                f"{result.full_polls} of {result.polls} polls returned BT.CPP's limit of "
                f"{BUFFER_LIMIT} transitions: older transitions may be lost (poll faster)"
            )
        if self.bad_blackboards:
            told.append(
                f"{len(self.bad_blackboards)} blackboard replies skipped, the first: "
                f"{self.bad_blackboards[0]}"
            )
        return told


_MISSING = object()
_FULL = (
    f"BT.CPP's buffer of {BUFFER_LIMIT} transitions was full: the transitions before these "
    "were dropped"
)


def _what(error: BaseException | None) -> str:
    """An error's message without the endpoint that starts it (the warnings name it)."""
    text = str(error) if error is not None else "a new publisher answered"
    head, _sep, rest = text.partition(": ")
    return rest if head.startswith("tcp://") and rest else text

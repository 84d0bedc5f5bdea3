"""Record a running BT.CPP process live through the Groot2 protocol (``btlog attach``).

Any ``Groot2Publisher`` (and Nav2 with ``enable_groot_monitoring``) answers ZMQ REQ/REP
requests on its port (``include/behaviortree_cpp/loggers/groot2_protocol.h``). Every
request is a multipart message whose first part is a 6-byte header: protocol u8 (2),
request type u8 (an ASCII letter), a u32 id (little-endian). The reply starts with the
same 6 bytes plus a 16-byte tree id; an error reply is ``["error", message]``.

- ``T``: the tree XML (as the FileLogger2 embeds it);
- ``r`` + ``"start"``: the publisher starts recording transitions; the reply is the wall
  time in µs; ``r`` + ``"stop"`` stops it;
- ``t``: the recorded transitions since the last ``t``, as 9-byte records (u48 µs since
  the start, u16 uid, u8 status). The publisher keeps at most 1,000: a reply of 1,000
  may have lost older ones, which is reported;
- ``B`` + ``"name;name"``: the blackboards of those subtrees (the main tree by its ID,
  the others by their path), msgpack of ``{name: {key: value}}``; with ``--blackboard``
  btlog polls them and records each change as a write (no writer: the protocol has none),
  stamped with the time of the last transition before the poll that saw it.

A publisher that stops answering after the attach (the process ended) ends the
recording with a warning; the file keeps everything polled until then.
"""

from __future__ import annotations

import hashlib
import random
import struct
import threading
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from btlog.sources.btcpp_records import decode_records
from btlog.sources.btcpp_tree import tree_from_log_xml
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    RecordingBuilder,
    Source,
    SourceError,
)
from btlog.status import Status
from btlog.tree.model import SUBTREE, Tree
from btlog.tree.registry import Registry

FORMAT = "groot2"
PROTOCOL = 2
BUFFER_LIMIT = 1000


class Groot2Client:
    """A REQ connection to a Groot2 publisher; every call fails within ``timeout`` s."""

    def __init__(self, endpoint: str, timeout: float = 3.0) -> None:
        import zmq

        if not endpoint.startswith("tcp://") or ":" not in endpoint[6:]:
            raise SourceError(f"{endpoint}: expected tcp://HOST:PORT")
        self.endpoint = endpoint
        self.timeout = timeout
        self._context = zmq.Context()
        self._socket = self._connect()
        self._waiting = False

    def _connect(self) -> Any:
        import zmq

        sock = self._context.socket(zmq.REQ)
        millis = int(self.timeout * 1000)
        sock.setsockopt(zmq.RCVTIMEO, millis)
        sock.setsockopt(zmq.SNDTIMEO, millis)
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(self.endpoint)
        return sock

    def request(self, kind: str, payload: bytes | None = None) -> bytes:
        """Send one request; the reply's payload (``SourceError`` on silence or error)."""
        import zmq

        unique = random.getrandbits(32)
        header = struct.pack("<BBI", PROTOCOL, ord(kind), unique)
        parts = [header] if payload is None else [header, payload]
        if self._waiting:  # a request interrupted (Ctrl-C) before its reply: start afresh
            self._socket.close(0)
            self._socket = self._connect()
        try:
            self._waiting = True
            self._socket.send_multipart(parts)
            reply = self._socket.recv_multipart()
            self._waiting = False
        except zmq.Again:
            raise SourceError(
                f"{self.endpoint}: no Groot2 publisher answered within {self.timeout:g} s"
            ) from None
        except zmq.ZMQError as error:
            raise SourceError(f"{self.endpoint}: {error}") from None
        if reply and reply[0] == b"error":
            message = reply[1].decode(errors="replace") if len(reply) > 1 else ""
            raise SourceError(f"{self.endpoint}: the publisher refused {kind!r}: {message}")
        if len(reply[0]) != 22 or reply[0][1:2] != kind.encode() or reply[0][2:6] != header[2:]:
            raise SourceError(f"{self.endpoint}: a reply that is not Groot2's to {kind!r}")
        return reply[1] if len(reply) > 1 else b""

    def tree_xml(self) -> bytes:
        """The tree as the publisher wrote it."""
        return self.request("T")

    def start(self) -> int:
        """Start recording transitions; the publisher's wall time in µs."""
        reply = self.request("r", b"start")
        try:
            return int(reply.decode())
        except ValueError:
            raise SourceError(f"{self.endpoint}: start time {reply[:40]!r}") from None

    def stop(self) -> None:
        """Stop recording transitions."""
        self.request("r", b"stop")

    def transitions(self) -> list[tuple[int, int, Status]]:
        """The transitions recorded since the last call: (µs since start, uid, status)."""
        return list(decode_records(self.request("t"), self.endpoint))

    def blackboards(self, names: list[str]) -> dict[str, dict[str, Any]]:
        """The entries of these blackboards (``{name: {key: value}}``)."""
        import msgpack

        data = self.request("B", ";".join(names).encode())
        decoded = msgpack.unpackb(data, raw=False, strict_map_key=False) if data else {}
        return decoded if isinstance(decoded, dict) else {}

    def close(self) -> None:
        """Close the connection."""
        self._socket.close(0)
        self._context.term()


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
        """After each poll; ``t_ns`` is the publisher's time since the start."""

    def before_close(self, builder: RecordingBuilder) -> None:
        """Once, after the last poll, before the file is finished."""


@dataclass
class AttachResult:
    """A finished attach: the build result, polls made and polls that may have lost data."""

    build: BuildResult
    polls: int = 0
    full_polls: int = 0
    gone: bool = False


@dataclass
class AttachOptions:
    """How to attach: duration (None: until stopped), poll interval, blackboard polling."""

    duration: float | None = None
    poll_interval: float = 0.01
    blackboard: bool = False
    blackboard_interval: float = 0.1
    timeout: float = 3.0
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS
    flush_interval: float = 1.0


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
            started_at=datetime.fromtimestamp(start_us / 1e6, UTC),
            attachments=[("btcpp-tree.xml", xml)],
            tick_gap_ns=options.tick_gap_ns,
            flush_interval=options.flush_interval,
        )
        result = AttachResult(BuildResult(Path(output), "", 0, 0, 0, Status.IDLE, []))
        try:
            hooks.on_start(builder)
            _poll_until_done(client, builder, tree, start_us, options, result, hooks, stop)
        finally:
            result.build = _finish(client, builder, result, hooks)
        return result
    finally:
        client.close()


def _poll_until_done(
    client: Groot2Client,
    builder: RecordingBuilder,
    tree: Tree,
    start_us: int,
    options: AttachOptions,
    result: AttachResult,
    hooks: AttachHooks,
    stop: threading.Event | None,
) -> None:
    began = time.monotonic()
    names = blackboard_names(tree)
    entries: dict[tuple[str, str], Any] = {}
    next_blackboard = began
    next_flush = began + options.flush_interval
    try:
        while True:
            try:
                _poll_transitions(client, builder, result)
            except SourceError as error:
                builder.warnings.append(f"the publisher stopped answering: {error}")
                result.gone = True
                return
            now = time.monotonic()
            t_ns = max(0, (time.time_ns() // 1000 - start_us) * 1000)
            if options.blackboard and now >= next_blackboard:
                _poll_blackboard(client, builder, names, entries, builder.last_t_ns)
                next_blackboard = now + options.blackboard_interval
            hooks.on_poll(builder, t_ns)
            if now >= next_flush:  # crash safety even while the tree is idle
                builder.flush()
                next_flush = now + options.flush_interval
            if options.duration is not None and now - began >= options.duration:
                return
            if stop is not None and stop.wait(options.poll_interval):
                return
            if stop is None:
                time.sleep(options.poll_interval)
    except KeyboardInterrupt:
        return


def _poll_transitions(
    client: Groot2Client, builder: RecordingBuilder, result: AttachResult
) -> None:
    batch = client.transitions()
    result.polls += 1
    if len(batch) >= BUFFER_LIMIT:
        result.full_polls += 1
    for t_us, uid, status in batch:
        builder.transition(t_us * 1000, uid, status)


def _poll_blackboard(
    client: Groot2Client,
    builder: RecordingBuilder,
    names: dict[str, str],
    entries: dict[tuple[str, str], Any],
    t_ns: int,
) -> None:
    dump = client.blackboards(list(names))
    seen = set()
    for name, board in dump.items():
        scope = names.get(name, name)
        for key, value in (board or {}).items():
            seen.add((scope, key))
            if entries.get((scope, key), _MISSING) != value:
                entries[(scope, key)] = value
                builder.write(t_ns, scope, str(key), value)
    for scope, key in [k for k in entries if k not in seen]:
        del entries[(scope, key)]
        builder.write(t_ns, scope, key, None, type_label="unset")


_MISSING = object()


def _finish(
    client: Groot2Client,
    builder: RecordingBuilder,
    result: AttachResult,
    hooks: AttachHooks,
) -> BuildResult:
    """Take the last transitions, stop the publisher's recording, finish the file."""
    try:
        if not result.gone:
            _poll_transitions(client, builder, result)
            client.stop()
    except SourceError as error:  # the process went away: keep what was recorded
        builder.warnings.append(f"the publisher stopped answering: {error}")
    hooks.before_close(builder)
    if result.full_polls:
        builder.warnings.append(
            f"{result.full_polls} of {result.polls} polls returned BT.CPP's limit of "
            f"{BUFFER_LIMIT} transitions: older transitions may be lost (poll faster)"
        )
    return builder.close()

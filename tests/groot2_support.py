"""A fake Groot2 publisher for the tests: BT.CPP's protocol on a ZMQ REP socket, with faults.

It answers as ``src/loggers/groot2_publisher.cpp`` does (``T``, ``r start``/``stop``,
``t``, ``B``; a random 16-byte tree id per start; at most 1,000 transitions kept, the
oldest dropped) and, on demand, falls silent (stops serving: requests wait in its queue,
as with a hung process), restarts (a new socket, tree id and clock, recording off, as a
process started again) or sends a crafted reply instead of the next one of a kind. The
test plays the robot: ``transition`` logs a status change at the publisher's clock.
"""

from __future__ import annotations

import os
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import msgpack
import zmq

BUFFER_LIMIT = 1000
#: A crafted reply: given the reply header (22 bytes), the parts to send.
Crafted = Callable[[bytes], list[bytes]]


def free_port() -> int:
    """A TCP port nobody listens on now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class FakePublisher:
    """A Groot2 publisher of ``xml`` on ``endpoint``, served from a thread; use in ``with``."""

    def __init__(self, xml: bytes, blackboard: dict[str, Any] | None = None) -> None:
        self.xml = xml
        self.blackboard = blackboard if blackboard is not None else {}
        self.port = free_port()
        self.endpoint = f"tcp://127.0.0.1:{self.port}"
        self.start_reply: bytes | None = None  # what "r start" answers (None: the time)
        self.crafted: dict[str, deque[Crafted]] = {}
        self.served: dict[str, int] = {}
        #: every transition logged: (recording number, µs since that start, uid, status);
        #: number 0 is before the first ``r start`` (not recorded)
        self.published: list[tuple[int, int, int, int]] = []
        self.starts = 0
        self._lock = threading.Lock()
        self._buffer: deque[tuple[int, int, int]] = deque()
        self._recording = False
        self._zero = time.monotonic_ns()
        self._silent = threading.Event()
        self._restart = threading.Event()
        self._quit = threading.Event()
        self._context = zmq.Context()
        self.tree_id = os.urandom(16)
        self._thread = threading.Thread(target=self._serve, daemon=True)

    def __enter__(self) -> FakePublisher:
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._quit.set()
        self._thread.join(timeout=10)
        self._context.term()

    # -- the robot -----------------------------------------------------------------------
    def now_us(self) -> int:
        """The publisher's clock: µs since its recording started."""
        return (time.monotonic_ns() - self._zero) // 1000

    def transition(self, uid: int, status: int) -> None:
        """A node changed status now (kept while recording, as BT.CPP keeps it)."""
        with self._lock:
            entry = (self.now_us(), uid, status)
            self.published.append((self.starts if self._recording else 0, *entry))
            if self._recording:
                self._buffer.append(entry)
                while len(self._buffer) > BUFFER_LIMIT:
                    self._buffer.popleft()

    # -- faults ----------------------------------------------------------------------------
    def fall_silent(self) -> None:
        """Stop serving (requests wait, as in a hung process) until ``resume``."""
        self._silent.set()

    def resume(self) -> None:
        """Serve again."""
        self._silent.clear()

    def restart(self, xml: bytes | None = None) -> None:
        """Start again: a new socket on the same port, a new tree id, recording off."""
        with self._lock:
            self.xml = xml if xml is not None else self.xml
            self.tree_id = os.urandom(16)
            self._recording = False
            self._buffer.clear()
        self._restart.set()
        deadline = time.monotonic() + 15
        while self._restart.is_set():
            assert self._thread.is_alive() and time.monotonic() < deadline, "never restarted"
            time.sleep(0.005)

    def craft(self, kind: str, *replies: Crafted) -> None:
        """Send these instead of the next replies to requests of ``kind``."""
        with self._lock:
            self.crafted.setdefault(kind, deque()).extend(replies)

    # -- serving ---------------------------------------------------------------------------
    def _bind(self) -> Any:
        sock = self._context.socket(zmq.REP)
        sock.setsockopt(zmq.LINGER, 0)
        deadline = time.monotonic() + 10
        while True:  # a socket just closed may hold the port for a moment
            try:
                sock.bind(self.endpoint)
                return sock
            except zmq.ZMQError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.01)

    def _serve(self) -> None:
        sock = self._bind()
        try:
            while not self._quit.is_set():
                if self._restart.is_set():
                    sock.close(0)
                    sock = self._bind()
                    self._restart.clear()
                if self._silent.is_set() or not sock.poll(20):
                    time.sleep(0.005)
                    continue
                request = sock.recv_multipart()
                sock.send_multipart(self._reply(request))
        finally:
            sock.close(0)

    def _reply(self, request: list[bytes]) -> list[bytes]:
        head = request[0]
        if len(head) != 6:
            return [b"error", b"wrong request header"]
        kind = chr(head[1])
        header = struct.pack("<B", 2) + head[1:6] + self.tree_id
        with self._lock:
            self.served[kind] = self.served.get(kind, 0) + 1
            crafted = self.crafted.get(kind)
            if crafted:
                return crafted.popleft()(header)
            if kind == "T":
                return [header, self.xml]
            if kind == "r":
                return self._toggle(header, request[1] if len(request) > 1 else b"")
            if kind == "t":
                records = b"".join(
                    t.to_bytes(6, "little") + u.to_bytes(2, "little") + bytes([s])
                    for t, u, s in self._buffer
                )
                self._buffer.clear()
                return [header, records]
            if kind == "B":
                return [header, msgpack.packb(self.blackboard)]
        return [b"error", b"Request not recognized"]

    def _toggle(self, header: bytes, command: bytes) -> list[bytes]:
        if command == b"start":
            self._zero = time.monotonic_ns()
            self._buffer.clear()
            self._recording = True
            self.starts += 1
            now = self.start_reply or str(time.time_ns() // 1000).encode()
            return [header, now]
        self._recording = False
        return [header]

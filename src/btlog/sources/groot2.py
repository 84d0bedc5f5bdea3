"""The Groot2 protocol, as a client: what ``btlog attach`` asks a BT.CPP process.

Any ``Groot2Publisher`` (and Nav2 with ``enable_groot_monitoring``) answers ZMQ REQ/REP
requests on its port (``include/behaviortree_cpp/loggers/groot2_protocol.h``). Every
request is a multipart message whose first part is a 6-byte header: protocol u8 (2),
request type u8 (an ASCII letter), a u32 id (little-endian). The reply starts with the
same 6 bytes plus a 16-byte tree id, which a publisher draws at random when it starts (a
new id: the process restarted); an error reply is ``["error", message]``.

- ``T``: the tree XML (as the FileLogger2 embeds it);
- ``r`` + ``"start"``: the publisher starts recording transitions; the reply is the wall
  time in µs; ``r`` + ``"stop"`` stops it (a reply of the header alone);
- ``t``: the recorded transitions since the last ``t``, as 9-byte records (u48 µs since
  the start, u16 uid, u8 status). The publisher keeps at most ``BUFFER_LIMIT``;
- ``B`` + ``"name;name"``: the blackboards of those subtrees (the main tree by its ID,
  the others by their path), msgpack of ``{name: {key: value}}``.

Every reply is checked against this shape: a reply of another shape raises ``BadReply``,
no reply within the timeout (or a connection error) raises ``Silent``; both name the
endpoint. ``Groot2Client.reset`` starts a fresh connection (a REQ socket whose request
went unanswered cannot be used again).
"""

from __future__ import annotations

import random
import re
import socket
import struct
from dataclasses import dataclass
from typing import Any

from btlog.sources.btcpp_records import RECORD_SIZE
from btlog.sources.builder import SourceError

PROTOCOL = 2
#: The transitions a publisher keeps between two ``t`` requests (older ones are dropped).
BUFFER_LIMIT = 1000
HEADER_SIZE = 6
REPLY_HEADER_SIZE = 22
_ENDPOINT = re.compile(r"tcp://(?P<host>\[[0-9A-Fa-f:.]+\]|[^\[\]:/\s]+):(?P<port>\d{1,5})")


class Silent(SourceError):
    """The publisher did not answer within the timeout, or the connection failed."""


class BadReply(SourceError):
    """A reply that is not the Groot2 protocol's answer to the request."""


def parse_endpoint(endpoint: str) -> tuple[str, int]:
    """(host, port) of ``tcp://HOST:PORT``, the host resolved (``SourceError`` if not)."""
    match = _ENDPOINT.fullmatch(endpoint)
    if match is None:
        raise SourceError(f"{endpoint}: expected tcp://HOST:PORT (PORT 1-65535)")
    host, port = match["host"], int(match["port"])
    if not 1 <= port <= 65535:
        raise SourceError(f"{endpoint}: port {port} is not 1-65535")
    try:
        socket.getaddrinfo(host.strip("[]"), port, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as error:
        reason = error.strerror if isinstance(error, socket.gaierror) else str(error)
        raise SourceError(f"{endpoint}: the host {host} does not resolve ({reason})") from None
    return host, port


@dataclass(frozen=True)
class Transitions:
    """A ``t`` reply: its whole records, and the bytes of a record it ends inside."""

    records: bytes
    cut: int

    def __len__(self) -> int:
        return len(self.records) // RECORD_SIZE

    @property
    def full(self) -> bool:
        """True when it holds as many as the publisher keeps: older ones may be lost."""
        return len(self) >= BUFFER_LIMIT


def check_reply(
    endpoint: str, kind: str, header: bytes, reply: list[bytes], parts: tuple[int, ...] = (2,)
) -> tuple[bytes, bytes]:
    """(tree id, payload) of a reply to the request ``kind`` sent with ``header``, in one
    of ``parts`` parts; ``BadReply`` naming the endpoint unless it has that shape."""
    if reply and reply[0] == b"error":
        message = reply[1].decode(errors="replace") if len(reply) > 1 else ""
        raise BadReply(f"{endpoint}: the publisher refused {kind!r}: {message[:200]}")
    head = reply[0] if reply else b""
    if len(head) != REPLY_HEADER_SIZE or head[1:HEADER_SIZE] != header[1:]:
        raise BadReply(f"{endpoint}: a reply to {kind!r} that is not Groot2's ({head[:8]!r})")
    if len(reply) not in parts:
        expected = " or ".join(map(str, parts))
        raise BadReply(f"{endpoint}: a reply to {kind!r} in {len(reply)} parts, not {expected}")
    return head[HEADER_SIZE:], reply[1] if len(reply) > 1 else b""


def decode_transitions(payload: bytes) -> Transitions:
    """A ``t`` reply's payload: whole records, and how many bytes of a last one it has."""
    cut = len(payload) % RECORD_SIZE
    return Transitions(payload[: len(payload) - cut], cut)


def decode_blackboards(endpoint: str, payload: bytes) -> dict[str, dict[str, Any]]:
    """A ``B`` reply's payload as ``{name: {key: value}}`` (``BadReply`` if it is not)."""
    import msgpack

    if not payload:
        return {}
    try:
        decoded = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as error:  # msgpack's own errors, any of them, on untrusted bytes
        what = type(error).__name__
        raise BadReply(f"{endpoint}: a blackboard reply that is not msgpack ({what})") from None
    if not isinstance(decoded, dict):
        raise BadReply(
            f"{endpoint}: a blackboard reply of {type(decoded).__name__}, not a map of boards"
        )
    for name, board in decoded.items():
        if not isinstance(board, dict):
            raise BadReply(
                f"{endpoint}: blackboard {str(name)[:60]!r} is {type(board).__name__}, "
                "not a map of entries"
            )
    return decoded


class Groot2Client:
    """A REQ connection to a Groot2 publisher; every call fails within ``timeout`` s.
    ``tree_id`` is the id of the publisher that gave the last reply."""

    def __init__(self, endpoint: str, timeout: float = 3.0) -> None:
        import zmq

        self.endpoint = endpoint
        self.host, self.port = parse_endpoint(endpoint)
        self.timeout = timeout
        self.tree_id: bytes | None = None
        self._context = zmq.Context()
        self._socket = self._connect()
        self._waiting = False

    def _connect(self) -> Any:
        import zmq

        sock = self._context.socket(zmq.REQ)
        millis = max(1, int(self.timeout * 1000))
        sock.setsockopt(zmq.RCVTIMEO, millis)
        sock.setsockopt(zmq.SNDTIMEO, millis)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.IPV6, int(self.host.startswith("[")))
        try:
            sock.connect(self.endpoint)
        except zmq.ZMQError as error:
            sock.close(0)
            raise SourceError(f"{self.endpoint}: {error}") from None
        return sock

    def reset(self) -> None:
        """A fresh connection (after a request that went unanswered)."""
        self._socket.close(0)
        self._socket = self._connect()
        self._waiting = False

    def request(self, kind: str, payload: bytes | None = None) -> bytes:
        """Send one request; the reply's payload (``Silent``, ``BadReply``)."""
        import zmq

        header = struct.pack("<BBI", PROTOCOL, ord(kind), random.getrandbits(32))
        parts = [header] if payload is None else [header, payload]
        if self._waiting:  # a request interrupted (Ctrl-C, a timeout) before its reply
            self.reset()
        try:
            self._waiting = True
            self._socket.send_multipart(parts)
            reply = self._socket.recv_multipart()
            self._waiting = False
        except zmq.Again:
            raise Silent(
                f"{self.endpoint}: no Groot2 publisher answered within {self.timeout:g} s"
            ) from None
        except zmq.ZMQError as error:
            raise Silent(f"{self.endpoint}: {error}") from None
        shapes = (1, 2) if payload == b"stop" else (2,)  # "stop": the header alone
        tree_id, body = check_reply(self.endpoint, kind, header, reply, shapes)
        self.tree_id = tree_id
        return body

    def tree_xml(self) -> bytes:
        """The tree as the publisher wrote it."""
        xml = self.request("T")
        if not xml:
            raise BadReply(f"{self.endpoint}: an empty tree")
        return xml

    def start(self) -> int:
        """Start recording transitions; the publisher's wall time in µs."""
        reply = self.request("r", b"start")
        text = reply.decode(errors="replace").strip()
        if not re.fullmatch(r"-?\d{1,30}", text):
            raise BadReply(f"{self.endpoint}: start time {reply[:40]!r} is not a number")
        return int(text)

    def stop(self) -> None:
        """Stop recording transitions."""
        self.request("r", b"stop")

    def transitions(self) -> Transitions:
        """The transitions recorded since the last call."""
        return decode_transitions(self.request("t"))

    def blackboards(self, names: list[str]) -> dict[str, dict[str, Any]]:
        """The entries of these blackboards (``{name: {key: value}}``)."""
        return decode_blackboards(self.endpoint, self.request("B", ";".join(names).encode()))

    def close(self) -> None:
        """Close the connection."""
        self._socket.close(0)
        self._context.term()

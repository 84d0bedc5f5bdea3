"""``btlog view``'s web server: the page and its JSON, on 127.0.0.1 only, read-only.

Standard library only: GET requests for the page, its static files and the JSON of
``btlog.view.model``, answered by ``http.server``'s request handler. Queries share one
DuckDB connection, so they are serialised by a lock. Requests whose ``Host`` is not the
loopback address are refused (a web page elsewhere cannot reach the viewer through DNS
rebinding); nothing the page asks can change a recording or its cache.

Connections cannot exhaust it (``ViewerServer``): one thread accepts them and reads each
request's head without blocking — at most ``HEAD_LIMIT`` bytes within ``REQUEST_TIMEOUT``
seconds, else the connection is closed — and only a complete request goes to a pool of
``WORKERS`` threads. At most ``MAX_PENDING`` connections wait for their head (past it the
oldest is closed, so idle or half-sent connections never stop the viewer answering) and
as many complete requests for a worker (past it a request is closed unanswered). A
client that goes away mid-answer is forgotten quietly; nothing of the standard library
is printed.
"""

from __future__ import annotations

import contextlib
import io
import json
import selectors
import socket
import sys
import threading
import time
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from btlog.errors import one_line
from btlog.replay.moments import Resolved
from btlog.view.model import RunView, question_patterns, standard_questions
from btlog.view.page import STATIC_FILES, page_html

HOST = "127.0.0.1"
_TYPES = {".js": "text/javascript", ".css": "text/css"}
#: Threads answering complete requests (queries are serialised anyway).
WORKERS = 4
#: Seconds a connection has to send its request's head; and to take each part of an answer.
REQUEST_TIMEOUT = 10.0
#: The longest request head read (a GET has no body).
HEAD_LIMIT = 64 * 1024
#: Connections waiting for their head at once; past it the oldest is closed.
MAX_PENDING = 1024


class ViewerApp:
    """The runs being viewed and the answers to the page's requests."""

    def __init__(self, views: list[RunView], diff: dict[str, Any] | None = None) -> None:
        self.views = views
        self.diff = diff
        self.lock = threading.Lock()

    def runs_json(self) -> dict[str, Any]:
        """Every run's meta, the divergence of two runs, and the question patterns."""
        return {
            "runs": [view.meta() for view in self.views],
            "diff": self.diff,
            "patterns": question_patterns(),
            "questions": standard_questions(),
        }

    def api(self, path: str, query: dict[str, str]) -> Any:
        """Answer ``/api/...``; raises KeyError for unknown paths, ValueError for bad values."""
        parts = path.strip("/").split("/")
        if parts == ["api", "runs"]:
            with self.lock:  # every query of the one connection, this one too
                return self.runs_json()
        if len(parts) != 4 or parts[:2] != ["api", "run"]:
            raise KeyError(path)
        view = self.views[int(parts[2])]
        what = parts[3]
        with self.lock:
            if what == "gantt":
                hi = query.get("hi")
                return view.gantt(int(query.get("lo", "0")), None if hi is None else int(hi))
            moment = self._moment(view, query)
            if what == "resolve":
                return moment.to_json()
            if what == "state":
                return view.state(moment)
            if what == "step":
                return view.step_tick(moment, int(query.get("dir", "1"))).to_json()
            if what == "ask":
                return view.ask(moment, query.get("q", ""))
        raise KeyError(path)

    @staticmethod
    def _moment(view: RunView, query: dict[str, str]) -> Resolved:
        """The moment a request names: ``at`` (any ``--at`` form), ``t_ns`` or ``count``."""
        if "at" in query:
            return view.resolve(query["at"])
        if "t_ns" in query:
            return view.at_time(int(query["t_ns"]))
        return view.at_count(int(query.get("count", "0")))


def make_handler(app: ViewerApp) -> type[BaseHTTPRequestHandler]:
    """A request handler class bound to ``app``."""

    class Handler(BaseHTTPRequestHandler):
        """GET only: the page, static files, JSON. Its request is ``(socket, head)``:
        the head was read by ``ViewerServer``."""

        server_version = "btlog-view"

        def setup(self) -> None:
            """Read the request from its head; answer on the socket."""
            self.connection, head = self.request
            self.rfile = io.BytesIO(head)
            self.wfile = self.connection.makefile("wb", buffering=0)

        def finish(self) -> None:
            """Close the answer's stream (the server closes the socket)."""
            self.wfile.close()

        def log_message(self, format: str, *args: Any) -> None:
            """Quiet: the terminal shows the URL, not every request."""

        def do_GET(self) -> None:
            """Serve one request."""
            host = (self.headers.get("Host") or "").rsplit(":", 1)[0]
            if host not in (HOST, "localhost"):
                self._send(HTTPStatus.FORBIDDEN, b"loopback only", "text/plain")
                return
            url = urlsplit(self.path)
            if url.path in ("/", "/index.html"):
                self._send(HTTPStatus.OK, page_html().encode(), "text/html; charset=utf-8")
                return
            if url.path.startswith("/static/"):
                self._static(url.path.removeprefix("/static/"))
                return
            query = {k: v[-1] for k, v in parse_qs(url.query).items()}
            try:
                data = app.api(url.path, query)
            except (KeyError, IndexError):
                self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain")
                return
            except ValueError as error:
                body = json.dumps({"error": str(error)}).encode()
                self._send(HTTPStatus.BAD_REQUEST, body, "application/json")
                return
            except Exception as error:  # a bug: one line, and the page is told
                where = f"btlog view: internal error on {url.path}"
                print(f"{where}: {one_line(error)}", file=sys.stderr)
                self._send(HTTPStatus.INTERNAL_SERVER_ERROR, b"internal error", "text/plain")
                return
            body = json.dumps(data, default=repr, separators=(",", ":")).encode()
            self._send(HTTPStatus.OK, body, "application/json")

        def _static(self, name: str) -> None:
            if name not in STATIC_FILES:
                self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain")
                return
            data = resources.files("btlog.view").joinpath("static", name).read_bytes()
            kind = _TYPES.get(name[name.rfind(".") :], "application/octet-stream")
            self._send(HTTPStatus.OK, data, kind + "; charset=utf-8")

        def _send(self, status: HTTPStatus, body: bytes, kind: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.send_header(
                "Content-Security-Policy",
                "default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'",
            )
            self.end_headers()
            self.wfile.write(body)

    return Handler


class _Pending:
    """A connection whose request head is still coming."""

    __slots__ = ("address", "deadline", "head")

    def __init__(self, address: Any, deadline: float) -> None:
        self.address, self.deadline, self.head = address, deadline, bytearray()


class ViewerServer:
    """Serves ``handler`` on 127.0.0.1 (see the module docstring): ``serve_forever`` in one
    thread, ``shutdown`` from another, then ``server_close``."""

    def __init__(
        self,
        handler: type[BaseHTTPRequestHandler],
        port: int = 0,
        workers: int = WORKERS,
        timeout: float = REQUEST_TIMEOUT,
        max_pending: int = MAX_PENDING,
    ) -> None:
        self.handler, self.timeout, self.max_pending = handler, timeout, max_pending
        self.socket = socket.create_server((HOST, port), backlog=128)
        self.socket.setblocking(False)
        self.server_address = self.socket.getsockname()
        self.pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="btlog-view")
        self.pending: OrderedDict[socket.socket, _Pending] = OrderedDict()
        self._stop = threading.Event()
        self._stopped = threading.Event()
        #: complete requests handed to the pool and not yet answered
        self.queued = 0
        self._count = threading.Lock()

    def serve_forever(self) -> None:
        """Accept connections and read their heads until ``shutdown``."""
        self._stopped.clear()
        with selectors.DefaultSelector() as selector:
            selector.register(self.socket, selectors.EVENT_READ)
            try:
                while not self._stop.is_set():
                    for key, _events in selector.select(timeout=0.2):
                        if key.fileobj is self.socket:
                            self._accept(selector)
                        else:
                            self._read(selector, key.fileobj)  # type: ignore[arg-type]
                    self._expire(selector)
            finally:
                for connection in list(self.pending):
                    self._drop(selector, connection)
                self._stopped.set()

    def _accept(self, selector: selectors.BaseSelector) -> None:
        for _ in range(64):  # what is waiting now, a batch at a time
            try:
                connection, address = self.socket.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # out of descriptors, a reset before accept: try a bit later
                time.sleep(0.05)
                return
            if len(self.pending) >= self.max_pending:
                oldest = next(iter(self.pending))
                self._drop(selector, oldest)
            connection.setblocking(False)
            self.pending[connection] = _Pending(address, time.monotonic() + self.timeout)
            selector.register(connection, selectors.EVENT_READ)

    def _read(self, selector: selectors.BaseSelector, connection: socket.socket) -> None:
        pending = self.pending.get(connection)
        if pending is None:
            return
        try:
            data = connection.recv(HEAD_LIMIT)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(selector, connection)
            return
        pending.head += data
        end = pending.head.find(b"\r\n\r\n")
        if end < 0 and len(pending.head) <= HEAD_LIMIT:
            return
        selector.unregister(connection)
        del self.pending[connection]
        if end < 0 or self.queued >= self.max_pending:  # a head past the limit; a flood
            connection.close()
            return
        with self._count:
            self.queued += 1
        self.pool.submit(self._answer, connection, pending.address, bytes(pending.head[: end + 4]))

    def _expire(self, selector: selectors.BaseSelector) -> None:
        now = time.monotonic()
        for connection, pending in list(self.pending.items()):
            if pending.deadline > now:
                break  # in order of arrival: the rest are younger
            self._drop(selector, connection)

    def _drop(self, selector: selectors.BaseSelector, connection: socket.socket) -> None:
        self.pending.pop(connection, None)
        with contextlib.suppress(KeyError, ValueError):
            selector.unregister(connection)
        connection.close()

    def _answer(self, connection: socket.socket, address: Any, head: bytes) -> None:
        """In a worker: answer one complete request; a client gone is forgotten."""
        try:
            connection.setblocking(True)
            connection.settimeout(self.timeout)
            self.handler((connection, head), address, self)  # type: ignore[arg-type]
        except OSError:  # the client went away or stopped reading: nothing to tell
            pass
        except Exception as error:
            print(f"btlog view: internal error: {one_line(error)}", file=sys.stderr)
        finally:
            connection.close()
            with self._count:
                self.queued -= 1

    def shutdown(self) -> None:
        """Stop ``serve_forever`` (from another thread) and wait until it has."""
        self._stop.set()
        self._stopped.wait(5)

    def server_close(self) -> None:
        """Close the listening socket and let the workers finish."""
        self.socket.close()
        self.pool.shutdown(wait=False, cancel_futures=True)


def serve(app: ViewerApp, port: int = 0, **limits: Any) -> ViewerServer:
    """A server for ``app`` on 127.0.0.1 (port 0: a free port); call ``serve_forever``.
    ``limits``: ``workers``, ``timeout``, ``max_pending`` (``ViewerServer``)."""
    return ViewerServer(make_handler(app), port, **limits)

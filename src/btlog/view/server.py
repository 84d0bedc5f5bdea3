"""``btlog view``'s web server: the page and its JSON, on 127.0.0.1 only, read-only.

Standard library only (``http.server`` on a ``ThreadingHTTPServer``): GET requests for
the page, its static files and the JSON of ``btlog.view.model``. Queries share one DuckDB
connection, so they are serialised by a lock. Requests whose ``Host`` is not the loopback
address are refused (a web page elsewhere cannot reach the viewer through DNS
rebinding); nothing the page asks can change a recording or its cache.
"""

from __future__ import annotations

import json
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from btlog.replay.moments import Resolved
from btlog.view.model import RunView, question_patterns, standard_questions
from btlog.view.page import STATIC_FILES, page_html

HOST = "127.0.0.1"
_TYPES = {".js": "text/javascript", ".css": "text/css"}


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
        """GET only: the page, static files, JSON."""

        server_version = "btlog-view"

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


def serve(app: ViewerApp, port: int = 0) -> ThreadingHTTPServer:
    """A server for ``app`` on 127.0.0.1 (port 0: a free port); call ``serve_forever``."""
    server = ThreadingHTTPServer((HOST, port), make_handler(app))
    server.daemon_threads = True
    return server

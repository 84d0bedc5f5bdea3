"""The viewer's server under hostile connections: 200 half-sent requests held open, clients
that vanish mid-answer, connections past every limit. It keeps answering a normal request
promptly, with a bounded number of threads, and prints nothing on stderr."""

from __future__ import annotations

import socket
import struct
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from btlog.replay.database import open_runs
from btlog.view.model import RunView
from btlog.view.server import WORKERS, ViewerApp, ViewerServer, serve
from tests.view_support import CHUCK, copy_recording

HALF_REQUEST = b"GET /api/runs HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: "  # never finished


@pytest.fixture(scope="module")
def app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ViewerApp]:
    database = open_runs(copy_recording(CHUCK, tmp_path_factory.mktemp("server")))
    yield ViewerApp([RunView(database, database.run(), "chuck")])
    database.close()


def running(app: ViewerApp, **limits: float) -> tuple[ViewerServer, threading.Thread, str]:
    server = serve(app, **limits)  # type: ignore[arg-type]
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    return server, thread, f"http://127.0.0.1:{server.server_address[1]}"


def stopped(server: ViewerServer, thread: threading.Thread) -> None:
    server.shutdown()
    server.server_close()
    thread.join(timeout=10)


def timed_get(url: str, timeout: float = 10) -> tuple[float, bytes]:
    began = time.monotonic()
    with urllib.request.urlopen(url, timeout=timeout) as answer:
        body = answer.read()
    return time.monotonic() - began, body


def half_requests(port: int, count: int) -> list[socket.socket]:
    held = []
    for _ in range(count):
        client = socket.create_connection(("127.0.0.1", port), timeout=5)
        client.sendall(HALF_REQUEST)
        held.append(client)
    return held


def test_200_half_sent_requests_leave_the_viewer_answering_promptly(app, capfd) -> None:
    server, thread, url = running(app)
    threads_before = threading.active_count()
    try:
        alone, body = timed_get(f"{url}/api/runs")
        held = half_requests(server.server_address[1], 200)
        time.sleep(0.3)  # every one accepted and read
        assert len(server.pending) == 200
        loaded, again = timed_get(f"{url}/api/runs")
        page, _html = timed_get(f"{url}/")
        assert again == body
        assert loaded < max(2.0, 10 * alone), (alone, loaded)
        assert page < 2.0
        assert threading.active_count() <= threads_before + WORKERS
        for client in held:
            client.close()
    finally:
        stopped(server, thread)
    print(f"alone {alone * 1000:.1f} ms, beside 200 half-requests {loaded * 1000:.1f} ms")
    assert capfd.readouterr().err == ""


def test_half_sent_requests_are_closed_after_the_timeout(app) -> None:
    server, thread, url = running(app, timeout=0.5)
    try:
        (client,) = half_requests(server.server_address[1], 1)
        began = time.monotonic()
        client.settimeout(5)
        assert client.recv(100) == b"", "closed without an answer"
        assert 0.4 < time.monotonic() - began < 2.5
        assert timed_get(f"{url}/api/runs")[1]
    finally:
        stopped(server, thread)


def test_past_the_limit_the_oldest_waiting_connection_makes_room(app) -> None:
    server, thread, url = running(app, max_pending=50)
    try:
        held = half_requests(server.server_address[1], 120)
        time.sleep(0.3)
        assert len(server.pending) <= 50
        took, _body = timed_get(f"{url}/api/runs")
        assert took < 2.0
        for client in held:
            client.close()
    finally:
        stopped(server, thread)


def test_clients_that_vanish_mid_answer_are_forgotten_quietly(app, capfd) -> None:
    server, thread, url = running(app)
    port = server.server_address[1]
    try:
        for _ in range(60):  # ask for the largest answer, then reset the connection
            client = socket.create_connection(("127.0.0.1", port), timeout=5)
            client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)
            client.sendall(b"GET /api/runs HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            client.close()
        for _ in range(20):  # and connections closed before a byte
            socket.create_connection(("127.0.0.1", port), timeout=5).close()
        time.sleep(0.5)
        assert timed_get(f"{url}/api/runs")[1]
        deadline = time.monotonic() + 5
        while server.queued:  # the last worker closes the socket, then counts down
            assert time.monotonic() < deadline, "a request never finished"
            time.sleep(0.01)
    finally:
        stopped(server, thread)
    assert capfd.readouterr().err == ""


def test_a_head_past_the_limit_is_closed_and_nothing_is_printed(app, capfd) -> None:
    server, thread, url = running(app)
    try:
        client = socket.create_connection(("127.0.0.1", server.server_address[1]), timeout=5)
        try:
            client.sendall(b"GET /" + b"a" * 70_000)
            assert client.recv(100) == b""
        except ConnectionResetError:
            pass  # closed while we were still sending: as good
        client.close()
        assert timed_get(f"{url}/")[1]
    finally:
        stopped(server, thread)
    assert capfd.readouterr().err == ""


def test_the_cli_viewer_stays_quiet_under_the_same_load(tmp_path: Path) -> None:
    from tests.view_support import Served

    served = Served(copy_recording(CHUCK, tmp_path))
    try:
        port = int(served.url.rstrip("/").rsplit(":", 1)[1])
        held = half_requests(port, 200)
        took, _body = timed_get(f"{served.url}api/runs")
        assert took < 2.0
        for client in held[:100]:
            client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            client.close()
        assert timed_get(f"{served.url}api/runs")[1]
    finally:
        served.process.terminate()
        _out, errors = served.process.communicate(timeout=10)
    assert "Traceback" not in errors and "Error" not in errors, errors

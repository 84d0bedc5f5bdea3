"""``btlog attach`` against a real BT.CPP process serving its tree with ``Groot2Publisher``.

The process (the oracle, in a subprocess) waits until btlog is attached, runs a random
tree with scripted leaves, and logs every transition with ``StdCoutLogger``; what btlog
recorded through the Groot2 protocol must be that stream, transition for transition.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from btlog.events import StatusChange
from btlog.record.reader import open_recording
from btlog.sources.attach import AttachHooks, AttachOptions, AttachResult, attach
from btlog.sources.builder import RecordingBuilder
from tests.cli_support import ROOT, assert_bad_input, btlog
from tests.oracle.random_trees import generate
from tests.oracle.runner import have_behaviortreepy, run_oracle, tick_boundaries

pytestmark = pytest.mark.skipif(not have_behaviortreepy(), reason="behaviortreepy missing")


def _free_port_pair() -> int:
    """A port P with P and P+1 free (the publisher binds both)."""
    for _ in range(50):
        with socket.socket() as first:
            first.bind(("127.0.0.1", 0))
            port = first.getsockname()[1]
            with socket.socket() as second:
                try:
                    second.bind(("127.0.0.1", port + 1))
                except OSError:
                    continue
        return port
    raise RuntimeError("no free port pair")


class _OracleDied(Exception):
    """BT.CPP's process ended (crashed, or hung and was killed) before the handshake."""


def _wait_for(path: Path, oracle: Future[Any], timeout: float = 70) -> None:
    """Wait until the oracle creates ``path``; raise ``_OracleDied`` if it ends first.

    The oracle's own timeout (60 s) bounds the wait when BT.CPP hangs.
    """
    deadline = time.monotonic() + timeout
    while not path.exists():
        if oracle.done():
            raise _OracleDied(f"BT.CPP ended before {path.name}: {oracle.result()!r:.300}")
        assert time.monotonic() < deadline, f"{path.name} never appeared"
        time.sleep(0.005)


ATTEMPTS = 3


def _with_btcpp_retries(tmp_path: Path, attempt: Callable[[Path], None]) -> None:
    """Run ``attempt`` in a fresh folder, again when BT.CPP's process died under it.

    The Groot2 publisher runs in a BT.CPP thread beside the ticking one; on a rare
    schedule (twice in CI, never in 45 runs here, under load too) the process hung, or
    its publisher stopped answering for more than 3 s while the tree ran on. Such a run
    says nothing about btlog, so it is retried; any other failure is not, and three
    deaths in a row fail the test.
    """
    deaths = []
    for number in range(ATTEMPTS):
        folder = tmp_path / f"attempt{number}"
        folder.mkdir()
        try:
            attempt(folder)
            return
        except _OracleDied as died:
            deaths.append(str(died))
    pytest.fail(f"BT.CPP's process died in all {ATTEMPTS} attempts: {deaths}")


class _Polled(AttachHooks):
    def __init__(self) -> None:
        self.event = threading.Event()

    def on_poll(self, builder: RecordingBuilder, t_ns: int) -> None:
        self.event.set()


def _raise_if_publisher_fell_silent(stderr: str) -> None:
    """``_OracleDied`` when ``btlog attach`` reported BT.CPP's publisher falling silent."""
    if "stopped answering" in stderr or "reconnecting for up to" in stderr:
        raise _OracleDied(f"BT.CPP's Groot2 publisher stopped answering: {stderr.strip()}")


def _attach_to_btcpp(
    folder: Path, payload: dict[str, Any], options: AttachOptions
) -> tuple[AttachResult, dict[str, Any], Path]:
    """Serve ``payload`` from BT.CPP, attach, run it to the end; (ours, theirs, recording)."""
    port = _free_port_pair()
    sync = folder / "sync"
    sync.mkdir()
    payload = {**payload, "groot2_port": port, "sync_dir": str(sync)}
    out = folder / "live.mcap"
    stop, polled = threading.Event(), _Polled()
    with ThreadPoolExecutor(max_workers=2) as pool:
        oracle = pool.submit(run_oracle, payload, 60)
        try:
            _wait_for(sync / "ready", oracle)
            attached = pool.submit(
                attach, f"tcp://127.0.0.1:{port}", out, options, hooks=polled, stop=stop
            )
            assert polled.event.wait(10), "attach never polled"
            (sync / "go").touch()
            _wait_for(sync / "ran", oracle)
            stop.set()
            # BT.CPP keeps serving until told to quit: attach's last poll must come first
            # (quitting at once made that poll time out under load: a false "silent").
            result = attached.result(timeout=20)
        finally:
            stop.set()
            (sync / "quit").touch()
        theirs = oracle.result(timeout=30)
    if theirs is None:
        raise _OracleDied("BT.CPP's process ended without a result")
    if result.gone or result.reconnects:  # seen in CI: BT.CPP's publisher fell silent
        raise _OracleDied(f"BT.CPP's Groot2 publisher stopped answering: {result.build.warnings}")
    return result, theirs, out


@pytest.mark.parametrize("seed", [7001, 7002, 7003])
def test_attach_records_btcpp_transition_for_transition(tmp_path: Path, seed: int) -> None:
    payload = {**dataclasses.asdict(generate(seed)), "tick_sleep_ms": 8}
    options = AttachOptions(poll_interval=0.005, tick_gap_ns=3_000_000)

    def attempt(folder: Path) -> None:
        result, theirs, out = _attach_to_btcpp(folder, payload, options)
        assert not theirs["error"], theirs
        assert result.full_polls == 0 and not result.build.warnings
        recording = open_recording(out)
        names = {n.uid: n.name for n in recording.tree}
        ours = [
            [e.tick, names[e.uid], e.prev.name, e.status.name]
            for e in recording.events
            if isinstance(e, StatusChange)
        ]
        assert [r[1:] for r in ours] == [t[1:] for t in theirs["transitions"]]
        assert tick_boundaries(theirs["transitions"]) <= tick_boundaries(ours)  # every tick
        assert recording.metadata["source"]["format"] == "groot2"

    _with_btcpp_retries(tmp_path, attempt)


def test_attach_to_a_port_nobody_serves_fails_within_5_s(tmp_path: Path) -> None:
    began = time.monotonic()
    result = btlog("attach", f"tcp://127.0.0.1:{_free_port_pair()}", "-o", str(tmp_path / "x.mcap"))
    assert time.monotonic() - began < 5 + 10  # the 5 s timeout, plus starting Python
    assert_bad_input(result, "no Groot2 publisher answered")
    assert not (tmp_path / "x.mcap").exists()
    assert_bad_input(btlog("attach", "localhost:1667", "-o", "x.mcap"), "tcp://HOST:PORT")


ATTACH_COMMAND = [sys.executable, "-m", "btlog.cli.main", "attach"]
ATTACH_ENV = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NO_COLOR": "1"}


def _interruptible() -> None:
    """In the child before ``exec``: SIGINT's default action, whatever the test's own."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_attach_cli_answers_live_and_records_blackboard_changes(tmp_path: Path) -> None:
    def attempt(folder: Path) -> None:
        port = _free_port_pair()
        sync = folder / "sync"
        sync.mkdir()
        payload = {**dataclasses.asdict(generate(7001)), "groot2_port": port}
        payload |= {"sync_dir": str(sync), "tick_sleep_ms": 30}
        out = folder / "live.mcap"
        command = [*ATTACH_COMMAND, f"tcp://127.0.0.1:{port}", "-o", str(out), "--blackboard"]
        command += ["--ask", "tick:1=What are you doing?"]
        proc: subprocess.Popen[Any] | None = None
        with ThreadPoolExecutor(max_workers=1) as pool:
            oracle = pool.submit(run_oracle, payload, 60)
            try:
                _wait_for(sync / "ready", oracle)
                proc = subprocess.Popen(
                    command,
                    env=ATTACH_ENV,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    text=True,
                    # a shell without job control starts background jobs with SIGINT
                    # ignored, and a child keeps that: Ctrl-C must reach btlog here
                    preexec_fn=_interruptible,
                )
                assert proc.stdout is not None
                assert proc.stdout.readline().startswith("attached to")
                (sync / "go").touch()
                _wait_for(sync / "ran", oracle)
                time.sleep(0.2)  # a blackboard poll after the last tick
                # Ctrl-C finishes the file cleanly, with a last poll: before BT.CPP quits
                proc.send_signal(signal.SIGINT)
                rest, errors = proc.communicate(timeout=20)
            finally:
                if proc is not None and proc.poll() is None:  # BT.CPP died, or a hang
                    proc.kill()
                    proc.wait(timeout=10)
                (sync / "quit").touch()
            _raise_if_publisher_fell_silent(errors)
            if oracle.result(timeout=30) is None:
                raise _OracleDied("BT.CPP's process ended without a result")
        assert proc.returncode == 0
        assert "[tick:1] What are you doing?" in rest
        recording = open_recording(out)
        assert not recording.truncated
        assert [a["question"] for a in recording.answers] == ["What are you doing?"]
        writes = {(e.scope, e.key): e.value for e in recording.events if hasattr(e, "key")}
        assert writes.get(("", "x")) is not None and writes.get(("", "v")) is not None

    _with_btcpp_retries(tmp_path, attempt)


BURST_XML = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Repeat name="burst" num_cycles="400">
      <Sequence name="step"><AlwaysSuccess name="a"/><AlwaysSuccess name="b"/></Sequence>
    </Repeat>
  </BehaviorTree>
</root>"""


def test_attach_reports_transitions_lost_beyond_btcpps_buffer(tmp_path: Path) -> None:
    payload = {"xml": BURST_XML, "outcomes": {}, "max_ticks": 1}

    def attempt(folder: Path) -> None:
        # one tick: 400 cycles, 2,800 transitions at once
        result, theirs, _ = _attach_to_btcpp(folder, payload, AttachOptions(poll_interval=0.05))
        assert len(theirs["transitions"]) > 2500
        assert result.full_polls >= 1
        assert any("may be lost" in w for w in result.build.warnings)
        assert result.build.transitions <= 1000 * result.full_polls + 1000

    _with_btcpp_retries(tmp_path, attempt)


def test_attach_killed_leaves_a_readable_prefix(tmp_path: Path) -> None:
    busy = """<root BTCPP_format="4"><BehaviorTree ID="Main">
      <KeepRunningUntilFailure name="forever"><AlwaysSuccess name="beat"/></KeepRunningUntilFailure>
    </BehaviorTree></root>"""

    def attempt(folder: Path) -> None:
        port = _free_port_pair()
        sync = folder / "sync"
        sync.mkdir()
        payload = {"xml": busy, "outcomes": {}, "max_ticks": 100, "tick_sleep_ms": 20}
        payload |= {"groot2_port": port, "sync_dir": str(sync)}
        out = folder / "killed.mcap"
        command = [*ATTACH_COMMAND, f"tcp://127.0.0.1:{port}", "-o", str(out)]
        proc: subprocess.Popen[Any] | None = None
        with ThreadPoolExecutor(max_workers=1) as pool:
            oracle = pool.submit(run_oracle, payload, 60)
            try:
                _wait_for(sync / "ready", oracle)
                proc = subprocess.Popen(
                    command, env=ATTACH_ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE
                )
                assert proc.stdout is not None
                assert proc.stdout.readline().startswith(b"attached to")
                (sync / "go").touch()
                time.sleep(1.6)  # past one flush interval
                if proc.poll() is not None:  # it finished the file itself: why?
                    errors = proc.communicate(timeout=10)[1].decode()
                    _raise_if_publisher_fell_silent(errors)
                    pytest.fail(f"btlog attach ended before it was killed: {errors}")
                proc.kill()
                proc.wait(timeout=10)
            finally:
                if proc is not None and proc.poll() is None:
                    proc.kill()
                (sync / "quit").touch()
            _wait_for(sync / "ran", oracle)
            if oracle.result(timeout=30) is None:
                raise _OracleDied("BT.CPP's process ended without a result")
        recording = open_recording(out)
        assert recording.truncated
        assert len(recording.events) > 20  # a second of beats, at least

    _with_btcpp_retries(tmp_path, attempt)

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
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from btlog.events import StatusChange
from btlog.record.reader import open_recording
from btlog.sources.builder import RecordingBuilder
from btlog.sources.groot2 import AttachHooks, AttachOptions, attach
from tests.oracle.random_trees import generate
from tests.oracle.runner import have_behaviortreepy, run_oracle, tick_boundaries
from tests.test_cli import ROOT, assert_bad_input, btlog

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


def _wait_for(path: Path, timeout: float = 30) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert time.monotonic() < deadline, f"{path.name} never appeared"
        time.sleep(0.005)


class _Polled(AttachHooks):
    def __init__(self) -> None:
        self.event = threading.Event()

    def on_poll(self, builder: RecordingBuilder, t_ns: int) -> None:
        self.event.set()


@pytest.mark.parametrize("seed", [7001, 7002, 7003])
def test_attach_records_btcpp_transition_for_transition(tmp_path: Path, seed: int) -> None:
    case = generate(seed)
    port = _free_port_pair()
    sync = tmp_path / "sync"
    sync.mkdir()
    payload = {
        **dataclasses.asdict(case),
        "groot2_port": port,
        "sync_dir": str(sync),
        "tick_sleep_ms": 8,
    }
    out = tmp_path / "live.mcap"
    stop, polled = threading.Event(), _Polled()
    options = AttachOptions(poll_interval=0.005, tick_gap_ns=3_000_000)
    with ThreadPoolExecutor(max_workers=2) as pool:
        oracle = pool.submit(run_oracle, payload, 60)
        _wait_for(sync / "ready")
        attached = pool.submit(
            attach, f"tcp://127.0.0.1:{port}", out, options, hooks=polled, stop=stop
        )
        assert polled.event.wait(10), "attach never polled"
        (sync / "go").touch()
        _wait_for(sync / "ran")
        stop.set()
        result = attached.result(timeout=20)
        (sync / "quit").touch()
        theirs = oracle.result(timeout=30)
    assert theirs is not None and not theirs["error"], theirs
    assert result.full_polls == 0 and not result.build.warnings
    recording = open_recording(out)
    names = {n.uid: n.name for n in recording.tree}
    ours = [
        [e.tick, names[e.uid], e.prev.name, e.status.name]
        for e in recording.events
        if isinstance(e, StatusChange)
    ]
    assert [r[1:] for r in ours] == [t[1:] for t in theirs["transitions"]]
    assert tick_boundaries(theirs["transitions"]) <= tick_boundaries(ours)  # every tick is found
    assert recording.metadata["source"]["format"] == "groot2"


def test_attach_to_a_port_nobody_serves_fails_within_5_s(tmp_path: Path) -> None:
    began = time.monotonic()
    result = btlog("attach", f"tcp://127.0.0.1:{_free_port_pair()}", "-o", str(tmp_path / "x.mcap"))
    assert time.monotonic() - began < 5 + 2  # the timeout, plus starting Python
    assert_bad_input(result, "no Groot2 publisher answered")
    assert not (tmp_path / "x.mcap").exists()
    assert_bad_input(btlog("attach", "localhost:1667", "-o", "x.mcap"), "tcp://HOST:PORT")


def test_attach_cli_answers_live_and_records_blackboard_changes(tmp_path: Path) -> None:
    case = generate(7001)
    port = _free_port_pair()
    sync = tmp_path / "sync"
    sync.mkdir()
    payload = {**dataclasses.asdict(case), "groot2_port": port, "sync_dir": str(sync)}
    payload["tick_sleep_ms"] = 30
    out = tmp_path / "live.mcap"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NO_COLOR": "1"}
    command = [sys.executable, "-m", "btlog.cli.main", "attach", f"tcp://127.0.0.1:{port}"]
    command += ["-o", str(out), "--blackboard", "--ask", "tick:1=What are you doing?"]
    with ThreadPoolExecutor(max_workers=1) as pool:
        oracle = pool.submit(run_oracle, payload, 60)
        _wait_for(sync / "ready")
        proc = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, text=True)
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("attached to")
        (sync / "go").touch()
        _wait_for(sync / "ran")
        time.sleep(0.2)  # a blackboard poll after the last tick
        proc.send_signal(signal.SIGINT)  # Ctrl-C finishes the file cleanly
        rest = proc.communicate(timeout=20)[0]
        (sync / "quit").touch()
        assert oracle.result(timeout=30) is not None
    assert proc.returncode == 0
    assert "[tick:1] What are you doing?" in rest
    recording = open_recording(out)
    assert not recording.truncated
    assert [a["question"] for a in recording.answers] == ["What are you doing?"]
    writes = {(e.scope, e.key): e.value for e in recording.events if hasattr(e, "key")}
    assert writes.get(("", "x")) is not None and writes.get(("", "v")) is not None


BURST_XML = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Repeat name="burst" num_cycles="400">
      <Sequence name="step"><AlwaysSuccess name="a"/><AlwaysSuccess name="b"/></Sequence>
    </Repeat>
  </BehaviorTree>
</root>"""


def test_attach_reports_transitions_lost_beyond_btcpps_buffer(tmp_path: Path) -> None:
    port = _free_port_pair()
    sync = tmp_path / "sync"
    sync.mkdir()
    payload = {"xml": BURST_XML, "outcomes": {}, "max_ticks": 1}
    payload |= {"groot2_port": port, "sync_dir": str(sync)}
    stop, polled = threading.Event(), _Polled()
    options = AttachOptions(poll_interval=0.05)
    with ThreadPoolExecutor(max_workers=2) as pool:
        oracle = pool.submit(run_oracle, payload, 60)
        _wait_for(sync / "ready")
        attached = pool.submit(
            attach, f"tcp://127.0.0.1:{port}", tmp_path / "b.mcap", options, hooks=polled, stop=stop
        )
        assert polled.event.wait(10)
        (sync / "go").touch()  # one tick: 400 cycles, 2,800 transitions at once
        _wait_for(sync / "ran")
        stop.set()
        result = attached.result(timeout=20)
        (sync / "quit").touch()
        theirs = oracle.result(timeout=30)
    assert theirs is not None and len(theirs["transitions"]) > 2500
    assert result.full_polls >= 1
    assert any("may be lost" in w for w in result.build.warnings)
    assert result.build.transitions <= 1000 * result.full_polls + 1000


def test_attach_killed_leaves_a_readable_prefix(tmp_path: Path) -> None:
    port = _free_port_pair()
    sync = tmp_path / "sync"
    sync.mkdir()
    busy = """<root BTCPP_format="4"><BehaviorTree ID="Main">
      <KeepRunningUntilFailure name="forever"><AlwaysSuccess name="beat"/></KeepRunningUntilFailure>
    </BehaviorTree></root>"""
    payload = {"xml": busy, "outcomes": {}, "max_ticks": 100, "tick_sleep_ms": 20}
    payload |= {"groot2_port": port, "sync_dir": str(sync)}
    out = tmp_path / "killed.mcap"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NO_COLOR": "1"}
    command = [sys.executable, "-m", "btlog.cli.main", "attach", f"tcp://127.0.0.1:{port}"]
    with ThreadPoolExecutor(max_workers=1) as pool:
        oracle = pool.submit(run_oracle, payload, 60)
        _wait_for(sync / "ready")
        proc = subprocess.Popen([*command, "-o", str(out)], env=env, stdout=subprocess.PIPE)
        assert proc.stdout is not None and proc.stdout.readline().startswith(b"attached to")
        (sync / "go").touch()
        time.sleep(1.6)  # past one flush interval
        proc.kill()
        proc.wait(timeout=10)
        _wait_for(sync / "ran")
        (sync / "quit").touch()
        assert oracle.result(timeout=30) is not None
    recording = open_recording(out)
    assert recording.truncated
    assert len(recording.events) > 20  # a second of beats, at least

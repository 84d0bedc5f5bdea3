"""``btlog attach`` against a flaky robot: a fake Groot2 publisher (``tests/groot2_support.py``)
that falls silent, restarts, overflows its buffer and sends short or odd replies. Whatever
happens, every transition the robot logged is in the recording or inside a gap the
recording marks (and ``btlog explain`` tells); bad input is one line and exit 2."""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import msgpack
import pytest

from btlog.events import GAP_SCOPE, BlackboardWrite, Gap, StatusChange
from btlog.record.reader import open_recording
from btlog.sources.attach import AttachHooks, AttachOptions, AttachResult, attach
from btlog.sources.builder import RecordingBuilder
from btlog.status import Status
from tests.cli_support import btlog
from tests.fuzz_support import assert_contract, run_cli
from tests.groot2_support import FakePublisher

XML = b"""<root BTCPP_format="4" main_tree_to_execute="Main"><BehaviorTree ID="Main">
  <Sequence name="patrol"><GoTo name="go a"/><GoTo name="go b"/></Sequence>
</BehaviorTree></root>"""
OTHER_XML = XML.replace(b"go b", b"go c")
#: One lap of the robot: (uid, status) — patrol 1, go a 2, go b 3.
LAP = [(1, 1), (2, 1), (2, 2), (3, 1), (3, 2), (1, 2), (3, 0), (2, 0), (1, 0)]
FAST = AttachOptions(poll_interval=0.01, timeout=0.3, reconnect=5.0, blackboard_interval=0.05)
#: How far btlog's clock of the run and the publisher's may differ, in ns.
CLOCKS = 60_000_000


class Robot:
    """Logs ``LAP`` over and over on the publisher, a transition every ``pace`` s."""

    def __init__(self, publisher: FakePublisher, pace: float = 0.004) -> None:
        self.publisher, self.pace = publisher, pace
        self.running = threading.Event()
        self.running.set()
        self._quit = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._quit.is_set():
            for uid, status in LAP:
                self.running.wait()
                self.publisher.transition(uid, status)
                time.sleep(self.pace)

    def stop(self) -> None:
        self._quit.set()
        self.running.set()
        self._thread.join(timeout=5)


class Attaching:
    """An attach running in a thread: ``finish`` stops it and returns its result."""

    def __init__(self, future: Future[AttachResult], stop: threading.Event) -> None:
        self.future, self.stop = future, stop

    def finish(self) -> AttachResult:
        self.stop.set()
        return self.future.result(timeout=30)

    def ends_by_itself(self, within: float = 10) -> AttachResult:
        return self.future.result(timeout=within)


@contextmanager
def attached(
    publisher: FakePublisher, out: Path, options: AttachOptions = FAST
) -> Iterator[Attaching]:
    """Attach in a thread while the block plays the robot and its faults."""
    stop = threading.Event()
    with ThreadPoolExecutor(max_workers=1) as pool:
        future = pool.submit(attach, publisher.endpoint, out, options, stop=stop)
        deadline = time.monotonic() + 10
        while publisher.starts == 0:
            assert time.monotonic() < deadline and not future.done(), "never attached"
            time.sleep(0.005)
        try:
            yield Attaching(future, stop)
        finally:
            stop.set()


def wait_polls(publisher: FakePublisher, kind: str = "t", polls: int = 5) -> None:
    """Until the publisher has served ``polls`` more requests of ``kind``."""
    target = publisher.served.get(kind, 0) + polls
    deadline = time.monotonic() + 10
    while publisher.served.get(kind, 0) < target:
        assert time.monotonic() < deadline, f"no {kind!r} requests"
        time.sleep(0.005)


def recorded(out: Path) -> tuple[list[tuple[int, int, int]], list[Gap]]:
    """The recording's transitions (ns, uid, status) and gaps."""
    recording = open_recording(out)
    changes = [
        (e.t_ns, e.uid, int(e.status)) for e in recording.events if isinstance(e, StatusChange)
    ]
    marks: dict[str, Gap] = {}
    for e in recording.events:
        if isinstance(e, BlackboardWrite) and e.scope == GAP_SCOPE:
            marks[e.key] = Gap(**e.value)
    return changes, sorted(marks.values())


def assert_lost_only_in_gaps(publisher: FakePublisher, out: Path, session: int = 1) -> None:
    """Every transition of the publisher's first recording is in the file (same time,
    node, status) or lies inside a gap the file marks."""
    changes, gaps = recorded(out)
    kept = set(changes)
    for number, t_us, uid, status in publisher.published:
        if number != session or (t_us * 1000, uid, status) in kept:
            continue
        t_ns = t_us * 1000
        assert any(g.from_ns - CLOCKS <= t_ns <= g.to_ns + CLOCKS for g in gaps), (
            f"transition {(t_ns, uid, status)} lost outside every gap {gaps}"
        )


def test_a_silent_publisher_is_reconnected_and_the_gap_marked(tmp_path: Path) -> None:
    out = tmp_path / "silent.mcap"
    with FakePublisher(XML) as publisher, attached(publisher, out) as attaching:
        robot = Robot(publisher)
        wait_polls(publisher)
        publisher.fall_silent()
        time.sleep(0.8)  # past the 0.3 s timeout: btlog tries again, backing off
        publisher.resume()
        wait_polls(publisher, polls=10)
        robot.stop()
        wait_polls(publisher)
        result = attaching.finish()
    assert result.reconnects == 1 and result.restarts == 0 and not result.gone
    _changes, gaps = recorded(out)
    assert len(gaps) == 1 and "did not answer" in gaps[0].why
    assert gaps[0].to_ns - gaps[0].from_ns >= 300_000_000
    assert_lost_only_in_gaps(publisher, out)
    assert any("no data from" in w for w in result.build.warnings)
    story = run_cli("explain", out)
    assert_contract(story, codes=[0])
    assert "Gaps in the data: 1." in story.stdout and "No data from" in story.stdout


def test_a_restarted_publisher_is_recorded_again_after_its_nodes_reset(tmp_path: Path) -> None:
    out = tmp_path / "restart.mcap"
    with FakePublisher(XML) as publisher, attached(publisher, out) as attaching:
        robot = Robot(publisher)
        wait_polls(publisher)
        robot.running.clear()
        publisher.transition(1, 1)  # patrol left RUNNING by the process that dies
        publisher.transition(2, 1)
        wait_polls(publisher)
        publisher.restart()
        robot.running.set()
        deadline = time.monotonic() + 10
        while publisher.starts < 2:
            assert time.monotonic() < deadline, "never restarted the recording"
            time.sleep(0.01)
        wait_polls(publisher, polls=10)
        robot.stop()
        wait_polls(publisher)
        result = attaching.finish()
    assert result.restarts == 1 and not result.gone
    changes, gaps = recorded(out)
    assert len(gaps) == 1 and "restarted" in gaps[0].why
    restart = gaps[0].to_ns
    left: dict[int, int] = {}  # each node's status before the restart
    for _t, uid, status in (c for c in changes if c[0] < restart):
        left[uid] = status
    resets = {uid for t, uid, status in changes if t == restart and status == 0}
    assert {1, 2} <= resets == {uid for uid, status in left.items() if status}, (
        "the old tree's running nodes reset"
    )
    assert_lost_only_in_gaps(publisher, out, session=1)
    after = [(uid, status) for t, uid, status in changes if t > restart]
    theirs = [(uid, status) for number, _t, uid, status in publisher.published if number == 2]
    assert after == theirs, "everything of the new process is recorded"
    assert "Gaps in the data: 1." in run_cli("explain", out).stdout


def test_a_restart_with_another_tree_ends_the_recording(tmp_path: Path) -> None:
    out = tmp_path / "other.mcap"
    with FakePublisher(XML) as publisher, attached(publisher, out) as attaching:
        robot = Robot(publisher)
        wait_polls(publisher)
        publisher.restart(OTHER_XML)
        result = attaching.ends_by_itself()
        robot.stop()
    assert result.gone
    assert any("restarted with another tree" in w for w in result.build.warnings)
    assert recorded(out)[0], "what was recorded before is kept"


def test_a_publisher_silent_for_good_ends_the_recording_keeping_it(tmp_path: Path) -> None:
    out = tmp_path / "gone.mcap"
    options = AttachOptions(poll_interval=0.01, timeout=0.2, reconnect=0.6)
    with FakePublisher(XML) as publisher, attached(publisher, out, options) as attaching:
        robot = Robot(publisher)
        wait_polls(publisher, polls=10)
        publisher.fall_silent()
        began = time.monotonic()
        result = attaching.ends_by_itself()
        took = time.monotonic() - began
        robot.stop()
    assert result.gone and 0.6 < took < 0.6 + 0.2 + 2.5  # the timeout, the tries, a last one
    warning = next(w for w in result.build.warnings if "stopped answering" in w)
    assert "no answer for 0.6 s" in warning and "the recording ends at" in warning
    assert len(recorded(out)[0]) > 10


def test_an_attach_ending_while_the_publisher_is_silent_says_so(tmp_path: Path) -> None:
    out = tmp_path / "ends.mcap"
    options = dataclasses.replace(FAST, duration=1.0)
    with FakePublisher(XML) as publisher, attached(publisher, out, options) as attaching:
        robot = Robot(publisher)
        wait_polls(publisher)
        publisher.fall_silent()
        result = attaching.ends_by_itself()
        robot.stop()
    assert not result.gone
    assert any("had not answered for" in w for w in result.build.warnings)
    assert recorded(out)[0]


def _cut(header: bytes) -> list[bytes]:
    records = b"".join(
        (1000 * i).to_bytes(6, "little") + (2).to_bytes(2, "little") + bytes([1]) for i in (1, 2)
    )
    return [header, records + b"\x01\x02\x03\x04"]


@pytest.mark.parametrize(
    ("crafted", "why"),
    [
        (_cut, "ended inside a record (4 of 9 bytes)"),
        (lambda header: [header, b"", b"extra"], "in 3 parts, not 2"),
        (lambda header: [b"\x02t" + b"\0" * 20, b""], "that is not Groot2's"),
        (lambda header: [b"error", b"busy"], "refused 't': busy"),
        (lambda header: [header, (1).to_bytes(6, "little") + b"\x09\x00\x01"], "uid 9"),
        (lambda header: [header, (1).to_bytes(6, "little") + b"\x01\x00\x07"], "status 7"),
    ],
)
def test_odd_transition_replies_are_gaps_never_silent(tmp_path: Path, crafted, why: str) -> None:
    out = tmp_path / "odd.mcap"
    with FakePublisher(XML) as publisher, attached(publisher, out) as attaching:
        robot = Robot(publisher)
        wait_polls(publisher)
        publisher.craft("t", crafted)
        wait_polls(publisher, polls=10)
        robot.stop()
        wait_polls(publisher)
        result = attaching.finish()
    _changes, gaps = recorded(out)
    assert len(gaps) == 1 and why in gaps[0].why, gaps
    assert not result.gone and any(why in w for w in result.build.warnings)
    assert_lost_only_in_gaps(publisher, out)


def test_a_full_buffer_marks_the_dropped_transitions_as_a_gap(tmp_path: Path) -> None:
    out = tmp_path / "full.mcap"
    with FakePublisher(XML) as publisher, attached(publisher, out) as attaching:
        wait_polls(publisher)
        publisher.fall_silent()  # a burst while btlog waits: 1,800 transitions, 1,000 kept
        time.sleep(0.05)
        for _lap in range(200):
            for uid, status in LAP:
                publisher.transition(uid, status)
        publisher.resume()
        wait_polls(publisher, polls=5)
        result = attaching.finish()
    assert result.full_polls == 1
    changes, gaps = recorded(out)
    full = [g for g in gaps if "buffer of 1000 transitions was full" in g.why]
    assert len(full) == 1
    assert full[0].to_ns == min(t for t, _u, _s in changes if t >= full[0].to_ns)
    assert any("may be lost" in w for w in result.build.warnings)
    assert_lost_only_in_gaps(publisher, out)


@pytest.mark.parametrize(
    ("payload", "why"),
    [
        (msgpack.packb({"Main": [1, 2, 3]}), "blackboard 'Main' is list"),
        (b"\xc1\xc1\xc1", "not msgpack"),
        (b"\x91" * 5000, "not msgpack"),  # nested past msgpack's depth
        (msgpack.packb([1, 2]), "of list, not a map"),
    ],
)
def test_bad_blackboard_replies_are_skipped_naming_the_endpoint(tmp_path, payload, why) -> None:
    out = tmp_path / "bb.mcap"
    options = dataclasses.replace(FAST, blackboard=True)
    with (
        FakePublisher(XML, {"Main": {"x": 1}}) as publisher,
        attached(publisher, out, options) as attaching,
    ):
        wait_polls(publisher, "B", 2)
        publisher.craft("B", lambda header: [header, payload])
        publisher.blackboard = {"Main": {"x": 2}}
        wait_polls(publisher, "B", 3)
        result = attaching.finish()
    assert not result.gone
    told = [w for w in result.build.warnings if "blackboard replies skipped" in w]
    assert len(told) == 1 and why in told[0] and publisher.endpoint in told[0]
    writes = [e.value for e in open_recording(out).events if isinstance(e, BlackboardWrite)]
    assert writes == [1, 2]


# -- the command line -------------------------------------------------------------------------
def test_attach_cli_reconnects_and_tells_the_gap(tmp_path: Path) -> None:
    out = tmp_path / "cli.mcap"
    with FakePublisher(XML) as publisher:
        robot = Robot(publisher)
        command = ("attach", publisher.endpoint, "-o", out, "--duration", "2.5")
        with ThreadPoolExecutor(max_workers=1) as pool:
            run = pool.submit(btlog, *command, "--timeout", "0.3", "--reconnect", "5")
            deadline = time.monotonic() + 20
            while publisher.starts == 0:
                assert time.monotonic() < deadline
                time.sleep(0.01)
            wait_polls(publisher)
            publisher.fall_silent()
            time.sleep(0.7)
            publisher.resume()
            result = run.result(timeout=60)
        robot.stop()
    assert result.returncode == 0, result.stderr
    silent = "btlog attach: no Groot2 publisher answered within 0.3 s; reconnecting for up to 5 s"
    assert silent in result.stderr
    assert "btlog attach: warning: no data from" in result.stderr
    assert "Traceback" not in result.stderr
    assert "No data from" in run_cli("explain", out).stdout


def test_attach_start_time_of_30_nines_records_from_the_epoch(tmp_path: Path) -> None:
    out = tmp_path / "nines.mcap"
    with FakePublisher(XML) as publisher:
        publisher.start_reply = b"9" * 30
        result = run_cli("attach", publisher.endpoint, "-o", out, "--duration", "0.3")
    assert_contract(result, codes=[0])
    assert "start time 999999999999999999999999999999 µs" in result.stderr
    assert open_recording(out).metadata["started_at"].startswith("1970-01-01")


@pytest.mark.parametrize(
    ("endpoint", "words"),
    [
        ("tcp://127.0.0.1:-1", ["tcp://127.0.0.1:-1", "expected tcp://HOST:PORT"]),
        ("tcp://127.0.0.1:70000", ["port 70000 is not 1-65535"]),
        ("tcp://no-such-host.invalid:1667", ["no-such-host.invalid", "does not resolve"]),
        ("localhost:1667", ["expected tcp://HOST:PORT"]),
    ],
)
def test_bad_endpoints_are_one_line(tmp_path: Path, endpoint: str, words: list[str]) -> None:
    result = run_cli("attach", endpoint, "-o", tmp_path / "x.mcap", "--timeout", "0.5")
    assert_contract(result, *words, codes=[2])
    assert not (tmp_path / "x.mcap").exists()


def test_a_first_reply_of_the_wrong_shape_is_one_line_naming_the_endpoint(tmp_path) -> None:
    with FakePublisher(XML) as publisher:
        publisher.craft("T", lambda header: [header])
        result = run_cli("attach", publisher.endpoint, "-o", tmp_path / "x.mcap")
        assert_contract(result, publisher.endpoint, "in 1 parts, not 2", codes=[2])
        publisher.start_reply = b"soon"
        result = run_cli("attach", publisher.endpoint, "-o", tmp_path / "x.mcap")
        assert_contract(result, publisher.endpoint, "b'soon' is not a number", codes=[2])
    assert not (tmp_path / "x.mcap").exists()


# -- the viewer -----------------------------------------------------------------------------
def test_the_viewer_tells_each_gap_and_links_to_its_moment(tmp_path: Path) -> None:
    from btlog.sources.btcpp_tree import tree_from_log_xml
    from btlog.sources.builder import RecordingBuilder, Source
    from tests.view_support import launched_chromium

    out = tmp_path / "gap.mcap"
    with RecordingBuilder(out, tree_from_log_xml(XML, "test"), Source("test", "mem")) as built:
        built.transition(0, 1, Status.RUNNING)
        built.transition(1_000_000_000, 2, Status.RUNNING)
        gap = Gap(1_000_000_000, 2_500_000_000, "the publisher did not answer")
        built.write(gap.to_ns, GAP_SCOPE, "gap 1", gap.to_json())
        built.transition(2_600_000_000, 2, Status.SUCCESS)
    page_file = tmp_path / "gap.html"
    assert_contract(run_cli("view", out, "--export", page_file), codes=[0])
    for browser in launched_chromium():
        page = browser.new_page()
        page.goto(page_file.as_uri())
        link = page.get_by_text("No data from 1.000 s to 2.500 s")
        link.wait_for(timeout=15000)
        assert "the publisher did not answer" in page.inner_text(".story")
        link.click()
        page.wait_for_selector('.pane[data-run="0"][data-count="2"]', timeout=15000)
        page.close()


class _SlowRecording(AttachHooks):
    """Takes ``seconds`` after each poll, as recording a big reply does."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def on_poll(self, builder: RecordingBuilder, t_ns: int) -> None:
        time.sleep(self.seconds)


def test_polls_start_every_interval_however_long_a_reply_takes_to_record(tmp_path) -> None:
    """A poll starts ``poll_interval`` after the one before started, not after it was
    recorded: 2 s at 0.1 s a poll, each taking 0.07 s, make about 20 polls (about 12
    if the wait came after the recording), so a busy attach keeps up with a publisher
    that keeps only 1,000 transitions between two polls."""
    options = dataclasses.replace(FAST, poll_interval=0.1, duration=2.0)
    with FakePublisher(XML) as publisher:
        result = attach(
            publisher.endpoint, tmp_path / "slow.mcap", options, hooks=_SlowRecording(0.07)
        )
    assert 16 <= result.polls <= 22, result.polls

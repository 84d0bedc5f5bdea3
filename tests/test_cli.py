"""The real command line, in subprocesses, on real files: outputs and exit codes."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from btlog.record.reader import open_recording
from tests.cli_support import assert_bad_input, btlog
from tests.waiting import wait_for_events

ROOT = Path(__file__).resolve().parent.parent
KITTING = ROOT / "trees" / "kitting.xml"
#: Copies of ``recordings/`` that the tests query, so the caches built while reading
#: them never land in the project (filled by the ``recording_copies`` fixture).
RECORDINGS = Path(tempfile.gettempdir()) / f"btlog-test-recordings-{os.getpid()}"


@pytest.fixture(scope="module", autouse=True)
def recording_copies() -> Iterator[Path]:
    """Copy the project's recordings to ``RECORDINGS`` for this module's tests."""
    shutil.copytree(ROOT / "recordings", RECORDINGS, dirs_exist_ok=True)
    yield RECORDINGS
    shutil.rmtree(RECORDINGS, ignore_errors=True)


def test_run_records_and_answers_live(tmp_path: Path) -> None:
    out = tmp_path / "k.mcap"
    result = btlog(
        "run",
        str(KITTING),
        "--domain",
        "kitting",
        "--fail",
        "look at chuck",
        "--ask",
        "30s=What went wrong?",
        "-o",
        str(out),
    )
    assert result.returncode == 0, result.stderr
    assert "I am retrying for attempt 1 to go insert large gear." in result.stdout
    assert "final status: SUCCESS" in result.stdout
    recording = open_recording(out)
    assert [e.seq for e in recording.events] == list(range(len(recording.events)))
    assert recording.answers[0]["question"] == "What went wrong?"
    assert recording.metadata["domain"] == "kitting"
    assert recording.metadata["fail"] == ["look at chuck"]


def test_seeded_runs_are_identical(tmp_path: Path) -> None:
    events = []
    for name in ("a", "b"):
        out = tmp_path / f"{name}.mcap"
        result = btlog(
            "run",
            str(KITTING),
            "--domain",
            "kitting",
            "--failure-rate",
            "0.2",
            "--seed",
            "7",
            "--max-ticks",
            "3000",
            "-o",
            str(out),
        )
        assert result.returncode == 0, result.stderr
        events.append(open_recording(out).events)
    assert events[0] == events[1]
    assert len(events[0]) > 50


def test_validate(tmp_path: Path) -> None:
    result = btlog("validate", str(KITTING))
    assert result.returncode == 0
    assert "OK (BehaviorTree.CPP v4 format)" in result.stdout
    assert "subgoals: go insert large gear; go pick screw; go place screw" in result.stdout
    paper = ROOT / "tests" / "data" / "v3-gear-pair.xml"
    assert "v3 format" in btlog("validate", str(paper)).stdout


@pytest.mark.parametrize(
    ("xml", "words"),
    [
        ("<root><BehaviorTree ID='M'><Sequence>", ["malformed XML", ":1"]),
        (
            "<root BTCPP_format='4'><BehaviorTree ID='M'><Mystery><AlwaysSuccess/></Mystery>"
            "</BehaviorTree></root>",
            ["unknown node type 'Mystery' with children"],
        ),
        (
            "<root BTCPP_format='4'><BehaviorTree ID='M'><Inverter><AlwaysSuccess/><AlwaysSuccess/>"
            "</Inverter></BehaviorTree></root>",
            ["Inverter must have 1 children, found 2"],
        ),
        (
            "<root BTCPP_format='4'><BehaviorTree ID='M'><SubTree ID='Nope'/>"
            "</BehaviorTree></root>",
            ["subtree 'Nope' is not defined"],
        ),
        (
            "<root BTCPP_format='4' main_tree_to_execute='A'><BehaviorTree ID='A'><SubTree ID='B'/>"
            "</BehaviorTree><BehaviorTree ID='B'><SubTree ID='A'/></BehaviorTree></root>",
            ["subtree cycle: A -> B -> A"],
        ),
        (
            "<root BTCPP_format='4' main_tree_to_execute='X'><BehaviorTree ID='A'><AlwaysSuccess/>"
            "</BehaviorTree></root>",
            ["main tree 'X' is not defined"],
        ),
        (
            "<root BTCPP_format='4'><BehaviorTree ID='M'><RetryUntilSuccessful num_attempts='many'>"
            "<AlwaysSuccess/></RetryUntilSuccessful></BehaviorTree></root>",
            ["bad value 'many'"],
        ),
        (
            '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>'
            "<root><BehaviorTree ID='M'><AlwaysSuccess name='&b;'/></BehaviorTree></root>",
            ["DOCTYPE"],
        ),
    ],
)
def test_bad_trees(tmp_path: Path, xml: str, words: list[str]) -> None:
    tree = tmp_path / "bad.xml"
    tree.write_text(xml)
    assert_bad_input(btlog("validate", str(tree)), str(tree), *words)
    assert_bad_input(btlog("run", str(tree), "-o", str(tmp_path / "x.mcap")), str(tree))


@pytest.mark.parametrize(
    ("content", "words"),
    [
        ("nodes: [1, 2]", [":1: nodes: must be a mapping"]),
        (
            "nodes:\n  'look at chuck': MAYBE",
            [":2: nodes['look at chuck']: status must be SUCCESS or FAILURE"],
        ),
        ("nodes:\n  'no such node': FAILURE", ["matches no node"]),
        ("default: {duration: -1}", ["default['duration']: must be a number"]),
        ("nodes: {a: [", ["not valid YAML"]),
    ],
)
def test_bad_outcomes(tmp_path: Path, content: str, words: list[str]) -> None:
    outcomes = tmp_path / "outcomes.yaml"
    outcomes.write_text(content)
    result = btlog("run", str(KITTING), "--outcomes", str(outcomes), "-o", str(tmp_path / "x.mcap"))
    assert_bad_input(result, *words)


def test_bad_run_options(tmp_path: Path) -> None:
    out = str(tmp_path / "x.mcap")
    assert_bad_input(btlog("run", str(KITTING), "--domain", "mars", "-o", out), "mars")
    assert_bad_input(btlog("run", str(KITTING), "--ask", "soon=What?", "-o", out), "soon")
    assert_bad_input(
        btlog("run", str(KITTING), "--ask", "1s=Sing a song", "-o", out), "I don't understand"
    )
    assert_bad_input(btlog("run", str(KITTING), "--failure-rate", "2", "-o", out), "failure-rate")


@pytest.mark.parametrize("content", [b"", b"hello, I am not a recording\n", b"\x89MCAP0\r\n"])
def test_bad_recordings(tmp_path: Path, content: bytes) -> None:
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(content)
    assert_bad_input(btlog("recover", str(broken), "-o", str(tmp_path / "fixed.mcap")), str(broken))


def test_missing_files_are_bad_input(tmp_path: Path) -> None:
    assert_bad_input(btlog("validate", str(tmp_path / "none.xml")), "cannot read")
    assert_bad_input(btlog("recover", str(tmp_path / "none.mcap"), "-o", str(tmp_path / "f.mcap")))


def test_kill_9_then_recover(tmp_path: Path) -> None:
    """A real ``btlog run`` killed with SIGKILL keeps a readable prefix; recover fixes it."""
    out = tmp_path / "killed.mcap"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "btlog.cli.main",
            "run",
            str(KITTING),
            "--domain",
            "kitting",
            "--realtime",
            "--tick-period",
            "0.005",
            "--flush-interval",
            "0.05",
            "--quiet",
            "-o",
            str(out),
        ],
        cwd=ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for_events(out, process, at_least=50)
    finally:
        process.send_signal(signal.SIGKILL)
    process.wait(timeout=10)
    broken = open_recording(out)
    assert broken.truncated
    assert len(broken.events) > 0
    assert [e.seq for e in broken.events] == list(range(len(broken.events)))
    fixed = tmp_path / "fixed.mcap"
    result = btlog("recover", str(out), "-o", str(fixed))
    assert result.returncode == 0, result.stderr
    recovered = open_recording(fixed)
    assert not recovered.truncated
    assert recovered.events == broken.events


def test_help_for_every_command() -> None:
    for command in (
        "run",
        "ask",
        "explain",
        "show",
        "timeline",
        "replay",
        "sql",
        "diff",
        "check",
        "recover",
        "validate",
    ):
        result = btlog(command, "--help")
        assert result.returncode == 0
        assert f"usage: btlog {command}" in result.stdout


FAILS = str(RECORDINGS / "kitting-look-at-chuck-fails.mcap")


def test_ask_and_explain_post_hoc() -> None:
    result = btlog("ask", FAILS, "--at", "30s", "What went wrong?")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == (
        "I am retrying for attempt 1 to go insert large gear. "
        "I could not insert large gear because look at chuck "
        "failed."
    )
    explained = btlog("explain", FAILS, "--at", "30s", "--json")
    data = __import__("json").loads(explained.stdout)
    assert [a["intent"] for a in data["answers"]] == [
        "doing",
        "why",
        "subgoal",
        "goal",
        "how_subgoal",
        "how_goal",
        "wrong",
    ]
    assert data["answers"][3]["answer"] == "My goal is to build a gearbox kit."
    assert data["moment"]["t_ns"] <= 30_000_000_000


def test_ask_can_you_post_hoc_shows_the_tree_and_keeps_the_recording() -> None:
    before = Path(FAILS).read_bytes()
    result = btlog("ask", FAILS, "--at", "20s", "Can you insert large gear?")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("Yes. I will insert large gear after go insert large gear.")
    assert "The tree after this insertion" in result.stdout
    assert "◀ current" in result.stdout
    assert Path(FAILS).read_bytes() == before


def test_show_timeline_sql() -> None:
    shown = btlog("show", FAILS, "--at", "30s", "--blackboard", "--plain")
    assert shown.returncode == 0, shown.stderr
    assert "back to approach for door  reach  #24  RUNNING  ◀ current" in shown.stdout
    assert "insertion pose = " in shown.stdout
    timeline = btlog("timeline", FAILS, "--node", "look at chuck", "--status", "FAILURE")
    assert timeline.returncode == 0, timeline.stderr
    assert timeline.stdout.count("RUNNING -> FAILURE") == 1
    csv = btlog(
        "sql",
        FAILS,
        str(RECORDINGS / "taxi-optimal.mcap"),
        "SELECT count(DISTINCT run_id) AS runs FROM transitions",
        "--format",
        "csv",
    )
    assert csv.stdout.split() == ["runs", "2"]


def test_replay_driven_by_a_script() -> None:
    script = "n 5\nt 10\np 2\ng 30s\nask What went wrong?\nbb\nq\n"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NO_COLOR": "1"}
    result = subprocess.run(
        [sys.executable, "-m", "btlog.cli.main", "replay", FAILS, "--plain", "--script", "-"],
        input=script,
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.count("── event") == 6
    assert "I could not insert large gear because look at chuck failed." in result.stdout
    assert "[go insert large gear::2]" in result.stdout


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["ask", FAILS, "--at", "99s", "What are you doing?"], ["after the end"]),
        (["ask", FAILS, "--at", "soon", "What are you doing?"], ["unparseable moment"]),
        (["ask", FAILS, "--at", "1s", "Sing a song"], ["I don't understand"]),
        (["sql", FAILS, "SELEC 1"], ["SQL error"]),
        (["show", "/no/such/file.mcap"], ["file.mcap"]),
        (["timeline", FAILS, "--status", "DANCING"], ["DANCING"]),
    ],
)
def test_query_bad_input(args: list[str], words: list[str]) -> None:
    assert_bad_input(btlog(*args), *words)


def test_truncated_recording_is_read_with_a_warning(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    assert (
        btlog(
            "run", str(KITTING), "--domain", "kitting", "--flush-interval", "0", "-o", str(out)
        ).returncode
        == 0
    )
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(out.read_bytes()[: int(out.stat().st_size * 0.8)])
    result = btlog("explain", str(cut), "--at", "end")
    assert result.returncode == 0, result.stderr
    assert "warning:" in result.stderr and "truncated" in result.stderr
    assert "What are you doing?" in result.stdout


def test_show_html_escapes_names(tmp_path: Path) -> None:
    tree = tmp_path / "evil.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M">'
        '<Sequence name="&lt;script&gt;alert(1)&lt;/script&gt;">'
        '<Action ID="reach" name="&lt;b&gt;x&lt;/b&gt;"/></Sequence>'
        "</BehaviorTree></root>"
    )
    out = tmp_path / "evil.mcap"
    assert btlog("run", str(tree), "-o", str(out)).returncode == 0
    page = tmp_path / "moment.html"
    result = btlog("show", str(out), "--at", "0.2s", "--html", str(page))
    assert result.returncode == 0, result.stderr
    text = page.read_text()
    assert "<script>" not in text and "<b>x</b>" not in text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text
    assert "I &lt;b&gt;x&lt;/b&gt;." in text
    plain = btlog("show", str(out), "--at", "0.2s", "--plain")
    assert "<script>alert(1)</script>" in plain.stdout  # shown literally, never interpreted

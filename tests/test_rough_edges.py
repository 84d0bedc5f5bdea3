"""Rough edges a new user hit (issue #11, item 5), each through the real command line."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli_support import btlog

ROOT = Path(__file__).resolve().parent.parent
KITTING = str(ROOT / "trees" / "kitting.xml")


@pytest.fixture(scope="module")
def failing_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A kitting run in which "look at chuck" fails once (the README's example)."""
    folder = tmp_path_factory.mktemp("rough")
    result = btlog(
        "run", KITTING, "--domain", "kitting", "--fail", "look at chuck", "-o", "k.mcap",
        cwd=folder,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    return folder / "k.mcap"


@pytest.mark.parametrize(
    "args",
    [
        ["ask", "--at", "-2s", "What are you doing?"],
        ["explain", "--at", "-1500ms"],
        ["show", "--at", "-2s", "--plain"],
        ["timeline", "--from", "-30s", "--to", "-20s"],
    ],
)
def test_negative_moments_are_accepted_as_written(failing_run: Path, args: list[str]) -> None:
    result = btlog(args[0], str(failing_run), *args[1:], cwd=failing_run.parent)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() and not result.stderr


def test_live_questions_take_the_post_hoc_moments(tmp_path: Path) -> None:
    """``end``, ``-2s``, ``tick:N`` and wall times live; each live answer is the post-hoc
    answer at the same moment."""
    asks = ["end=What are you doing?", "-2s=What are you doing?", "tick:40=What is your subgoal?"]
    run = btlog(
        "run", KITTING, "--domain", "kitting", *[a for q in asks for a in ("--ask", q)],
        "-o", "k.mcap", cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    live = dict(zip(run.stdout.splitlines()[0:6:2], run.stdout.splitlines()[1:6:2], strict=True))
    for ask in asks:
        when, question = ask.split("=")
        post = btlog("ask", "k.mcap", "--at", when, question, cwd=tmp_path)
        assert post.returncode == 0, post.stderr
        assert live[f"[{when}] {question}"].strip() == post.stdout.strip()


def test_live_questions_outside_the_run_are_refused_as_post_hoc(tmp_path: Path) -> None:
    """The run is recorded (exit 0) and the question it never reached is not answered,
    with post hoc's reason as a warning (issue #26: it used to record and exit 2)."""
    run = btlog(
        "run", KITTING, "--domain", "kitting", "--ask", "999s=What are you doing?",
        "-o", "k.mcap", cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "warning: --ask 999s=" in run.stderr
    assert "moment '999s' is after the end of the run" in run.stderr
    assert "Traceback" not in run.stderr and (tmp_path / "k.mcap").exists()
    post = btlog("ask", "k.mcap", "--at", "999s", "What are you doing?", cwd=tmp_path)
    assert post.returncode == 2 and "moment '999s' is after the end of the run" in post.stderr


def test_live_questions_past_any_run_of_max_ticks_are_refused_before_running(
    tmp_path: Path,
) -> None:
    for when in ("999s", "tick:51"):
        run = btlog(
            "run", KITTING, "--domain", "kitting", "--max-ticks", "50",
            "--ask", f"{when}=What are you doing?", "-o", "k.mcap", cwd=tmp_path,
        )  # fmt: skip
        assert run.returncode == 2, run.stderr
        assert f"moment '{when}' is after the end of any run of --max-ticks 50" in run.stderr
        assert not (tmp_path / "k.mcap").exists()


def test_a_fail_spec_that_never_applied_is_reported(tmp_path: Path) -> None:
    run = btlog(
        "run", KITTING, "--domain", "kitting", "--fail", "look at chuck@2", "-o", "k.mcap",
        cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert run.stderr.splitlines() == [
        'btlog run: warning: --fail "look at chuck@2" never applied: look at chuck ran 1 time'
    ]


def test_outcomes_entries_never_applied_and_bad_keys_name_the_file_and_line(
    tmp_path: Path,
) -> None:
    (tmp_path / "o.yaml").write_text(
        "default: {status: SUCCESS, duration: 0.1}\nnodes:\n"
        '  "look at chuck": [FAILURE, SUCCESS, FAILURE]\n',
        encoding="utf-8",
    )
    run = btlog("run", KITTING, "--outcomes", "o.yaml", "--domain", "kitting", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert (
        "btlog run: warning: o.yaml:3: 'look at chuck' entry 3 never applied: "
        "look at chuck ran 2 times"
    ) in run.stderr
    (tmp_path / "bad.yaml").write_text(
        'nodes:\n  "look at chuck": FAILURE\n  "luk at chuck": FAILURE\n'
    )
    bad = btlog("run", KITTING, "--outcomes", "bad.yaml", cwd=tmp_path)
    assert bad.returncode == 2
    assert bad.stderr.strip() == (
        "btlog run: bad.yaml:3: key 'luk at chuck' matches no node of the tree"
    )


def test_a_run_stopped_by_max_ticks_says_so_on_stderr(tmp_path: Path) -> None:
    run = btlog("run", KITTING, "--domain", "kitting", "--max-ticks", "50", cwd=tmp_path)
    assert run.returncode == 0
    assert "final status: RUNNING" in run.stdout
    assert "stopped after --max-ticks 50 with the tree RUNNING" in run.stderr


def test_a_bug_in_btlog_exits_3_with_one_line(tmp_path: Path) -> None:
    """An exception that is no bad input is reported as a bug (exit 3), one line; the
    traceback with BTLOG_DEBUG=1. The fault is injected into ``validate``."""
    script = (
        "import sys\n"
        "from btlog.cli import commands, main\n"
        "def broken(args): return {}['missing']\n"
        "commands.validate = broken\n"
        "sys.exit(main.main(sys.argv[1:]))\n"
    )
    command = [sys.executable, "-c", script, "validate", KITTING]
    env = {k: v for k, v in os.environ.items() if k != "BTLOG_DEBUG"}
    bug = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    assert bug.returncode == 3
    assert bug.stderr.strip().splitlines() == [
        "btlog validate: internal error, a bug in btlog (KeyError: 'missing'); "
        "BTLOG_DEBUG=1 shows the traceback"
    ]
    debug = subprocess.run(
        command, capture_output=True, text=True, env={**env, "BTLOG_DEBUG": "1"}, check=False
    )
    assert debug.returncode == 3 and "Traceback" in debug.stderr
    bad = btlog("validate", str(tmp_path / "missing.xml"), cwd=tmp_path)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


RECORDINGS = ROOT / "recordings"
PARALLEL_TREE = """<root BTCPP_format="4" main_tree_to_execute="Main">
<BehaviorTree ID="Main"><Parallel name="work" success_count="2" failure_count="1">
<SubTree ID="go to dock"/><Action ID="beep" name="beep"/></Parallel></BehaviorTree>
<BehaviorTree ID="go to dock"><Sequence name="go to dock"><Action ID="drive" name="drive"/>
</Sequence></BehaviorTree></root>"""
NO_ATTEMPTS = """<root BTCPP_format="4"><BehaviorTree ID="Main"><Sequence name="s">
<RetryUntilSuccessful name="r"><Action ID="go" name="go"/></RetryUntilSuccessful>
</Sequence></BehaviorTree></root>"""


@pytest.fixture
def copies(tmp_path: Path) -> Path:
    """Copies of the project's recordings (their caches stay out of the project)."""
    for name in ("kitting-look-at-chuck-fails.mcap", "taxi-optimal.mcap", "kitting-ok.mcap"):
        (tmp_path / name).write_bytes((RECORDINGS / name).read_bytes())
    return tmp_path


def test_under_a_parallel_only_real_subgoals_are_joined(tmp_path: Path) -> None:
    (tmp_path / "p.xml").write_text(PARALLEL_TREE, encoding="utf-8")
    run = btlog("run", "p.xml", "--ask", "0.2s=What is your subgoal?", "-o", "p.mcap", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines()[1].strip() == "My subgoal is to go to dock."
    post = btlog("ask", "p.mcap", "--at", "0.2s", "What is your subgoal?", cwd=tmp_path)
    assert post.stdout.strip() == "My subgoal is to go to dock."


def test_validate_makes_the_checks_run_makes(tmp_path: Path) -> None:
    (tmp_path / "r.xml").write_text(NO_ATTEMPTS, encoding="utf-8")
    validated = btlog("validate", "r.xml", cwd=tmp_path)
    ran = btlog("run", "r.xml", "-o", "r.mcap", cwd=tmp_path)
    assert validated.returncode == ran.returncode == 2
    assert "port 'num_attempts' is not set" in validated.stderr
    assert validated.stderr.replace("validate", "run") == ran.stderr
    assert not (tmp_path / "r.mcap").exists()


@pytest.mark.parametrize(
    ("moment", "header"),
    [("seq:33", "at seq:33: seq 33, tick "), ("tick:300", ", tick 300, "), ("end", ": seq 255,")],
)
def test_show_headers_name_the_moment_exactly(copies: Path, moment: str, header: str) -> None:
    shown = btlog("show", "kitting-look-at-chuck-fails.mcap", "--at", moment, cwd=copies)
    assert shown.returncode == 0, shown.stderr
    assert header in shown.stdout.splitlines()[0]


def test_show_styles_names_plainly_and_statuses_once(copies: Path) -> None:
    env = {"FORCE_COLOR": "1", "NO_COLOR": ""}
    environment = {k: v for k, v in os.environ.items() if k != "NO_COLOR"} | {"FORCE_COLOR": "1"}
    shown = subprocess.run(
        [sys.executable, "-m", "btlog.cli.main", "show", "kitting-look-at-chuck-fails.mcap"],
        cwd=copies, env=environment, capture_output=True, text=True, check=False, timeout=60,
    )  # fmt: skip
    assert env and shown.returncode == 0, shown.stderr
    line = next(x for x in shown.stdout.splitlines() if "build a gearbox kit" in x)
    assert "\x1b[" in line  # coloured
    assert "\x1b[2mbuild a gearbox kit" not in line and "\x1b[1;2;" not in shown.stdout


def test_diff_exits_1_on_divergence_and_0_when_equal(copies: Path) -> None:
    human = str(ROOT / "trees" / "taxi-human.xml")
    assert btlog("diff", "taxi-optimal.mcap", human, cwd=copies).returncode == 1
    same = btlog("diff", "taxi-optimal.mcap", "taxi-optimal.mcap", cwd=copies)
    assert same.returncode == 0, same.stderr


def test_timeline_node_by_type_matches_every_node_of_it(copies: Path) -> None:
    found = btlog("timeline", "kitting-look-at-chuck-fails.mcap", "--node", "reach", cwd=copies)
    assert found.returncode == 0, found.stderr
    for name in ("approach door", "prepare to insert", "back to approach for door"):
        assert name in found.stdout


def test_kitting_conditions_answer_at_once(tmp_path: Path) -> None:
    (tmp_path / "w.xml").write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><ReactiveSequence name="watch">'
        '<Condition ID="gripper ok" name="gripper ok"/><Action ID="move to" name="go" '
        'place="dock"/></ReactiveSequence></BehaviorTree></root>',
        encoding="utf-8",
    )
    run = btlog("run", "w.xml", "--domain", "kitting", "-o", "w.mcap", cwd=tmp_path)
    assert run.returncode == 0 and run.stderr == ""
    assert "ticks: 41  final status: SUCCESS" in run.stdout  # move to: 4 s


def test_rerun_uses_the_tree_of_the_recordings_project(tmp_path: Path) -> None:
    """The recorded path relative to the recording's project comes first (the recorded
    absolute path exists here too); which file is said, and a changed one warned about."""
    project = tmp_path / "clone"
    (project / "recordings").mkdir(parents=True)
    (project / "trees").mkdir()
    (project / "pyproject.toml").write_text("[project]\nname = 'clone'\n", encoding="utf-8")
    tree = (ROOT / "trees" / "kitting.xml").read_text(encoding="utf-8")
    (project / "trees" / "kitting.xml").write_text(tree + "<!-- edited -->\n", encoding="utf-8")
    run = project / "recordings" / "kitting-ok.mcap"
    run.write_bytes((RECORDINGS / "kitting-ok.mcap").read_bytes())
    checked = btlog("check", str(run), "--rerun", cwd=tmp_path)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    used = project / "trees" / "kitting.xml"
    assert f"with {used} (changed since the recording)" in checked.stdout
    assert f"re-run with {used}, whose sha256 differs" in checked.stderr


def test_recover_prints_a_summary(tmp_path: Path) -> None:
    data = (RECORDINGS / "kitting-ok.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    recovered = btlog("recover", "cut.mcap", "-o", "fixed.mcap", cwd=tmp_path)
    assert recovered.returncode == 0, recovered.stderr
    assert "RecoveryReport(" not in recovered.stdout and "events" in recovered.stdout


def _ticks_said(text: str) -> str:
    """The "N ticks" a command's summary says."""
    (found,) = re.findall(r"(\d+) ticks", text)
    return found


def test_run_recover_and_the_story_count_the_same_ticks(tmp_path: Path) -> None:
    """A run's ticks are the ticks it ran, its teardown not counted, and the story's
    extent is the run's, also after its last event (a cut run ticked on)."""
    ran = btlog(
        "run", KITTING, "--domain", "kitting", "-o", "k.mcap", "--flush-interval", "0",
        cwd=tmp_path,
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    ticks = re.search(r"ticks: (\d+)", ran.stdout)
    assert ticks is not None
    data = (tmp_path / "k.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) * 6 // 10])
    for source, target in (("k.mcap", "whole.mcap"), ("cut.mcap", "fixed.mcap")):
        recovered = btlog("recover", source, "-o", target, cwd=tmp_path)
        assert recovered.returncode == 0, recovered.stderr
        told = btlog("explain", target, cwd=tmp_path).stdout.splitlines()[0]
        assert _ticks_said(told) == _ticks_said(recovered.stdout), (told, recovered.stdout)
        if source == "k.mcap":
            assert _ticks_said(told) == ticks.group(1)
        else:  # the cut run ticked on after its last event: the story says how long
            query = "SELECT duration_ns FROM runs"
            rows = btlog("sql", target, query, "--format", "csv", cwd=tmp_path)
            duration = int(rows.stdout.splitlines()[1]) / 1e9
            assert f"after {duration:.3f} s" in told and "not finished (RUNNING)" in told

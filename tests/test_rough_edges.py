"""Rough edges a new user hit (issue #11, item 5), each through the real command line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
KITTING = str(ROOT / "trees" / "kitting.xml")


def btlog(*args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    """The installed command, in a subprocess."""
    environment = {**os.environ, "NO_COLOR": "1", **(env or {})}
    if "BTLOG_DEBUG" not in (env or {}):
        environment.pop("BTLOG_DEBUG", None)
    return subprocess.run(
        [sys.executable, "-m", "btlog.cli.main", *args],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


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
    run = btlog(
        "run", KITTING, "--domain", "kitting", "--ask", "999s=What are you doing?",
        "-o", "k.mcap", cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 2
    assert "moment '999s' is after the end of the run" in run.stderr
    assert "Traceback" not in run.stderr and (tmp_path / "k.mcap").exists()
    post = btlog("ask", "k.mcap", "--at", "999s", "What are you doing?", cwd=tmp_path)
    assert post.returncode == 2 and "moment '999s' is after the end of the run" in post.stderr


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

"""Regression checks on stored runs: ``btlog check`` (expectations, re-runs) and the plugin.

The stored run is the kitting task (``trees/kitting.xml``, kitting domain, seed 1). Its
first action is "move to see chuck" (4 s, under a nameless RetryUntilSuccessful in the
subgoal "go insert large gear"), so at tick 1 and at 2.5 s it is running, and the answers
there follow from the paper's templates by hand.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from btlog.checks.behaviours import executed_actions
from btlog.checks.expectations import (
    ExpectationError,
    check_run,
    load_expectations,
    record_expectations,
)
from btlog.checks.rerun import _read_run, rerun, run_extent, tree_for_rerun
from btlog.checks.stored_run import final_status_of
from btlog.record.reader import open_recording, stream_events
from btlog.runner import RunConfig, execute
from tests.cli_support import btlog as cli

ROOT = Path(__file__).resolve().parents[1]
KITTING = ROOT / "trees" / "kitting.xml"
SCAN = '<Action ID="scan scene" name="scan scene for collision avoidance"/>'
ATTACH = '<Action ID="attach large gear to scene" name=""/>'
GOOD = {
    "final_status": "SUCCESS",
    "answers": [
        {"at": "tick:1", "ask": "What are you doing?", "answer": "I move to see chuck."},
        {
            "at": "2.5s",
            "ask": "Why are you doing this?",
            "answer": "I move to see chuck in order to go insert large gear.",
        },
        {
            "at": "seq:5",
            "ask": "What is your subgoal?",
            "answer": "My subgoal is to go insert large gear.",
        },
    ],
    "statuses": [
        {"at": "tick:1", "node": "move to see chuck", "status": "RUNNING"},
        {"at": "tick:1", "node": "detect chuck", "status": "IDLE"},
        {"at": "end", "node": "move to see chuck", "status": "IDLE"},
    ],
}


def _env() -> dict[str, str]:
    paths = [str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p)}


@pytest.fixture(scope="module")
def kitting_run(tmp_path_factory) -> Path:
    """A stored kitting run (seed 1)."""
    folder = tmp_path_factory.mktemp("kitting")
    result = execute(
        RunConfig(tree=str(KITTING), domain="kitting", seed=1), folder / "kitting-1.mcap"
    )
    assert result.final_status.name == "SUCCESS"
    return result.path


@pytest.fixture(scope="module")
def swapped_tree(tmp_path_factory) -> Path:
    """The kitting tree with "scan scene…" and "attach large gear to scene" swapped."""
    text = KITTING.read_text(encoding="utf-8")
    pair = f"{SCAN}\n                {ATTACH}"
    assert text.count(pair) == 1
    path = tmp_path_factory.mktemp("edited") / "kitting-swapped.xml"
    path.write_text(text.replace(pair, f"{ATTACH}\n                {SCAN}"), encoding="utf-8")
    return path


def _write(path: Path, data: dict) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


# -- re-runs -----------------------------------------------------------------------------
def test_rerun_of_a_stored_kitting_run_passes(kitting_run):
    report = rerun(kitting_run)
    assert report.ok, report.render()
    assert report.divergence.identical and not report.tree_changed
    assert [s.subgoal for s in report.divergence.subgoals] == [
        "go insert large gear",
        "go pick screw",
        "go place screw",
    ]
    assert report.recorded_status == report.rerun_status == "SUCCESS"


def test_a_run_streamed_for_a_rerun_reads_as_the_whole_file(kitting_run):
    """``check --rerun`` reads each run front to back (its actions as arrays, its ticks
    summarised): the final status, extent and actions of the whole read."""
    streamed = _read_run(kitting_run)
    assert stream_events(kitting_run) is not None  # the streamed path is the one taken
    recording = open_recording(kitting_run)
    assert streamed.final_status == final_status_of(recording) == "SUCCESS"
    assert streamed.extent == run_extent(recording)
    assert streamed.metadata == recording.metadata
    assert list(streamed.actions) == list(executed_actions(recording))
    assert len(streamed.actions) > 10


def test_rerun_with_swapped_actions_fails_and_names_them(kitting_run, swapped_tree):
    report = rerun(kitting_run, swapped_tree)
    assert not report.ok and report.tree_changed
    diverging = report.divergence.divergent_subgoals
    assert [s.subgoal for s in diverging] == ["go insert large gear"]
    found = diverging[0]
    assert found.edit_distance == 2
    assert {found.moves[0].action, *found.moves[0].past} == {
        "scan scene for collision avoidance",
        "attach large gear to scene",
    }
    failed = [r for r in report.results if not r.ok]
    assert [r.what for r in failed] == ['actions of subgoal "go insert large gear"']
    text = report.render()
    assert "scan scene for collision avoidance" in failed[0].actual
    assert "attach large gear to scene" in failed[0].actual
    assert "! " in text and "(in insert large gear)" in text


def test_rerun_replays_live_questions(tmp_path):
    result = execute(
        RunConfig(
            tree=str(KITTING),
            domain="kitting",
            seed=1,
            questions=["tick:100=Can you detect chuck?"],
        ),
        tmp_path / "asked.mcap",
    )
    assert rerun(result.path).ok


def test_rerun_finds_a_moved_projects_tree(tmp_path):
    """Recordings kept in a project find the tree by its recorded relative path."""
    (tmp_path / "pyproject.toml").write_text("[project]\nname = 'robot'\n", encoding="utf-8")
    (tmp_path / "trees").mkdir()
    (tmp_path / "recordings").mkdir()
    tree = tmp_path / "trees" / "kitting.xml"
    tree.write_text("<root/>", encoding="utf-8")
    metadata = {"tree_file": "trees/kitting.xml", "tree_file_abs": "/nowhere/kitting.xml"}
    found = tree_for_rerun(tmp_path / "recordings" / "run.mcap", metadata)
    assert Path(found).resolve() == tree.resolve()
    with pytest.raises(ValueError, match="pass --tree TREE"):
        tree_for_rerun(tmp_path / "run.mcap", {"tree_file": "gone.xml"})


def test_check_rerun_command(kitting_run, swapped_tree):
    passed = cli("check", kitting_run, "--rerun")
    assert passed.returncode == 0, passed.stdout + passed.stderr
    assert passed.stdout.startswith("PASS")
    failed = cli("check", kitting_run, "--rerun", "--tree", swapped_tree)
    assert failed.returncode == 1, failed.stderr
    assert 'FAIL  actions of subgoal "go insert large gear"' in failed.stdout
    assert "scan scene for collision avoidance" in failed.stdout
    assert "attach large gear to scene" in failed.stdout
    assert "1 run checked: 0 passed, 1 failed" in failed.stdout


# -- expectations ------------------------------------------------------------------------
def test_expectations_pass(kitting_run):
    results = check_run(kitting_run, GOOD)
    assert len(results) == 7
    assert all(r.ok for r in results), [r.report() for r in results if not r.ok]


def test_expectations_fail_with_expected_and_actual(kitting_run):
    wrong = {
        **GOOD,
        "final_status": "FAILURE",
        "statuses": [{"at": "tick:1", "node": "move to see chuck", "status": "SUCCESS"}],
    }
    results = check_run(kitting_run, wrong)
    failed = [r for r in results if not r.ok]
    assert [(r.expected, r.actual) for r in failed] == [
        ("FAILURE", "SUCCESS"),
        ("SUCCESS", "RUNNING"),
    ]
    assert "expected: FAILURE" in failed[0].report()


def test_check_expect_command_exit_codes(kitting_run, tmp_path):
    good = _write(tmp_path / "good.yaml", GOOD)
    passed = cli("check", kitting_run, "--expect", good)
    assert passed.returncode == 0, passed.stdout + passed.stderr
    assert "7 checks, 0 failed" in passed.stdout

    wrong = {**GOOD, "answers": [{**GOOD["answers"][0], "answer": "I dance."}]}
    failed = cli("check", kitting_run, "--expect", _write(tmp_path / "wrong.yaml", wrong))
    assert failed.returncode == 1
    assert 'FAIL  answers[0]: answer at tick:1 to "What are you doing?"' in failed.stdout
    assert "expected: I dance." in failed.stdout
    assert "actual:   I move to see chuck." in failed.stdout

    as_json = cli("check", kitting_run, "--expect", good, "--rerun", "--json")
    assert as_json.returncode == 0, as_json.stderr
    data = json.loads(as_json.stdout)
    assert data["ok"] and len(data["runs"][0]["expectations"]["checks"]) == 7
    assert data["runs"][0]["rerun"]["divergence"]["identical"]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (
            "answers:\n  - at: tick:1\n    ask: What are you doing?\n",
            ":2: answers[0]: 'answer' missing",
        ),
        (
            "answers: [{at: 'tick:1', ask: Dance for me, answer: x}]",
            "answers[0]: unknown question 'Dance for me'",
        ),
        (
            "statuses: [{at: tick:1, node: x, status: GREAT}]",
            ":1: statuses[0]['status']: must be one of IDLE",
        ),
        ("final_status: [1, 2", "not valid YAML"),
        ("colour: blue", ":1: colour: unknown key 'colour'"),
        ("statuses: [{at: tick:99999, node: detect chuck, status: IDLE}]", "statuses[0]:"),
        ("statuses: [{at: tick:1, node: retreat arm, status: IDLE}]", "matches 6 nodes"),
    ],
)
def test_bad_expectation_files_exit_2_with_one_line(kitting_run, tmp_path, content, message):
    path = tmp_path / "bad.yaml"
    path.write_text(content, encoding="utf-8")
    result = cli("check", kitting_run, "--expect", path)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and message in lines[0], lines


def test_check_needs_expect_or_rerun(kitting_run):
    result = cli("check", kitting_run)
    assert result.returncode == 2
    assert result.stderr.strip() == "btlog check: check needs --expect FILE or --rerun"


def test_load_expectations_names_the_file_and_entry(tmp_path):
    path = tmp_path / "e.yaml"
    path.write_text("answers:\n  - at: 1s\n    ask: What is your goal?\n", encoding="utf-8")
    with pytest.raises(ExpectationError, match=r"e\.yaml:2: answers\[0\]: 'answer' missing"):
        load_expectations(path)
    assert load_expectations(path, partial=True).answers[0].answer is None


def test_record_expectations_fills_in_actual_values(kitting_run):
    skeleton = {
        "answers": [{"at": a["at"], "ask": a["ask"]} for a in GOOD["answers"]],
        "statuses": [{**s, "status": "FAILURE"} for s in GOOD["statuses"]],
    }
    assert record_expectations(kitting_run, skeleton) == GOOD


# -- the pytest plugin -------------------------------------------------------------------
def _plugin_args() -> list[str]:
    """``-p btlog.testing.plugin`` unless the installed entry point loads it already."""
    installed = any(ep.name == "btlog" for ep in importlib.metadata.entry_points(group="pytest11"))
    return [] if installed else ["-p", "btlog.testing.plugin"]


def _pytest(folder: Path, *args: str) -> subprocess.CompletedProcess:
    command = [
        sys.executable,
        "-m",
        "pytest",
        *_plugin_args(),
        "-p",
        "no:cacheprovider",
        "-p",
        "no:hypothesispytest",
        "-q",
        "-rf",
        *args,
    ]
    return subprocess.run(
        command, capture_output=True, text=True, env=_env(), cwd=folder, timeout=120
    )


FIXTURE_TESTS = """
def test_fixtures(btlog_run, btlog_expect):
    run = btlog_run("kit.mcap")
    assert run.final_status == "SUCCESS"
    assert run.answer("tick:1", "What are you doing?") == "I move to see chuck."
    assert run.status("tick:1", "move to see chuck") == "RUNNING"
    tree, state = run.state_at("end")
    assert state.seq > 0
    btlog_expect("kit.mcap", {"final_status": "SUCCESS"}, rerun=True)
"""


def test_plugin_collects_checks_and_re_records(kitting_run, tmp_path):
    suite = tmp_path / "suite"
    suite.mkdir()
    (suite / "pytest.ini").write_text("[pytest]\n", encoding="utf-8")
    (suite / "kit.mcap").write_bytes(kitting_run.read_bytes())
    (suite / "test_runs.py").write_text(FIXTURE_TESTS, encoding="utf-8")
    wrong = {**GOOD, "answers": [{**GOOD["answers"][0], "answer": "I dance."}], "rerun": True}
    expect = _write(suite / "kit.expect.yaml", wrong)

    failing = _pytest(suite)
    assert failing.returncode == 1, failing.stdout + failing.stderr
    assert "FAILED kit.expect.yaml::answers[0]" in failing.stdout
    assert (
        "expected: I dance." in failing.stdout
        and "actual:   I move to see chuck." in failing.stdout
    )
    assert "1 failed, 6 passed" in failing.stdout  # 1 + 1 + 3 + 1 rerun + 1 fixture test

    updated = _pytest(suite, "--btlog-update")
    assert updated.returncode == 0, updated.stdout + updated.stderr
    assert "re-recorded 1 expectation file(s)" in updated.stdout
    data = yaml.safe_load(expect.read_text(encoding="utf-8"))
    assert data["answers"][0]["answer"] == "I move to see chuck."
    assert data["rerun"] is True and data["statuses"] == GOOD["statuses"]

    passing = _pytest(suite)
    assert passing.returncode == 0, passing.stdout + passing.stderr
    assert "7 passed" in passing.stdout


def test_plugin_reports_a_bad_expectation_file_in_one_line(kitting_run, tmp_path):
    (tmp_path / "pytest.ini").write_text("[pytest]\n", encoding="utf-8")
    (tmp_path / "kit.expect.yaml").write_text("statuses: [{at: 1s}]\n", encoding="utf-8")
    result = _pytest(tmp_path)
    assert result.returncode == 2, result.stdout
    assert "kit.expect.yaml:1: statuses[0]: 'node' missing" in result.stdout

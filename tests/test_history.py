"""Explanations over a run's history (issue 15): Q6 after the fact, the new questions,
word for word on the project's trees, asked live (``--ask``) and post hoc."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from btlog.explain.questions import answer
from btlog.replay.database import open_runs
from btlog.runner import RunConfig, execute

ROOT = Path(__file__).resolve().parent.parent
TAXI = str(ROOT / "trees" / "taxi.xml")
KITTING = str(ROOT / "trees" / "kitting.xml")

TAXI_PICKUP_FAILS = {
    "What went wrong?": "I could not go deliver passenger because pick up passenger failed.",
    "Why didn't you drop off passenger?": (
        "I did not drop off passenger because pick up passenger failed."
    ),
    "Why did go pick up passenger fail?": (
        "I could not go pick up passenger because pick up passenger failed."
    ),
    "When did pick up passenger last fail?": "pick up passenger last failed at 7.000 s.",
    "When did drop off passenger last start?": "drop off passenger has not started.",
    "How long did go pick up passenger take?": (
        "go pick up passenger took 7.000 s, from 0.000 s to 7.000 s."
    ),
    "What will you do next?": "I have finished go deliver passenger.",
}


def _record(tmp_path: Path, tree: str, domain: str, questions=(), **config) -> Path:
    path = tmp_path / "run.mcap"
    execute(RunConfig(tree=tree, domain=domain, questions=list(questions), **config), path)
    return path


def _ask(path: Path, at: str, question: str) -> str:
    with open_runs(path, cache=False) as database:
        run = database.run(str(path))
        moment = run.resolve(at)
        tree, state = run.state_after(moment.count)
        return answer(tree, state, question, run.history(), moment.t_ns).text


@pytest.mark.parametrize(
    "tree_file", ["trees/taxi.xml", "paper/taxi-domain-tree.xml"], indirect=True
)
def test_taxi_pick_up_fails_live_and_post_hoc(tmp_path: Path, tree_file: Path) -> None:
    questions = [f"end={q}" for q in TAXI_PICKUP_FAILS]  # asked at the end, as post hoc
    path = tmp_path / "run.mcap"
    config = RunConfig(
        tree=str(tree_file), domain="taxi", fail=["pick up passenger"], questions=questions
    )
    result = execute(config, path)
    assert result.final_status.name == "FAILURE"
    live = {q.question: a.text for q, a, _ in result.answers}
    assert live == TAXI_PICKUP_FAILS
    for question, expected in TAXI_PICKUP_FAILS.items():
        assert _ask(path, "end", question) == expected


@pytest.mark.parametrize(
    "tree_file", ["trees/kitting.xml", "paper/kitting-tree.xml"], indirect=True
)
def test_kitting_insertion_fails_through_every_retry(tmp_path: Path, tree_file: Path) -> None:
    """The robot falls back to asking for help and the run succeeds: at the end Q6 tells
    the last failure episode as the story does (when the leaf failed, what Q6 said
    then), not when help was asked for; a leaf's failure is told by its time."""
    outcomes = {"nodes": {"trial and error insert": ["FAILURE"]}}
    path = _record(tmp_path, str(tree_file), "kitting", outcomes=outcomes)
    assert _ask(path, "end", "What went wrong?") == (
        "At 40.700 s: I am retrying for attempt 2 to go insert large gear. I could not "
        "insert large gear because trial and error insert failed."
    )
    assert _ask(path, "end", "Why did trial and error insert fail?") == (
        "trial and error insert failed at 40.700 s."
    )
    # The SubTree did not fail, its Sequence of the same name did: the answer is about it.
    assert _ask(path, "end", "Why did go insert large gear fail?") == (
        "I could not go insert large gear because trial and error insert failed."
    )
    assert _ask(path, "end", "When did go insert large gear last succeed?") == (
        "go insert large gear last succeeded at 43.700 s."
    )


def test_nothing_went_wrong_only_when_nothing_failed(tmp_path: Path) -> None:
    path = _record(tmp_path, TAXI, "taxi")
    assert _ask(path, "end", "What went wrong?") == "Nothing went wrong."
    assert _ask(path, "end", "Why did pick up passenger fail?") == (
        "pick up passenger has not failed."
    )
    assert _ask(path, "end", "Why didn't you drop off passenger?") == "I did drop off passenger."


@pytest.mark.parametrize(
    "tree_file", ["trees/kitting.xml", "paper/kitting-tree.xml"], indirect=True
)
def test_what_will_you_do_next_kitting(tmp_path: Path, tree_file: Path) -> None:
    path = _record(tmp_path, str(tree_file), "kitting", max_ticks=60)
    with open_runs(path, cache=False) as database:
        run = database.run(str(path))
        (first,) = [e for e in run.timeline(node="move to see chuck", status="RUNNING")][:1]
        tree, state = run.state_at(f"seq:{first.seq}")
        text = answer(tree, state, "What will you do next?", run.history()).text
    assert text == "After I move to see chuck, I will lift torso."


@pytest.mark.parametrize(
    ("question", "expected"),
    [
        ("what's next", "After I move right, I will move right."),
        ("Why haven't you dropped off passenger?", 'Sorry. I don\'t know "dropped off passenger".'),
        ("Why did you not drop off passenger?", "I have not started to drop off passenger yet."),
        ("When did navigate to passenger start?", "navigate to passenger last started at 0.000 s."),
        ("How long has move right been running?", "move right has been running for 0.250 s."),
    ],
)
def test_paraphrases(tmp_path_factory, question: str, expected: str) -> None:
    folder = tmp_path_factory.mktemp("taxi")
    path = _record(folder, TAXI, "taxi", max_ticks=6)
    assert _ask(path, "0.25s", question) == expected


def test_shared_name_means_the_outermost_node(tmp_path: Path) -> None:
    """``go insert large gear`` names a SubTree, its Fallback and a Sequence: the
    answer is about the SubTree, never a refusal."""
    path = _record(tmp_path, KITTING, "kitting", max_ticks=5)
    with open_runs(path, cache=False) as database:
        run = database.run(str(path))
        tree, state = run.state_at("end")
        result = answer(tree, state, "When did go insert large gear last start?", run.history())
    (uid,) = result.nodes
    assert tree.node(uid).kind == "subtree"
    assert result.text == "go insert large gear last started at 0.000 s."


def test_cli_ask_at_end(tmp_path: Path) -> None:
    path = _record(tmp_path, TAXI, "taxi", fail=["pick up passenger"])
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "btlog.cli.main",
            "ask",
            str(path),
            "--at",
            "end",
            "What went wrong?",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout.strip() == TAXI_PICKUP_FAILS["What went wrong?"]


def _explain(path: Path, *options: str) -> str:
    done = subprocess.run(
        [sys.executable, "-m", "btlog.cli.main", "explain", str(path), *options],
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout


def test_story_of_a_run_with_retries_and_a_fallback(tmp_path: Path) -> None:
    path = _record(
        tmp_path,
        KITTING,
        "kitting",
        outcomes={"nodes": {"look at chuck": ["FAILURE", "FAILURE", "SUCCESS"]}},
    )
    lines = _explain(path).splitlines()
    assert lines[0].startswith("Goal: build a gearbox kit. Outcome: SUCCESS after ")
    assert lines[1] == "Failures: 2."
    assert lines[2].endswith(": I could not insert large gear because look at chuck failed.")
    assert lines[3] == "    fell back to reset arm; no alternative left; retried (attempt 1 of 2)."
    assert lines[4].endswith(
        ": I am retrying for attempt 1 to go insert large gear. "
        "I could not insert large gear because look at chuck failed."
    )
    assert lines[5] == "    fell back to reset arm; no alternative left; retried (attempt 2 of 2)."
    assert lines[6] == "Subgoals:"
    assert [line.split(":")[0].strip() for line in lines[7:]] == [
        "go insert large gear",
        "go pick screw",
        "go place screw",
    ]
    assert "SUCCESS in" in lines[7] and "runs" not in lines[7]


def test_story_json_of_a_failed_run(tmp_path: Path) -> None:
    path = _record(tmp_path, TAXI, "taxi", fail=["pick up passenger"])
    told = json.loads(_explain(path, "--json"))
    assert told["outcome"] == "FAILURE"
    assert told["why"] == TAXI_PICKUP_FAILS["What went wrong?"]
    (episode,) = told["episodes"]
    assert episode["leaf"] == "pick up passenger"
    assert episode["t_ns"] == 7_000_000_000
    assert episode["handling"] == ["propagated to go deliver passenger: the run failed"]
    assert [(s["subgoal"], s["result"], s["runs"]) for s in told["subgoals"]] == [
        ("go pick up passenger", "FAILURE", 1),
        ("go drop off passenger", None, 0),
    ]

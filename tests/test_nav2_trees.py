"""Nav2's default trees load, run with scripted leaves, and explain a local recovery.

The trees are btlog's stand-ins in ``trees/nav2`` (same nodes, names and structure as
Nav2's ``navigate_to_pose_w_replanning_and_recovery.xml`` and
``navigate_through_poses_w_replanning_and_recovery.xml``). Set ``BTLOG_NAV2_TREES`` to a
folder holding Nav2's originals (``nav2_bt_navigator/behavior_trees`` of a navigation2
checkout) to run every test on the originals instead, and to check that the stand-ins
have the originals' structure.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from btlog.record.reader import open_recording
from btlog.runner import RunConfig, execute
from btlog.state import StateProjection
from btlog.status import FAILURE, SUCCESS
from btlog.tree.loader import load_tree
from btlog.tree.model import Node
from tests.cli_support import btlog

ROOT = Path(__file__).resolve().parent.parent
OURS = ROOT / "trees" / "nav2"
FAILS_ONCE = OURS / "follow-path-fails-once.yaml"
ORIGINALS = os.environ.get("BTLOG_NAV2_TREES")
TREES = {
    "navigate_to_pose": "navigate_to_pose_w_replanning_and_recovery.xml",
    "navigate_through_poses": "navigate_through_poses_w_replanning_and_recovery.xml",
}


def nav2_tree(kind: str) -> Path:
    """Nav2's original tree when ``BTLOG_NAV2_TREES`` is set, else btlog's stand-in."""
    if ORIGINALS:
        return Path(ORIGINALS) / TREES[kind]
    return OURS / f"{kind}.xml"


def shape(node: Node) -> tuple:
    """A node's type, name, ports and children, recursively."""
    ports = tuple(sorted((k, p.value) for k, p in node.ports.items()))
    return (node.type, node.name, ports, tuple(shape(c) for c in node.children))


@pytest.mark.skipif(not ORIGINALS, reason="BTLOG_NAV2_TREES is not set")
@pytest.mark.parametrize("kind", sorted(TREES))
def test_stand_ins_have_the_originals_structure(kind: str) -> None:
    original = load_tree(Path(ORIGINALS or "") / TREES[kind])
    ours = load_tree(OURS / f"{kind}.xml")
    assert shape(ours.root) == shape(original.root)
    assert ours.name == original.name


@pytest.mark.parametrize("kind", sorted(TREES))
def test_default_trees_run_to_success(kind: str, tmp_path: Path) -> None:
    config = RunConfig(
        str(nav2_tree(kind)),
        outcomes={
            "default": {"status": "SUCCESS", "duration": 0},
            "nodes": {"FollowPath": {"status": "SUCCESS", "duration": 4.0}},
        },
    )
    result = execute(config, tmp_path / "run.mcap")
    assert result.final_status is SUCCESS


@pytest.mark.parametrize("kind", sorted(TREES))
def test_follow_path_failing_once_clears_the_local_costmap(kind: str, tmp_path: Path) -> None:
    questions = ["2.2s=What are you doing?", "2.2s=What went wrong?", "3s=What went wrong?"]
    config = RunConfig(str(nav2_tree(kind)), outcomes_file=str(FAILS_ONCE), questions=questions)
    result = execute(config, tmp_path / "run.mcap")
    assert result.final_status is SUCCESS
    answers = [a.text for _, a, _ in result.answers]
    assert answers == [
        "I clear local costmap context.",
        "I could not follow path because follow path failed.",
        "I am retrying for attempt 1 to follow path. "
        "I could not follow path because follow path failed.",
    ]


def test_follow_path_failing_always_runs_the_recovery_actions_in_turn(tmp_path: Path) -> None:
    """Each failure of the navigation runs the next recovery action of the RoundRobin.
    Without ``wrap_around`` (Nav2's default) the last one, BackUp, ends the RoundRobin
    with FAILURE even though it succeeded, so the navigation fails after it."""
    outcomes = {
        "default": {"status": "SUCCESS", "duration": 0},
        "nodes": {
            "GlobalUpdatedGoal": "FAILURE",
            "GoalUpdated": "FAILURE",
            "IsGoalNearby": "FAILURE",
            "FollowPath": {"status": "FAILURE", "duration": 0.5},
        },
    }
    path = tmp_path / "run.mcap"
    config = RunConfig(str(nav2_tree("navigate_to_pose")), outcomes=outcomes)
    assert execute(config, path).final_status is FAILURE
    recording = open_recording(path)
    tree = recording.tree
    started = [
        tree.node(e.uid).description
        for e in recording.transitions
        if e.prev.name == "IDLE" and e.status.name != "IDLE"
    ]
    recoveries = [
        name for name in started if name in ("ClearLocalCostmap-Subtree", "Spin", "Wait", "BackUp")
    ]
    assert recoveries == ["ClearLocalCostmap-Subtree", "Spin", "Wait", "BackUp"]
    assert started.count("FollowPath") >= 8  # two tries (one local recovery) per round


def test_a_nav2_user_asks_why_the_local_costmap_was_cleared(tmp_path: Path) -> None:
    """The README's example: run with FollowPath failing once, ask post hoc."""
    out = tmp_path / "nav.mcap"
    tree = nav2_tree("navigate_to_pose")
    run = btlog("run", str(tree), "--outcomes", str(FAILS_ONCE), "-o", str(out), "--quiet")
    assert run.returncode == 0, run.stderr
    moment = btlog("timeline", str(out), "--node", "ClearLocalCostmap-Context")
    assert moment.returncode == 0, moment.stderr
    assert "IDLE -> RUNNING" in moment.stdout
    explained = btlog("explain", str(out), "--at", "2.2s", "--json")
    assert explained.returncode == 0, explained.stderr
    answers = {a["intent"]: a["answer"] for a in json.loads(explained.stdout)["answers"]}
    assert answers["doing"] == "I clear local costmap context."
    assert answers["wrong"] == "I could not follow path because follow path failed."


def test_state_counts_recovery_attempts_of_the_first_child_only(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    execute(RunConfig(str(nav2_tree("navigate_to_pose")), outcomes_file=str(FAILS_ONCE)), path)
    recording = open_recording(path)
    projection = StateProjection(recording.tree)
    follow = next(n for n in recording.tree if n.type == "RecoveryNode" and n.name == "FollowPath")
    seen = set()
    for event in recording.transitions:
        projection.on_status(event.seq, event.t_ns, event.tick, event.uid, event.prev, event.status)
        seen.add(projection.state.retry_attempts.get(follow.uid, 0))
    assert seen == {0, 1}
    assert follow.uid not in projection.state.retry_attempts  # the node completed


@pytest.mark.parametrize("kind", sorted(TREES))
def test_a_nodes_model_makes_nav2_conditions_conditions(kind: str, tmp_path: Path) -> None:
    config = RunConfig(
        str(nav2_tree(kind)),
        outcomes_file=str(FAILS_ONCE),
        nodes_model=str(OURS / "nodes_model.xml"),
        questions=["2.2s=What went wrong?"],
    )
    result = execute(config, tmp_path / "run.mcap")
    assert result.final_status is SUCCESS
    assert [a.text for _, a, _ in result.answers] == [
        "I could not follow path because follow path failed."
    ]
    recording = open_recording(result.path)
    conditions = {n.uid: n.type for n in recording.tree if n.kind == "condition"}
    assert set(conditions.values()) == {
        "GlobalUpdatedGoal",
        "GoalUpdated",
        "IsGoalNearby",
        "WouldAControllerRecoveryHelp",
        "WouldAPlannerRecoveryHelp",
    }
    assert all(e.status.name != "RUNNING" for e in recording.transitions if e.uid in conditions)
    assert recording.metadata["nodes_model"].endswith("nodes_model.xml")

"""The paper's worked answers (section 7), word for word, on the paper's own trees and on
the project's trees, asked live during real runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.domains import make_domain
from btlog.domains.outcomes import Outcomes
from btlog.events import EventLog
from btlog.executor.engine import Executor
from btlog.explain.questions import answer, explain
from btlog.state import StateProjection
from btlog.status import RUNNING
from btlog.tree.loader import load_tree

ROOT = Path(__file__).resolve().parent.parent
KITTING_TREES = ["paper/kitting-tree.xml", "trees/kitting.xml"]
TAXI_TREES = ["paper/taxi-domain-tree.xml", "trees/taxi.xml"]

SUBGOAL_STEPS = (
    'To achieve the subgoal "go insert large gear", I need to do 3 steps. '
    "1. move to see chuck. 2. detect chuck. 3. insert large gear."
)
GOAL_STEPS = (
    'To achieve the goal "build a gearbox kit", I need to do 3 steps. '
    "1. go insert large gear. 2. go pick screw. 3. go place screw."
)


class LiveRun:
    """A run driven tick by tick, with the live state projection."""

    def __init__(self, tree_path: Path, domain: str, outcomes: dict | None = None) -> None:
        self.tree = load_tree(tree_path)
        leaves = make_domain(domain).leaf_factory(self.tree, Outcomes.from_mapping(outcomes))
        self.executor = Executor(self.tree, leaf_factory=leaves)
        self.projection = StateProjection(self.tree)
        self.executor.subscribe(self.projection)

    def running(self) -> list[str]:
        """Descriptions of the running execution nodes."""
        state = self.projection.state
        return [
            n.description
            for n in self.projection.tree
            if n.is_execution and state.status_of(n.uid) is RUNNING
        ]

    def until(self, description: str, condition=lambda run: True, limit: int = 5000) -> None:
        """Tick until ``description`` is running and ``condition`` holds."""
        for _ in range(limit):
            self.executor.tick()
            if description in self.running() and condition(self):
                return
        raise AssertionError(f"{description!r} never ran")

    def ask(self, question: str) -> str:
        """The live answer."""
        return answer(self.projection.tree, self.projection.state, question).text

    def retrying(self) -> bool:
        """True once a retry has a failed attempt."""
        return bool(self.projection.state.retry_attempts)


@pytest.mark.parametrize("tree_file", KITTING_TREES, indirect=True)
@pytest.mark.parametrize(
    ("node", "why"),
    [
        ("move to see chuck", "I move to see chuck in order to go insert large gear."),
        ("look at chuck roughly", "I look at chuck roughly in order to detect chuck."),
        (
            "scan scene for collision avoidance",
            "I scan scene for collision avoidance in order to insert large gear.",
        ),
    ],
)
def test_hierarchical_answers_kitting(tree_file: Path, node: str, why: str) -> None:
    run = LiveRun(tree_file, "kitting")
    run.until(node)
    texts = [a.text for a in explain(run.projection.tree, run.projection.state)]
    assert texts == [
        f"I {node}.",
        why,
        "My subgoal is to go insert large gear.",
        "My goal is to build a gearbox kit.",
        SUBGOAL_STEPS,
        GOAL_STEPS,
        "Nothing went wrong.",
    ]


@pytest.mark.parametrize("tree_file", KITTING_TREES, indirect=True)
def test_look_at_chuck_failing_once(tree_file: Path) -> None:
    run = LiveRun(tree_file, "kitting", {"nodes": {"look at chuck": ["FAILURE", "SUCCESS"]}})
    run.until("retreat arm")
    assert (
        run.ask("What went wrong?") == "I could not insert large gear because look at chuck failed."
    )
    assert run.ask("Was there anything wrong?") == run.ask("How was the failure handled?")


@pytest.mark.parametrize("tree_file", KITTING_TREES, indirect=True)
def test_look_at_chuck_failing_twice(tree_file: Path) -> None:
    run = LiveRun(
        tree_file, "kitting", {"nodes": {"look at chuck": ["FAILURE", "FAILURE", "SUCCESS"]}}
    )
    run.until("retreat arm", LiveRun.retrying)
    assert run.ask("What went wrong?") == (
        "I am retrying for attempt 1 to go insert large gear. "
        "I could not insert large gear because look at chuck failed."
    )


@pytest.mark.parametrize("tree_file", KITTING_TREES, indirect=True)
@pytest.mark.parametrize(
    ("failing", "cause"),
    [
        ("move to see chuck", "I could not go insert large gear because move to see chuck failed."),
        ("lift torso", "I could not detect chuck because lift torso failed."),
    ],
)
def test_retried_failure(tree_file: Path, failing: str, cause: str) -> None:
    """Asked while the failed node runs again in the retry's second attempt (paper 7.1.3)."""
    run = LiveRun(tree_file, "kitting", {"nodes": {failing: ["FAILURE", "SUCCESS"]}})
    run.until(failing, LiveRun.retrying)
    assert (
        run.ask("What went wrong?")
        == f"I am retrying for attempt 1 to go insert large gear. {cause}"
    )


@pytest.mark.parametrize("tree_file", KITTING_TREES, indirect=True)
def test_can_you_insert_large_gear(tree_file: Path) -> None:
    run = LiveRun(tree_file, "kitting")
    run.until("trial and error insert")
    result = answer(run.projection.tree, run.projection.state, "Can you insert large gear?")
    assert result.text == "Yes. I will insert large gear after go insert large gear."
    plan = result.insertion
    # The unnamed Sequence holding "detect chuck" and "insert large gear" (paper, Fig. 11),
    # inserted into the root right after the current subgoal.
    assert plan.source.name == "" and plan.source.type == "Sequence"
    assert [c.description for c in plan.source.children] == ["detect chuck", "insert large gear"]
    assert plan.parent is run.projection.tree.root
    assert plan.after.description == "go insert large gear"


def test_cannot_redo_the_goal_and_does_not_know_what_the_tree_lacks(paper_trees: Path) -> None:
    """A behaviour the tree has but cannot insert (the goal itself) cannot be redone; one
    the tree does not have is not known, as in the other questions about a node."""
    run = LiveRun(paper_trees / "kitting-tree.xml", "kitting")
    run.until("move to see chuck")
    assert run.ask("Can you build a gearbox kit?") == 'Sorry. I cannot redo "build a gearbox kit".'
    assert run.ask("Can you fly to the moon?") == 'Sorry. I don\'t know "fly to the moon".'


@pytest.mark.parametrize("tree_file", TAXI_TREES, indirect=True)
def test_taxi_move_right(tree_file: Path) -> None:
    run = LiveRun(tree_file, "taxi")
    run.until("move right")
    texts = [a.text for a in explain(run.projection.tree, run.projection.state)]
    assert texts[:6] == [
        "I move right.",
        "I move right in order to navigate to passenger.",
        "My subgoal is to go pick up passenger.",
        "My goal is to go deliver passenger.",
        'To achieve the subgoal "go pick up passenger", I need to do 2 steps. '
        "1. navigate to passenger. 2. pick up passenger.",
        'To achieve the goal "go deliver passenger", I need to do 2 steps. '
        "1. go pick up passenger. 2. go drop off passenger.",
    ]


@pytest.mark.parametrize("tree_file", TAXI_TREES, indirect=True)
def test_taxi_drop_off(tree_file: Path) -> None:
    run = LiveRun(tree_file, "taxi")
    run.until("drop off passenger")
    texts = [a.text for a in explain(run.projection.tree, run.projection.state)]
    assert texts[:6] == [
        "I drop off passenger.",
        "I drop off passenger in order to go drop off passenger.",
        "My subgoal is to go drop off passenger.",
        "My goal is to go deliver passenger.",
        'To achieve the subgoal "go drop off passenger", I need to do 2 steps. '
        "1. navigate to destination. 2. drop off passenger.",
        'To achieve the goal "go deliver passenger", I need to do 2 steps. '
        "1. go pick up passenger. 2. go drop off passenger.",
    ]


@pytest.mark.parametrize("subgoal", ["go drop off passenger", "go pick up passenger"])
def test_taxi_can_you_insert_subgoal(subgoal: str, paper_trees: Path) -> None:
    run = LiveRun(paper_trees / "taxi-domain-tree.xml", "taxi")
    run.until("pick up passenger")
    result = answer(run.projection.tree, run.projection.state, f"Can you {subgoal}?")
    assert result.text == f"Yes. I will {subgoal} after go pick up passenger."
    assert result.insertion.source.kind == "subtree"


def test_live_insertion_runs_after_the_subgoal() -> None:
    """Asked live, "Can you insert large gear?" changes the running tree: the copy runs
    after the current subgoal and before the next one."""
    run = LiveRun(ROOT / "trees" / "kitting.xml", "kitting")
    log = EventLog()
    run.executor.subscribe(log)
    run.until("trial and error insert")
    result = answer(run.projection.tree, run.projection.state, "Can you insert large gear?")
    plan = result.insertion
    mutation = run.executor.insert_after(
        plan.parent.uid,
        plan.after.uid,
        run.executor.tree.node(plan.source.uid),
        "Can you insert large gear?",
    )
    assert run.executor.run(max_ticks=20000).name == "SUCCESS"
    tree = run.projection.tree
    assert [c.description for c in tree.root.children] == [
        "go insert large gear",
        "Sequence",
        "go pick screw",
        "go place screw",
    ]
    subgoal, copy, pick = (c.uid for c in tree.root.children[:3])
    assert copy == mutation.inserted_root_uid

    def first(uid: int, status: str) -> int:
        return next(e.seq for e in log.transitions if e.uid == uid and e.status.name == status)

    assert (
        first(subgoal, "SUCCESS")
        < first(copy, "RUNNING")
        < first(copy, "SUCCESS")
        < first(pick, "RUNNING")
    )

"""Live answers equal post-hoc answers, at every event boundary.

During a recorded run a subscriber answers every question after each event, from the
live state projection; afterwards the recording alone (MCAP → DuckDB → snapshot + tail)
must give the same answers at ``seq:N`` for every N. Random trees come from the
differential test's generator; random outcomes from hypothesis.
"""

from __future__ import annotations

from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import Subscriber
from btlog.executor.engine import Executor
from btlog.explain.questions import QUESTIONS, answer
from btlog.record.recorder import Recorder
from btlog.replay.database import open_runs
from btlog.state import StateProjection
from btlog.tree.loader import load_tree, load_tree_text
from btlog.tree.model import CONDITION
from btlog.tree.registry import NodeType, Registry
from tests.oracle.random_trees import generate

ROOT = Path(__file__).resolve().parent.parent
KITTING = ROOT / "trees" / "kitting.xml"
ASKED = [q for intent, q in QUESTIONS.items() if intent != "can"] + [
    "Can you insert large gear?",
    "Can you detect chuck?",
]


class AnswerEveryEvent(Subscriber):
    """After each event, every question's live answer (keyed by the event's seq)."""

    def __init__(self, projection: StateProjection) -> None:
        self.projection = projection
        self.answers: dict[int, list[str]] = {}

    def _record(self, seq: int) -> None:
        tree, state = self.projection.tree, self.projection.state
        self.answers[seq] = [answer(tree, state, q).text for q in ASKED]

    def on_status(self, seq, *args) -> None:
        self._record(seq)

    def on_write(self, seq, *args) -> None:
        self._record(seq)


def record_with_live_answers(tree, outcomes: Outcomes, path: Path, max_ticks: int):
    """Run and record; returns the live answers after every event."""
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes, seed=3))
    recorder = Recorder(path, tree, {"domain": "scripted"}, flush_interval=0)
    projection = StateProjection(tree)
    live = AnswerEveryEvent(projection)
    for subscriber in (recorder, projection, live):
        executor.subscribe(subscriber)
    executor.run(max_ticks)
    executor.close()
    return live.answers


def assert_post_hoc_equals_live(path: Path, live: dict[int, list[str]]) -> None:
    database = open_runs(path, cache=False)
    try:
        run = database.run(str(path))
        for seq, expected in live.items():
            tree, state = run.state_at(f"seq:{seq}")
            assert [answer(tree, state, q).text for q in ASKED] == expected, f"seq {seq}"
    finally:
        database.close()


outcome = st.sampled_from(["SUCCESS", "FAILURE"])
entry = st.fixed_dictionaries({"status": outcome, "ticks": st.integers(0, 3)})
names = [
    "move to see chuck",
    "lift torso",
    "look at chuck roughly",
    "detect chuck",
    "look at chuck",
    "scan scene for collision avoidance",
    "retreat arm",
    "trial and error insert",
    "check if grasped",
    "grasp screw",
]


@settings(
    max_examples=8,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(st.dictionaries(st.sampled_from(names), st.lists(entry, min_size=1, max_size=3), max_size=4))
def test_kitting_live_equals_post_hoc(tmp_path_factory, scripts) -> None:
    tree = load_tree(KITTING)
    outcomes = Outcomes.from_mapping(
        {"default": {"status": "SUCCESS", "ticks": 1}, "nodes": scripts}
    )
    path = tmp_path_factory.mktemp("live") / "run.mcap"
    live = record_with_live_answers(tree, outcomes, path, max_ticks=400)
    assert live
    assert_post_hoc_equals_live(path, live)


@settings(
    max_examples=12,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(st.integers(0, 10_000))
def test_random_trees_live_equals_post_hoc(tmp_path_factory, seed) -> None:
    case = generate(seed)
    registry = Registry()
    registry.register(NodeType("ScriptedCondition", CONDITION, declared_only=True))
    tree = load_tree_text(case.xml, registry)
    path = tmp_path_factory.mktemp("random") / "run.mcap"
    live = record_with_live_answers(
        tree, Outcomes.from_mapping(case.outcomes), path, case.max_ticks
    )
    assert_post_hoc_equals_live(path, live)

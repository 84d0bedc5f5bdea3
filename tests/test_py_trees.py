"""py_trees runs recorded and explained (``btlog.sources.py_trees``): the statuses btlog
replays after every tick are the live tree's, pre-emption included; blackboard writes,
subtree changes and the clock are recorded; live answers equal post-hoc ones."""

from __future__ import annotations

from pathlib import Path

import py_trees
import pytest
from py_trees.common import Status as PtStatus

from btlog.events import BlackboardWrite, TreeMutation
from btlog.record.reader import open_recording as read_recording
from btlog.sources.py_trees import record
from btlog.status import IDLE, RUNNING, SUCCESS
from tests.py_trees_support import (
    Seen,
    assert_replay_equals_live,
    questions_about,
    tick_and_watch,
)


def preemption_tree() -> py_trees.trees.BehaviourTree:
    """A Selector(memory=False) whose higher priority succeeds on its 4th tick, while
    the lower priority's child is RUNNING: that child is pre-empted without a visit."""
    high = py_trees.behaviours.StatusQueue(
        "battery low", queue=[PtStatus.FAILURE] * 3, eventually=PtStatus.SUCCESS
    )
    work = py_trees.composites.Sequence("work", memory=True)
    work.add_children([py_trees.behaviours.Success("pick"), py_trees.behaviours.Running("place")])
    root = py_trees.composites.Selector("root", memory=False)
    root.add_children([high, work])
    return py_trees.trees.BehaviourTree(root)


def test_preempted_child_is_recorded_and_replayed(tmp_path: Path) -> None:
    tree = preemption_tree()
    path = tmp_path / "run.mcap"
    asked = questions_about(["place", "battery low"])
    seen = Seen()
    with record(tree, path) as recorder:
        tick_and_watch(tree, recorder, 5, asked, seen)
        live = recorder.answer("What are you doing?").text
    assert recorder.result is not None and recorder.result.ticks == 5
    recording = read_recording(path)
    names = {n.uid: n.name for n in recording.tree}
    preempted = [
        e
        for e in recording.transitions
        if names[e.uid] == "place" and e.prev is RUNNING and e.status is IDLE
    ]
    assert [e.tick for e in preempted] == [4]
    assert seen.statuses[3][1] is SUCCESS and seen.statuses[3][5] is IDLE
    assert "battery low" in live
    assert_replay_equals_live(path, seen, asked)
    # the tree is as it was: its own classes, no recorder in its way
    assert type(tree.root) is py_trees.composites.Selector
    assert "tick" not in tree.__dict__


def test_tree_structure_maps_to_btlog_types(tmp_path: Path) -> None:
    tree = preemption_tree()
    with record(tree, tmp_path / "run.mcap"):
        tree.tick()
    recording = read_recording(tmp_path / "run.mcap")
    nodes = {n.name: n for n in recording.tree}
    assert (nodes["root"].type, nodes["root"].kind) == ("ReactiveFallback", "control")
    assert nodes["root"].attributes["py_trees"] == "Selector"
    assert nodes["work"].type == "Sequence"
    assert (nodes["place"].type, nodes["place"].kind) == ("Running", "action")


def test_blackboard_writes_with_writer_and_bounded_values(tmp_path: Path) -> None:
    py_trees.blackboard.Blackboard.clear()
    setter = py_trees.behaviours.SetBlackboardVariable(
        "set goal", variable_name="goal", variable_value={"x": 1.5}, overwrite=True
    )
    check = py_trees.behaviours.CheckBlackboardVariableValue(
        "goal set",
        check=py_trees.common.ComparisonExpression("goal", {"x": 1.5}, lambda a, b: a == b),
    )
    root = py_trees.composites.Sequence("root", memory=False, children=[setter, check])
    tree = py_trees.trees.BehaviourTree(root)
    outside = py_trees.blackboard.Client(name="program")
    outside.register_key("blob", access=py_trees.common.Access.WRITE)
    path = tmp_path / "run.mcap"
    with record(tree, path):
        outside.blob = object()
        tree.tick()
    recording = read_recording(path)
    writes = [e for e in recording.events if isinstance(e, BlackboardWrite)]
    by_key = {w.key: w for w in writes}
    assert by_key["/goal"].value == {"x": 1.5}
    uids = {n.name: n.uid for n in recording.tree}
    assert by_key["/goal"].writer_uid == uids["set goal"]
    assert by_key["/blob"].writer_uid is None
    assert by_key["/blob"].value.startswith("<object object at")
    assert by_key["/blob"].type == "object"
    nodes = {n.name: n for n in recording.tree}
    assert nodes["goal set"].kind == "condition"
    assert py_trees.blackboard.Blackboard.activity_stream is None


def test_simulated_clock_and_mutations(tmp_path: Path) -> None:
    now = [100.0]
    tree = preemption_tree()
    path = tmp_path / "run.mcap"
    with record(tree, path, clock=lambda: now[0]) as recorder:
        tree.tick()
        now[0] += 0.5
        extra = py_trees.behaviours.Success("charge")
        tree.insert_subtree(extra, tree.root.id, 1)
        tree.tick()
        now[0] += 0.5
        tree.prune_subtree(extra.id)
        tree.tick()
        assert "charge" not in [n.name for n in recorder.history.tree]  # type: ignore[union-attr]
    recording = read_recording(path)
    mutations = [e for e in recording.events if isinstance(e, TreeMutation)]
    ops = [(m.op, m.nodes[0]["name"]) for m in mutations]
    assert ops == [("insert", "charge"), ("prune", "charge")]
    assert [t.start_ns for t in recording.ticks] == [0, 500_000_000, 1_000_000_000]
    assert recording.metadata["clock"] == "sim"


def test_children_changed_on_composites_are_mutations(tmp_path: Path) -> None:
    """add_child, insert_child, remove_child, replace_child and remove_all_children on a
    composite, called during the run without the tree's API (here by a pre-tick
    handler), are recorded as mutations, and what the new behaviours do is recorded like
    the rest."""
    seq = py_trees.composites.Sequence("work", memory=False)
    seq.add_child(py_trees.behaviours.Success("first"))
    late = py_trees.composites.Selector("late", memory=False)
    go = py_trees.behaviours.Running("go")
    late.add_children([py_trees.behaviours.Failure("no"), go])

    def grow() -> None:
        seq.add_child(late)
        seq.insert_child(py_trees.behaviours.Success("early"), 0)

    def swap() -> None:
        seq.replace_child(seq.children[0], py_trees.behaviours.Success("earlier"))
        late.remove_child(late.children[0])

    steps = [lambda: None, grow, swap, lambda: seq.remove_all_children()]
    tree = py_trees.trees.BehaviourTree(seq)
    tree.add_pre_tick_handler(lambda _tree: steps.pop(0)())
    path = tmp_path / "run.mcap"
    seen = Seen()
    with record(tree, path) as recorder:
        tick_and_watch(tree, recorder, 2, [], seen)
        assert seen.statuses[1][recorder.watch.uid_of(go)] == RUNNING  # inserted, ran
        tick_and_watch(tree, recorder, 2, [], seen)
        assert [n.name for n in recorder.live_history().tree] == ["work"]
    recording = read_recording(path)
    ops = [(m.op, m.nodes[0]["name"]) for m in recording.events if isinstance(m, TreeMutation)]
    assert ops == [
        ("insert", "late"),
        ("insert", "early"),
        ("prune", "early"),
        ("insert", "earlier"),
        ("prune", "no"),
        ("prune", "earlier"),
        ("prune", "first"),
        ("prune", "late"),
    ]
    assert_replay_equals_live(path, seen, [])
    assert "add_child" not in vars(seq) and "stop" not in vars(seq)  # given back


def test_a_status_set_behind_py_trees_back_is_found_at_the_tick_end(tmp_path: Path) -> None:
    """A behaviour that writes ``self.status`` itself (py_trees says not to) still
    leaves the recorded state equal to the tree's after every tick."""

    class Stubborn(py_trees.behaviour.Behaviour):
        def update(self) -> PtStatus:
            self.status = PtStatus.FAILURE  # undone by tick(): the tick's result wins
            return PtStatus.RUNNING

    class Meddler(py_trees.behaviour.Behaviour):
        def update(self) -> PtStatus:
            stubborn.status = PtStatus.SUCCESS  # another behaviour's status, no stop()
            return PtStatus.SUCCESS

    stubborn = Stubborn("stubborn")
    root = py_trees.composites.Parallel(
        "both", policy=py_trees.common.ParallelPolicy.SuccessOnAll(), children=[stubborn]
    )
    root.add_child(Meddler("meddler"))
    tree = py_trees.trees.BehaviourTree(root)
    path = tmp_path / "run.mcap"
    seen = Seen()
    with record(tree, path) as recorder:
        tick_and_watch(tree, recorder, 3, [], seen)
    assert recorder.swept == 3
    assert_replay_equals_live(path, seen, [])


@pytest.mark.parametrize("answers", [True, False])
def test_answers_need_the_live_history(tmp_path: Path, answers: bool) -> None:
    tree = preemption_tree()
    with record(tree, tmp_path / "run.mcap", answers=answers) as recorder:
        tree.tick()
        if answers:
            assert recorder.answer("What are you doing?").text
        else:
            with pytest.raises(RuntimeError):
                recorder.answer("What are you doing?")

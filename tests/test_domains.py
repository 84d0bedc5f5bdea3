"""The simulated domains: data flowing through ports, the Taxi world, failures."""

from __future__ import annotations

from pathlib import Path

from btlog.domains import make_domain
from btlog.domains.outcomes import FailSpec, Outcomes
from btlog.domains.taxi_world import default_world
from btlog.events import BlackboardWrite, EventLog
from btlog.executor.engine import Executor
from btlog.status import FAILURE, SUCCESS
from btlog.tree.loader import load_tree

ROOT = Path(__file__).resolve().parent.parent


def run(tree_file: str, domain: str, outcomes: Outcomes | None = None, seed: int = 0):
    """Run a tree in a domain; returns (tree, executor, final status, event log)."""
    tree = load_tree(ROOT / "trees" / tree_file)
    leaves = make_domain(domain, seed).leaf_factory(tree, outcomes or Outcomes())
    executor = Executor(tree, leaf_factory=leaves)
    log = EventLog()
    executor.subscribe(log)
    status = executor.run(max_ticks=20_000)
    return tree, executor, status, log


def writes(log: EventLog, tree, key: str) -> list[tuple[str, object]]:
    """(writer description, value) of every write of ``key``."""
    return [
        (tree.node(e.writer_uid).description, e.value)
        for e in log.events
        if isinstance(e, BlackboardWrite) and e.key == key
    ]


def test_kitting_poses_flow_through_ports() -> None:
    tree, executor, status, log = run("kitting.xml", "kitting", seed=4)
    assert status is SUCCESS
    ((detector, pose),) = writes(log, tree, "object pose")[:1]
    assert detector == "detect chuck"
    ((converter, insertion),) = writes(log, tree, "insertion pose")
    assert converter == "convert to insertion pose"
    assert insertion["x"] == round(pose["x"] - 0.05, 4)
    assert insertion["z"] == round(pose["z"] + 0.02, 4)
    scope = next(
        e.scope for e in log.events if isinstance(e, BlackboardWrite) and e.key == "insertion pose"
    )
    assert scope == "go insert large gear::2"
    assert executor.blackboards()[scope]["insertion pose"] == insertion


def test_kitting_detection_failing_three_times_asks_for_help() -> None:
    outcomes = Outcomes()
    outcomes.failures = [FailSpec("detect chuck", n) for n in range(1, 4)]
    tree, _, status, log = run("kitting.xml", "kitting", outcomes)
    assert status is SUCCESS  # the subgoal's Fallback asks for help, the kit goes on
    assert not [w for w in writes(log, tree, "object pose") if w[0] == "detect chuck"]
    asked = [e for e in log.transitions if tree.node(e.uid).type == "ask" and e.status is SUCCESS]
    assert len(asked) == 1


def test_kitting_motion_without_a_pose_fails(tmp_path: Path) -> None:
    tree_file = tmp_path / "reach.xml"
    tree_file.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence name="s">'
        '<Action ID="reach" name="reach nowhere" pose="{missing}"/>'
        "</Sequence></BehaviorTree></root>"
    )
    tree = load_tree(tree_file)
    executor = Executor(tree, leaf_factory=make_domain("kitting").leaf_factory(tree, Outcomes()))
    assert executor.run(max_ticks=100) is FAILURE


def test_kitting_seeded_failure_rate_reproduces() -> None:
    outcomes = Outcomes()
    outcomes.failure_rate = 0.3
    first = run("kitting.xml", "kitting", outcomes, seed=11)[3].events
    outcomes = Outcomes()
    outcomes.failure_rate = 0.3
    second = run("kitting.xml", "kitting", outcomes, seed=11)[3].events
    assert first == second
    assert any(e.status is FAILURE for e in first if hasattr(e, "status"))


def test_taxi_drives_the_grid_and_delivers() -> None:
    tree, executor, status, log = run("taxi.xml", "taxi")
    assert status is SUCCESS
    cells = [tuple(value) for _, value in writes(log, tree, "taxi")]
    world = default_world()
    assert cells[-1] == world.destination
    assert world.passenger in cells
    assert all(not world.toll_at(cell) for cell in cells)
    assert executor.blackboards()[""]["passenger in taxi"] is False


def test_taxi_human_tree_pays_the_toll() -> None:
    tree, executor, status, log = run("taxi-human.xml", "taxi")
    assert status is SUCCESS
    cells = [tuple(value) for _, value in writes(log, tree, "taxi")]
    assert any(default_world().toll_at(cell) for cell in cells)
    optimal = run("taxi.xml", "taxi")[1].blackboards()[""]["reward"]
    assert executor.blackboards()[""]["reward"] < optimal

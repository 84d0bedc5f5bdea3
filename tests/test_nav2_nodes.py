"""Nav2's control nodes and decorators, checked against the expectations of Nav2's own
unit tests (navigation2 ``nav2_behavior_tree/test/plugins/{control,decorator}``, HEAD of
2026-08). Each test restates one of those tests' expectations as facts: a child set to a
status, the node ticked, the result and the statuses expected afterwards.

Nav2's tests drive ``DummyNode`` children whose status the test sets before each tick
(``changeStatus``); here the ``Dummy`` leaf does the same: ``set(name=STATUS)`` makes the
child report that status now and return it when ticked; ``plan`` queues results for its
next ticks (Nav2's ``RecoveryDummy``). The node under test is ticked directly, as Nav2's
tests call ``bt_node_->executeTick()``; time runs on a simulated clock.
"""

from __future__ import annotations

from typing import Any

import pytest

from btlog.events import EventLog
from btlog.executor.behavior import Behavior, NodeExecutionError
from btlog.executor.clock import SimClock
from btlog.executor.engine import Executor
from btlog.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, Status
from btlog.tree.loader import TreeError, load_tree_text
from btlog.tree.registry import Registry


class Dummy(Behavior):
    """Nav2's DummyNode: returns the status it was told to (IDLE makes parents throw)."""

    kind = "action"

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.requested: Status = IDLE
        self.plan: list[Status] = []

    def tick(self) -> Status:
        if self.plan:
            return self.plan.pop(0)
        return self.requested


class Harness:
    """One node under test, its Dummy children by name, a clock and an event log."""

    def __init__(self, body: str, period: float = 0.1) -> None:
        registry = Registry()
        registry.register_leaf(Dummy, "Dummy")
        text = f'<root BTCPP_format="4"><BehaviorTree ID="T">{body}</BehaviorTree></root>'
        self.tree = load_tree_text(text, registry)
        self.clock = SimClock(period)
        self.executor = Executor(self.tree, registry, clock=self.clock)
        self.log = EventLog()
        self.executor.subscribe(self.log)
        self.node = self.executor.root
        self.ticks = 0

    def child(self, name: str) -> Behavior:
        """The behaviour of the node named ``name``."""
        return next(b for b in self.executor.behaviors.values() if b.node.name == name)

    def set(self, **statuses: Status) -> None:
        """Nav2's changeStatus: the child's status now, and what it returns when ticked."""
        for name, status in statuses.items():
            child = self.child(name)
            assert isinstance(child, Dummy)
            child.requested = status
            if status is IDLE:
                child.reset_status()
            else:
                child.set_status(status)

    def tick(self) -> Status:
        """Advance the clock one period and tick the node under test."""
        self.ticks += 1
        self.executor.runtime.tick = self.ticks
        self.clock.start_tick(self.ticks)
        return self.node.execute_tick()

    def statuses(self, *names: str) -> list[Status]:
        """The statuses of the named nodes."""
        return [self.child(n).status for n in names]

    def transitions(self, name: str) -> list[tuple[str, str]]:
        """The logged transitions of the node named ``name``."""
        uid = self.child(name).uid
        return [(e.prev.name, e.status.name) for e in self.log.transitions if e.uid == uid]


def dummies(*names: str) -> str:
    """Dummy children."""
    return "".join(f'<Dummy name="{n}"/>' for n in names)


# -- RecoveryNode (test_recovery_node.cpp) --------------------------------------------------
def recovery(retries: int = 1) -> Harness:
    """A RecoveryNode over children ``first`` and ``second``."""
    return Harness(
        f'<RecoveryNode name="R" number_of_retries="{retries}">'
        f"{dummies('first', 'second')}</RecoveryNode>"
    )


def test_recovery_node_must_have_two_children() -> None:
    with pytest.raises(TreeError, match="RecoveryNode must have 2 children"):
        Harness(f"<RecoveryNode>{dummies('a')}</RecoveryNode>")


def test_recovery_node_running() -> None:
    h = recovery()
    h.set(first=RUNNING)
    assert h.tick() is RUNNING
    h.set(first=FAILURE, second=RUNNING)
    assert h.tick() is RUNNING


@pytest.mark.parametrize("which", ["first", "second"])
def test_recovery_node_refuses_an_idle_child(which: str) -> None:
    h = recovery()
    h.set(first=FAILURE if which == "second" else IDLE, second=IDLE)
    with pytest.raises(NodeExecutionError, match="returned IDLE"):
        h.tick()


def test_recovery_node_success_at_once_and_after_one_retry() -> None:
    h = recovery()
    h.set(first=SUCCESS)
    assert h.tick() is SUCCESS
    h.child("first").plan = [FAILURE, SUCCESS]
    h.set(second=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.node.status is SUCCESS
    assert h.statuses("first", "second") == [IDLE, IDLE]


def test_recovery_node_fails_when_the_recovery_fails_or_the_retry_fails() -> None:
    h = recovery()
    h.set(first=FAILURE, second=FAILURE)
    assert h.tick() is FAILURE
    assert h.node.status is FAILURE
    assert h.statuses("first", "second") == [IDLE, IDLE]
    h.set(first=FAILURE, second=SUCCESS)
    assert h.tick() is FAILURE  # failed, recovered, failed again: one retry allowed
    assert h.statuses("first", "second") == [IDLE, IDLE]


def test_recovery_node_skipping() -> None:
    h = recovery()
    h.set(first=SKIPPED, second=SUCCESS)
    assert h.tick() is SKIPPED
    assert h.node.status is IDLE
    assert h.statuses("first", "second") == [IDLE, IDLE]
    h.set(first=FAILURE, second=SKIPPED)
    assert h.tick() is FAILURE  # a skipped recovery means no recovery is possible
    assert h.node.status is FAILURE
    assert h.statuses("first", "second") == [IDLE, IDLE]


def test_recovery_node_logs_its_halt_before_its_result() -> None:
    """Nav2 halts the node (→IDLE) inside its tick before returning, so a retried success
    is logged RUNNING→IDLE→SUCCESS, and the recovery's success is reset at once."""
    h = recovery()
    h.child("first").plan = [FAILURE, SUCCESS]
    h.set(second=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.transitions("R") == [("IDLE", "RUNNING"), ("RUNNING", "IDLE"), ("IDLE", "SUCCESS")]
    assert h.transitions("first") == [
        ("IDLE", "FAILURE"),
        ("FAILURE", "IDLE"),
        ("IDLE", "SUCCESS"),
        ("SUCCESS", "IDLE"),
    ]
    assert h.transitions("second") == [("IDLE", "SUCCESS"), ("SUCCESS", "IDLE")]


def test_recovery_node_retries_up_to_number_of_retries() -> None:
    h = recovery(retries=3)
    h.child("first").plan = [FAILURE, FAILURE, FAILURE, FAILURE]
    h.set(second=SUCCESS)
    assert h.tick() is FAILURE
    assert h.transitions("second").count(("IDLE", "SUCCESS")) == 3


# -- PipelineSequence (test_pipeline_sequence.cpp) ------------------------------------------
def pipeline() -> Harness:
    """A PipelineSequence over three Dummy children."""
    return Harness(f"<PipelineSequence>{dummies('a', 'b', 'c')}</PipelineSequence>")


def test_pipeline_sequence_refuses_an_idle_child() -> None:
    h = pipeline()
    h.set(a=IDLE)
    with pytest.raises(NodeExecutionError):
        h.tick()


@pytest.mark.parametrize("control", ["PipelineSequence", "NonblockingSequence"])
def test_sequence_failure_halts_everything(control: str) -> None:
    """test_pipeline_sequence.cpp and test_nonblocking_sequence.cpp share these facts."""
    h = Harness(f"<{control}>{dummies('a', 'b', 'c')}</{control}>")
    for before, failing in [({}, "a"), ({"a": SUCCESS}, "b"), ({"a": SUCCESS, "b": SUCCESS}, "c")]:
        h.set(**before, **{failing: FAILURE})
        assert h.tick() is FAILURE
        assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]
    h.set(a=SUCCESS, b=SUCCESS, c=RUNNING)
    assert h.tick() is RUNNING
    h.set(a=FAILURE)
    assert h.tick() is FAILURE
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


def test_pipeline_sequence_keeps_earlier_children_running() -> None:
    h = pipeline()
    h.set(a=RUNNING, b=IDLE, c=IDLE)
    assert h.tick() is RUNNING
    h.set(a=SUCCESS, b=RUNNING, c=IDLE)
    assert h.tick() is RUNNING
    h.set(a=RUNNING, b=SUCCESS, c=RUNNING)
    assert h.tick() is RUNNING
    h.set(a=RUNNING, b=SUCCESS, c=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


def test_pipeline_sequence_skipped_children() -> None:
    h = pipeline()
    h.set(a=SKIPPED, b=SUCCESS, c=SUCCESS)
    assert h.tick() is SUCCESS
    h.set(a=SKIPPED, b=SUCCESS, c=FAILURE)
    assert h.tick() is FAILURE
    h.set(a=SKIPPED, b=SKIPPED, c=SKIPPED)
    assert h.tick() is SKIPPED
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


# -- RoundRobin (test_round_robin_node.cpp) -------------------------------------------------
def round_robin(wrap: str = "true") -> Harness:
    """A RoundRobin over three Dummy children (Nav2's fixture enables wrap_around)."""
    return Harness(f'<RoundRobin wrap_around="{wrap}">{dummies("a", "b", "c")}</RoundRobin>')


def test_round_robin_refuses_an_idle_child() -> None:
    h = round_robin()
    h.set(a=IDLE)
    with pytest.raises(NodeExecutionError):
        h.tick()


def test_round_robin_fails_when_every_child_failed() -> None:
    h = round_robin()
    h.set(a=FAILURE, b=RUNNING)
    assert h.tick() is RUNNING
    h.set(b=FAILURE, c=RUNNING)
    assert h.tick() is RUNNING
    h.set(c=FAILURE)
    assert h.tick() is FAILURE
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


def test_round_robin_resumes_after_the_last_completed_child() -> None:
    h = round_robin()
    h.set(a=RUNNING, b=IDLE, c=IDLE)
    assert h.tick() is RUNNING
    h.set(a=FAILURE, b=RUNNING, c=IDLE)
    assert h.tick() is RUNNING
    h.set(a=FAILURE, b=SUCCESS, c=IDLE)
    assert h.tick() is SUCCESS
    h.set(a=IDLE, b=IDLE, c=RUNNING)
    assert h.tick() is RUNNING  # the turn is now c's
    h.set(a=RUNNING, b=IDLE, c=FAILURE)
    assert h.tick() is RUNNING  # c failed, wraps to a
    h.set(a=FAILURE, b=SUCCESS, c=FAILURE)
    assert h.tick() is SUCCESS
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


def test_round_robin_skipped_children() -> None:
    h = round_robin()
    h.set(a=SKIPPED, b=SUCCESS, c=FAILURE)
    assert h.tick() is SUCCESS
    h.set(a=SKIPPED, b=SKIPPED, c=FAILURE)
    assert h.tick() is FAILURE
    h.set(a=SKIPPED, b=SKIPPED, c=SKIPPED)
    assert h.tick() is SKIPPED
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


def test_round_robin_without_wrap_around_stops_at_the_last_child() -> None:
    h = round_robin("false")
    h.set(a=FAILURE, b=FAILURE, c=FAILURE)
    assert h.tick() is FAILURE
    h.node.halt()
    h.set(a=SKIPPED, b=SKIPPED, c=SKIPPED)
    assert h.tick() is SKIPPED
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


def test_round_robin_without_wrap_around_fails_even_when_the_last_child_succeeds() -> None:
    """Nav2 HEAD leaves the loop before looking at the last child's result."""
    h = round_robin("false")
    h.set(a=FAILURE, b=FAILURE, c=SUCCESS)
    assert h.tick() is FAILURE


def test_round_robin_wrap_around_defaults_to_false() -> None:
    h = Harness(f"<RoundRobin>{dummies('a', 'b')}</RoundRobin>")
    h.set(a=FAILURE, b=FAILURE)
    assert h.tick() is FAILURE


# -- NonblockingSequence (test_nonblocking_sequence.cpp) -----------------------------------
def nonblocking() -> Harness:
    """A NonblockingSequence over three Dummy children."""
    return Harness(f"<NonblockingSequence>{dummies('a', 'b', 'c')}</NonblockingSequence>")


def test_nonblocking_sequence_ticks_every_child_every_tick() -> None:
    h = nonblocking()
    h.set(a=RUNNING, b=SUCCESS, c=RUNNING)
    assert h.tick() is RUNNING
    h.set(a=SUCCESS, b=SUCCESS, c=RUNNING)
    assert h.tick() is RUNNING
    h.set(a=RUNNING, b=SUCCESS, c=SUCCESS)
    assert h.tick() is RUNNING
    h.set(a=SUCCESS, b=SUCCESS, c=SUCCESS)
    assert h.tick() is SUCCESS
    h.set(a=RUNNING, b=RUNNING, c=FAILURE)
    assert h.tick() is FAILURE  # the third child is ticked although the first two run
    assert h.statuses("a", "b", "c") == [IDLE, IDLE, IDLE]


def test_nonblocking_sequence_refuses_idle_and_skipped_children() -> None:
    for status in (IDLE, SKIPPED):
        h = nonblocking()
        h.set(a=status)
        with pytest.raises(NodeExecutionError):
            h.tick()


# -- PersistentSequence (test_persistent_sequence.cpp) -------------------------------------
def test_persistent_sequence_needs_its_index() -> None:
    h = Harness("<PersistentSequence><AlwaysSuccess/></PersistentSequence>")
    with pytest.raises(NodeExecutionError, match="current_child_idx"):
        h.tick()


def test_persistent_sequence_keeps_its_index_on_the_blackboard() -> None:
    h = Harness(
        f'<PersistentSequence current_child_idx="{{idx}}">{dummies("a", "b", "c")}'
        "</PersistentSequence>"
    )
    board = h.node.blackboard
    h.set(a=RUNNING, b=RUNNING, c=RUNNING)
    board.set("idx", 0)
    assert h.tick() is RUNNING
    assert board.get("idx") == 0
    h.set(a=SUCCESS)
    assert h.tick() is RUNNING
    assert board.get("idx") == 1
    h.set(b=FAILURE)
    assert h.tick() is FAILURE
    assert board.get("idx") == 0
    board.set("idx", 1)
    h.set(a=FAILURE, b=SKIPPED, c=RUNNING)
    assert h.tick() is RUNNING
    assert board.get("idx") == 2
    h.set(c=SUCCESS)
    assert h.tick() is SUCCESS
    assert board.get("idx") == 0


# -- PauseResumeController (test_pause_resume_controller.cpp) ------------------------------
def pause_resume(children: str) -> Harness:
    """A PauseResumeController whose service calls are blackboard entries pause/resume."""
    return Harness(
        f'<PauseResumeController name="P" pause_service_name="pause" '
        f'resume_service_name="resume">{children}</PauseResumeController>'
    )


def test_pause_resume_controller_needs_one_to_four_children() -> None:
    with pytest.raises(TreeError):
        pause_resume("")


def test_pause_resume_controller_with_only_the_resumed_child() -> None:
    h = pause_resume(dummies("resumed"))
    board = h.node.blackboard
    controller = h.node
    h.set(resumed=RUNNING)
    assert h.tick() is RUNNING
    assert controller.state == "RESUMED"
    board.set("pause", True)
    assert h.tick() is RUNNING
    assert controller.state == "PAUSED"
    assert board.get("pause") is False  # the call was consumed
    assert h.tick() is RUNNING
    assert controller.state == "PAUSED"
    board.set("resume", True)
    assert h.tick() is RUNNING
    assert controller.state == "RESUMED"
    assert h.tick() is RUNNING
    assert controller.state == "RESUMED"


def test_pause_resume_controller_runs_its_transient_children() -> None:
    h = pause_resume(dummies("resumed", "paused", "on_pause", "on_resume"))
    board = h.node.blackboard
    controller = h.node
    h.set(resumed=RUNNING, paused=RUNNING, on_pause=RUNNING, on_resume=RUNNING)
    assert h.tick() is RUNNING
    assert controller.state == "RESUMED"
    board.set("pause", True)
    assert h.tick() is RUNNING
    assert controller.state == "ON_PAUSE"
    h.set(on_pause=SUCCESS)
    assert h.tick() is RUNNING
    assert controller.state == "PAUSED"
    h.set(paused=SUCCESS)
    assert h.tick() is RUNNING  # only the RESUMED child's success ends the node
    assert controller.state == "PAUSED"
    h.set(paused=SKIPPED)
    assert h.tick() is RUNNING
    assert controller.state == "PAUSED"
    board.set("pause", True)
    assert h.tick() is RUNNING  # already paused: the call is refused
    assert controller.state == "PAUSED"
    board.set("resume", True)
    h.set(on_resume=FAILURE)
    assert h.tick() is FAILURE
    h.node.halt()
    assert h.tick() is RUNNING
    assert controller.state == "RESUMED"
    h.set(resumed=SUCCESS)
    assert h.tick() is SUCCESS
    board.set("resume", True)
    assert h.tick() is SUCCESS  # not paused: the call is refused
    assert controller.state == "RESUMED"


# -- decorators ---------------------------------------------------------------------------
def test_rate_controller_ticks_its_child_once_per_period() -> None:
    """test_rate_controller.cpp: a tick every 0.5 s at 1 Hz alternates RUNNING/SUCCESS."""
    h = Harness(f'<RateController hz="1.0">{dummies("child")}</RateController>', period=0.5)
    assert h.node.status is IDLE
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.statuses("child") == [IDLE]
    for i in range(10):
        h.set(child=SUCCESS)
        if i % 2:
            assert h.tick() is SUCCESS
            assert h.statuses("child") == [IDLE]
        else:
            assert h.tick() is RUNNING


def test_rate_controller_default_rate_is_ten_hz() -> None:
    h = Harness(f"<RateController>{dummies('child')}</RateController>", period=0.1)
    h.set(child=SUCCESS)
    assert [h.tick() for _ in range(3)] == [SUCCESS, SUCCESS, SUCCESS]


def test_distance_controller_ticks_its_child_every_metre() -> None:
    """test_distance_controller.cpp: the robot moves 0.51 m per tick; the child is ticked
    on every second tick."""
    h = Harness(f'<DistanceController distance="1.0">{dummies("child")}</DistanceController>')
    board = h.node.blackboard
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.statuses("child") == [IDLE]
    for i in range(1, 21):
        board.set("robot_pose", {"pose": {"position": {"x": i * 0.51, "y": 0.0}}})
        h.set(child=SUCCESS)
        if i % 2:
            assert h.tick() is RUNNING
        else:
            assert h.tick() is SUCCESS
            assert h.statuses("child") == [IDLE]


def test_goal_updated_controller_ticks_its_child_when_the_goal_changes() -> None:
    h = Harness(f"<GoalUpdatedController>{dummies('child')}</GoalUpdatedController>")
    board = h.node.blackboard
    assert h.node.status is IDLE
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.statuses("child") == [IDLE]
    board.set("goal", {"header": {"stamp": {"sec": 5}}})
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.tick() is RUNNING  # no update: the child is not ticked
    assert h.statuses("child") == [IDLE]
    board.set("goals", {"goals": [{"header": {"stamp": {"sec": 5}}}]})
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS


def test_single_trigger_runs_its_child_once_per_activation() -> None:
    h = Harness(f"<SingleTrigger>{dummies('child')}</SingleTrigger>")
    assert h.node.status is IDLE
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.statuses("child") == [IDLE]
    assert h.tick() is FAILURE
    h.set(child=IDLE)
    assert h.tick() is FAILURE
    h.node.halt()
    h.set(child=RUNNING)
    assert h.tick() is RUNNING
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS
    assert h.tick() is FAILURE


def test_speed_controller_scales_its_period_with_the_speed() -> None:
    """test_speed_controller.cpp: 1 s ticks; at 0.223 m/s the period becomes ~2.2 s, at
    0 m/s 10 s (min_rate 0.1 .. max_rate 1.0 over 0 .. 0.5 m/s)."""
    h = Harness(
        '<SpeedController min_rate="0.1" max_rate="1.0" min_speed="0.0" max_speed="0.5">'
        f"{dummies('child')}</SpeedController>",
        period=1.0,
    )
    board = h.node.blackboard
    board.set("goal", {"header": {"stamp": {"sec": 1}}})
    board.set("robot_speed", 0.223)
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS  # t=0: the first tick
    assert h.statuses("child") == [IDLE]
    h.clock.t_ns = 500_000_000  # half a period later
    assert h.node.execute_tick() is RUNNING
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS  # t=1: the period passed; the next is 1/0.5014 s
    board.set("robot_speed", 0.0)
    assert h.tick() is RUNNING  # t=2
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS  # t=3: period ~2.02 s passed; the next is 10 s
    assert [h.tick() for _ in range(9)] == [RUNNING] * 9  # t=4..12
    h.set(child=SUCCESS)
    assert h.tick() is SUCCESS  # t=13


def test_goal_updater_outputs_the_newest_goal() -> None:
    body = (
        '<GoalUpdater input_goal="{goal}" input_goals="{goals}" output_goal="{updated_goal}"'
        ' output_goals="{updated_goals}"><AlwaysSuccess/></GoalUpdater>'
    )
    goal = {"header": {"stamp": {"sec": 10}}, "pose": {"position": {"x": 1.0}}}
    goals = {"header": {"stamp": {"sec": 10}}, "goals": [goal]}
    older = {"header": {"stamp": {"sec": 9}}, "pose": {"position": {"x": 2.0}}}
    newer = {"header": {"stamp": {"sec": 11}}, "pose": {"position": {"x": 3.0}}}
    for received, expected in [(None, goal), (older, goal), (newer, newer)]:
        h = Harness(body)
        board = h.node.blackboard
        board.set("goal", goal)
        board.set("goals", goals)
        if received is not None:
            board.set("goal_update", received)
            board.set("goals_update", {"header": received["header"], "goals": [received]})
        assert h.tick() is SUCCESS
        assert board.get("updated_goal") == expected
        assert board.get("updated_goals")["goals"] == [expected]


def test_path_longer_on_approach() -> None:
    body = (
        '<PathLongerOnApproach path="{path}" prox_len="{prox}" length_factor="{factor}">'
        "<AlwaysFailure/></PathLongerOnApproach>"
    )

    def path(count: int, step: float, start: int = 0) -> list[dict]:
        return [{"pose": {"position": {"x": step * i}}} for i in range(start, start + count)]

    h = Harness(body)
    board = h.node.blackboard
    board.set("prox", 5.0)
    board.set("factor", 2.0)
    board.set("path", path(10, 1.5))
    assert h.tick() is SUCCESS  # a first path never ticks the child
    h = Harness(body)
    board = h.node.blackboard
    board.set("prox", 20.0)
    board.set("factor", 1.0)
    board.set("path", path(5, 3.0, start=1))  # 3 .. 15 m, 12 m long
    assert h.tick() is SUCCESS
    board.set("path", path(11, 1.5))  # 0 .. 15 m, same goal, 15 m long
    assert h.tick() is FAILURE  # the child (AlwaysFailure) was ticked


def test_every_nav2_control_and_decorator_is_registered() -> None:
    registry = Registry()
    names = [
        "RecoveryNode",
        "PipelineSequence",
        "RoundRobin",
        "NonblockingSequence",
        "PersistentSequence",
        "PauseResumeController",
        "RateController",
        "DistanceController",
        "SpeedController",
        "GoalUpdatedController",
        "GoalUpdater",
        "SingleTrigger",
        "PathLongerOnApproach",
    ]
    assert all(registry.get(n) is not None and not registry.get(n).declared_only for n in names)

"""Nav2's decorators (``nav2_behavior_tree/plugins/decorator``), each with Nav2's policy.

Most of them gate their child: while the gate is shut they return their own status
(RUNNING, set at the start of the tick) without ticking the child, and a RUNNING child is
always ticked. "Active" is BT.CPP's ``isStatusActive``: neither IDLE nor SKIPPED, so a
decorator that returned SUCCESS keeps its timer until its parent resets it.

What Nav2 reads from ROS is read from the executor and the blackboard instead:

- time (RateController, SpeedController): the executor's clock;
- the robot's pose (DistanceController): the blackboard entry ``robot_pose`` —
  ``{"x": .., "y": ..}``, ``[x, y]`` or a PoseStamped-like ``{"pose": {"position": ..}}``;
  a robot with no such entry stands at the origin;
- the robot's speed (SpeedController): the entry ``robot_speed`` in m/s (default 0);
- goal updates (GoalUpdater): the entries ``goal_update`` and ``goals_update``, the
  latest message received on Nav2's topics of those names.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

from btlog.executor.behavior import Behavior, DecoratorBehavior
from btlog.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, Status


def _active(status: Status) -> bool:
    return status is not IDLE and status is not SKIPPED


class _Gated(DecoratorBehavior):
    """Shared shape of Nav2's rate-limiting decorators: tick the child on the first tick
    of an activation, while it runs, or when ``due()``; otherwise return RUNNING."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.first = False
        self.start_ns = 0

    def tick_child(self) -> Status:
        """Tick the child (the gate is open)."""
        self.first = False
        return self.child.execute_tick()

    def gate_open(self, due: bool) -> bool:
        """True on the first tick, while the child runs, or when ``due``."""
        return self.first or self.child.status is RUNNING or due

    def elapsed(self) -> float:
        """Seconds of the executor's clock since the timer started."""
        return (self.runtime.clock.now_ns() - self.start_ns) / 1e9


class RateController(_Gated):
    """Tick the child at most at ``hz``: on the first tick, while it runs, or when a
    period has passed since the activation began or the child last succeeded."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.period = 1.0

    def tick(self) -> Status:
        if not _active(self.status):
            self.period = 1.0 / self.get_input("hz", "float")
            self.start_ns = self.runtime.clock.now_ns()
            self.first = True
        self.set_status(RUNNING)
        if not self.gate_open(self.elapsed() >= self.period):
            return self.status
        result = self.tick_child()
        if result is SUCCESS:
            self.start_ns = self.runtime.clock.now_ns()
        return result


def position(value: Any) -> tuple[float, float, float]:
    """The (x, y, z) of a pose given as a mapping, a PoseStamped-like mapping or a list."""
    if isinstance(value, dict):
        inner = value.get("pose", value)
        if isinstance(inner, dict) and "position" in inner:
            inner = inner["position"]
        if isinstance(inner, dict):
            return (
                float(inner.get("x", 0.0)),
                float(inner.get("y", 0.0)),
                float(inner.get("z", 0.0)),
            )
    if isinstance(value, list | tuple):
        padded = [float(v) for v in value[:3]] + [0.0] * (3 - min(len(value), 3))
        return padded[0], padded[1], padded[2]
    raise ValueError(f"not a pose: {value!r}")


class DistanceController(_Gated):
    """Tick the child on the first tick, while it runs, or once the robot has travelled
    ``distance`` metres (straight line) from where the last success left it."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start_pose = (0.0, 0.0, 0.0)

    def _pose(self) -> tuple[float, float, float]:
        if not self.blackboard.exists("robot_pose"):
            return (0.0, 0.0, 0.0)
        return position(self.blackboard.get("robot_pose"))

    def tick(self) -> Status:
        if not _active(self.status):
            self.start_pose = self._pose()
            self.first = True
        self.set_status(RUNNING)
        travelled = math.dist(self.start_pose, self._pose())
        if not self.gate_open(travelled >= self.get_input("distance", "float")):
            return self.status
        result = self.tick_child()
        if result is SUCCESS:
            self.start_pose = self._pose()
            return SUCCESS
        return FAILURE if result is FAILURE else result


def _input_or_blackboard(node: Behavior, name: str) -> Any:
    """Nav2's getInputOrBlackboard: the port when set, else the blackboard entry ``name``."""
    if name in node.node.ports and node.node.ports[name].value.strip():
        return node.get_input(name)
    return node.blackboard.get(name) if node.blackboard.exists(name) else None


class _GoalWatcher(_Gated):
    """Remembers ``goal`` and ``goals`` (port or blackboard) to notice a new goal."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.goals: tuple[Any, Any] = (None, None)

    def current_goals(self) -> tuple[Any, Any]:
        """The goal and goals now."""
        return _input_or_blackboard(self, "goal"), _input_or_blackboard(self, "goals")


class GoalUpdatedController(_GoalWatcher):
    """Tick the child on the first tick, while it runs, or when the goal changed."""

    def tick(self) -> Status:
        if not _active(self.status):
            self.goals = self.current_goals()
            self.first = True
        self.set_status(RUNNING)
        now = self.current_goals()
        if now != self.goals:
            self.goals = now
            self.first = True
        if not self.gate_open(False):
            return self.status
        return self.tick_child()


class SpeedController(_GoalWatcher):
    """Tick the child at a rate scaled with the robot's speed, between ``min_rate`` (at
    ``min_speed``) and ``max_rate`` (at ``max_speed``); a new goal restarts at
    ``max_rate``. The period is re-scaled each time it elapses."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.period = 1.0

    def _scaled_rate(self, speed: float) -> float:
        min_rate, max_rate = (self.get_input(p, "float") for p in ("min_rate", "max_rate"))
        min_speed, max_speed = (self.get_input(p, "float") for p in ("min_speed", "max_speed"))
        rate = (speed - min_speed) / (max_speed - min_speed) * (max_rate - min_rate) + min_rate
        return max(min(rate, max_rate), min_rate)

    def _restart(self) -> None:
        self.period = 1.0 / self.get_input("max_rate", "float")
        self.start_ns = self.runtime.clock.now_ns()
        self.first = True

    def tick(self) -> Status:
        if not _active(self.status):
            self.goals = self.current_goals()
            self._restart()
        now = self.current_goals()
        if now != self.goals:
            self._restart()
            self.goals = now
        self.set_status(RUNNING)
        elapsed = self.elapsed()
        if not self.gate_open(elapsed >= self.period):
            return self.status
        if elapsed >= self.period:
            board = self.blackboard
            speed = board.get("robot_speed") if board.exists("robot_speed") else 0
            self.period = 1.0 / self._scaled_rate(abs(float(speed)))
            self.start_ns = self.runtime.clock.now_ns()
        return self.tick_child()


class SingleTrigger(DecoratorBehavior):
    """Tick the child until it completes once per activation; afterwards FAILURE."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.first = True

    def tick(self) -> Status:
        if not _active(self.status):
            self.first = True
        self.set_status(RUNNING)
        if not self.first:
            return FAILURE
        result = self.child.execute_tick()
        if result is SUCCESS or result is FAILURE:
            self.first = False
        return result


def _stamp(message: Any) -> float | None:
    """A message's ``header.stamp`` in seconds (``{sec, nanosec}`` or a number), or None."""
    if not isinstance(message, dict):
        return None
    header = message.get("header")
    stamp = header.get("stamp") if isinstance(header, dict) else None
    if isinstance(stamp, dict):
        seconds = float(stamp.get("sec", 0)) + float(stamp.get("nanosec", 0)) / 1e9
    elif isinstance(stamp, int | float):
        seconds = float(stamp)
    else:
        return None
    return seconds if seconds else None


class GoalUpdater(DecoratorBehavior):
    """Write ``output_goal``/``output_goals``: the latest received update (blackboard
    ``goal_update``/``goals_update``) when it is stamped no older than the input, else
    the input; then tick the child and return its result."""

    def _choose(self, original: Any, received: Any) -> Any:
        if received is None:
            return original
        if isinstance(received, dict) and received.get("goals") == []:
            return original
        received_at = _stamp(received)
        if received_at is None:
            return original
        original_at = _stamp(original) or 0.0
        return received if received_at >= original_at else original

    def tick(self) -> Status:
        board = self.blackboard
        for port, topic in (("goal", "goal_update"), ("goals", "goals_update")):
            original = self.get_input(f"input_{port}") if self.has_port(f"input_{port}") else None
            received = board.get(topic) if board.exists(topic) else None
            if self.has_port(f"output_{port}"):
                self.set_output(f"output_{port}", self._choose(original, received))
        return self.child.execute_tick()


def _poses(path: Any) -> list[Any]:
    if isinstance(path, dict):
        return list(path.get("poses") or [])
    return list(path) if isinstance(path, list | tuple) else []


def path_length(path: Any) -> float:
    """The length of a path: a list of poses, or a mapping with ``poses``."""
    points = [position(p) for p in _poses(path)]
    return sum(math.dist(a, b) for a, b in itertools.pairwise(points))


def _same_end(old: list[Any], new: list[Any]) -> bool:
    return bool(old) and bool(new) and position(old[-1]) == position(new[-1])


class PathLongerOnApproach(DecoratorBehavior):
    """Tick the child only when, close to the goal (the old path shorter than
    ``prox_len``), a new path to the same goal (same last position, another number of
    poses) is more than ``length_factor`` times longer than the old one; otherwise
    SUCCESS. The first path to a new goal never ticks the child."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.old_path: Any = None
        self.first = False

    def tick(self) -> Status:
        new_path = self.get_input("path")
        prox_len = self.get_input("prox_len", "float")
        factor = self.get_input("length_factor", "float")
        old, new = _poses(self.old_path), _poses(new_path)
        if not self.first and not _same_end(old, new):
            self.first = True
        self.set_status(RUNNING)
        updated = _same_end(old, new) and len(old) != len(new)
        old_length = path_length(old)
        if (
            updated
            and old_length < prox_len
            and path_length(new) > factor * old_length
            and not self.first
        ):
            result = self.child.execute_tick()
            if result is SUCCESS or result is FAILURE:
                self.old_path = new_path
                self.reset_child()
            return result
        self.old_path = new_path
        self.first = False
        return SUCCESS


NAV2_DECORATORS: dict[str, type[Behavior]] = {
    "RateController": RateController,
    "DistanceController": DistanceController,
    "SpeedController": SpeedController,
    "GoalUpdatedController": GoalUpdatedController,
    "GoalUpdater": GoalUpdater,
    "SingleTrigger": SingleTrigger,
    "PathLongerOnApproach": PathLongerOnApproach,
}

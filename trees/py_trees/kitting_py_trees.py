"""The gearbox kitting task of Han et al. (THRI 2020), section 4, as a py_trees tree.

The same task as ``trees/kitting.xml`` (BehaviorTree.CPP), built from py_trees'
composites and decorators: each subgoal a ``Selector(memory=True)`` that asks a person
when its work fails, the work a ``Sequence(memory=True)``, the retries ``Retry(3)``, the
"reset arm" a ``SuccessIsFailure``. Composites and decorators the paper leaves nameless
keep py_trees' default name (their class), which btlog reads as nameless. Every step is a
``KittingStep`` that runs for ``STEP_TICKS`` ticks and succeeds, unless told to fail its
first activations; "detect chuck" and the other detections write the pose they found
to the blackboard.

Record it with ``btlog record-py trees/py_trees/kitting_py_trees.py:create_root -o
kitting.mcap --until-done``, or the failing scenario with ``:look_at_chuck_fails``.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Access, Status

#: Ticks a step takes: RUNNING, then its result.
STEP_TICKS = 2


class KittingStep(py_trees.behaviour.Behaviour):
    """A step of the task: RUNNING for ``STEP_TICKS - 1`` ticks, then SUCCESS, or
    FAILURE for its first ``failures`` activations; a step with ``writes`` sets that
    blackboard key to the pose it found."""

    def __init__(self, name: str, failures: int = 0, writes: str | None = None) -> None:
        super().__init__(name)
        self.failures = failures
        self.ticks = 0
        self.writes = writes
        if writes is not None:
            self.board = self.attach_blackboard_client(name)
            self.board.register_key(writes, access=Access.WRITE)

    def initialise(self) -> None:
        """A new activation."""
        self.ticks = 0

    def update(self) -> Status:
        """RUNNING until done, then the step's result."""
        self.ticks += 1
        if self.ticks < STEP_TICKS:
            return Status.RUNNING
        if self.failures > 0:
            self.failures -= 1
            return Status.FAILURE
        if self.writes is not None:
            self.board.set(self.writes, {"frame": "base", "x": 0.6, "y": 0.1, "z": 0.8})
        return Status.SUCCESS


class CheckGrasped(KittingStep):
    """The one check of the task: is the screw in the gripper?"""

    btlog_kind = "condition"

    def __init__(self, name: str, failures: int = 0) -> None:
        super().__init__(name, failures)

    def update(self) -> Status:
        """A check answers at once."""
        self.ticks = STEP_TICKS
        return super().update()


def _retry(child: py_trees.behaviour.Behaviour) -> py_trees.behaviour.Behaviour:
    return py_trees.decorators.Retry("Retry", child, num_failures=3)


def _reset_arm() -> py_trees.behaviour.Behaviour:
    return py_trees.decorators.SuccessIsFailure("reset arm", KittingStep("retreat arm"))


def _subgoal(
    name: str,
    move: str,
    detect: str,
    detection: list[py_trees.behaviour.Behaviour],
    work: str,
    steps: list[py_trees.behaviour.Behaviour],
    ask: str,
) -> py_trees.behaviour.Behaviour:
    """``name``: move, then detect and work (retried), else ask a person."""
    detected = py_trees.composites.Sequence(detect, memory=True, children=detection)
    working = py_trees.composites.Selector(
        work,
        memory=True,
        children=[py_trees.composites.Sequence(work, memory=True, children=steps), _reset_arm()],
    )
    attempt = py_trees.composites.Sequence("Sequence", memory=True, children=[detected, working])
    body = py_trees.composites.Sequence(
        name, memory=True, children=[_retry(KittingStep(move)), _retry(attempt)]
    )
    return py_trees.composites.Selector(name, memory=True, children=[body, KittingStep(ask)])


def create_root(fail: dict[str, int] | None = None) -> py_trees.behaviour.Behaviour:
    """The kitting tree; ``fail`` maps a step's name to how many activations fail."""
    failing = fail or {}

    def step(name: str, writes: str | None = None) -> KittingStep:
        return KittingStep(name, failing.get(name, 0), writes)

    insert = _subgoal(
        "go insert large gear",
        "move to see chuck",
        "detect chuck",
        [step("lift torso"), step("look at chuck roughly"), step("detect chuck", "object_pose")],
        "insert large gear",
        [
            step(name)
            for name in (
                "convert to insertion pose",
                "scan scene for collision avoidance",
                "attach large gear to scene",
                "look at chuck",
                "approach door",
                "prepare to insert",
                "trial and error insert",
                "remove large gear from scene",
                "back to prepare to insert",
                "back to approach for door",
                "retreat arm",
            )
        ],
        "ask unable insert large gear",
    )
    pick = _subgoal(
        "go pick screw",
        "move to screw station",
        "detect screw",
        [step("lift torso"), step("look at table"), step("detect screw", "object_pose")],
        "pick screw",
        [
            *(
                step(name)
                for name in (
                    "convert to grasp pose",
                    "scan scene for collision avoidance",
                    "look at screw",
                    "close griper slightly",
                    "approach for grasp pose",
                    "allow partial collision",
                    "reach for grasp pose",
                    "grasp screw",
                )
            ),
            CheckGrasped("check if grasped", failing.get("check if grasped", 0)),
            step("back to approach pose"),
            step("retreat arm"),
        ],
        "ask unable pick screw",
    )
    place = _subgoal(
        "go place screw",
        "move to caddy station",
        "detect screw compartment",
        [
            step("lift torso"),
            step("look at table"),
            step("detect screw compartment", "object_pose"),
        ],
        "place screw into caddy",
        [
            step(name)
            for name in (
                "convert to place pose",
                "scan scene for collision avoidance",
                "look at screw compartment",
                "approach for place pose",
                "reach for place pose",
                "release screw",
                "back to approach pose",
                "retreat arm",
            )
        ],
        "ask unable to place screw",
    )
    return py_trees.composites.Sequence(
        "build a gearbox kit", memory=True, children=[insert, pick, place]
    )


def look_at_chuck_fails() -> py_trees.behaviour.Behaviour:
    """The kitting tree in which "look at chuck" fails once (the paper's example)."""
    return create_root({"look at chuck": 1})

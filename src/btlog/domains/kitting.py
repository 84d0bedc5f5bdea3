"""The gearbox kitting task (the paper's section 4), simulated.

Every leaf type of the kitting trees is a simulated skill with a plausible duration.
Perception writes poses to the blackboard through its ``output`` port (detect chuck →
``{object pose}``); conversions read a pose and write another (convert to insertion pose
→ ``{insertion pose}``); motions read their target pose and fail if it is missing. Poses
are deterministic for a seed. Random failures come from ``--failure-rate`` and ``--fail``.
"""

from __future__ import annotations

import random

from btlog.domains.base import Domain
from btlog.domains.outcomes import Effect, Outcome, ScriptedLeaf
from btlog.executor.behavior import NodeExecutionError
from btlog.status import FAILURE, SUCCESS, Status
from btlog.tree.model import Node

#: Seconds each skill takes (types not listed take 0.5 s).
DURATIONS = {
    "move to": 4.0,
    "lift torso": 1.0,
    "look at chuck roughly": 0.8,
    "look at table": 0.8,
    "detect chuck": 1.5,
    "detect screw": 1.5,
    "detect caddy": 1.5,
    "convert to insertion pose": 0.1,
    "convert to grasp pose": 0.1,
    "scan scene": 2.0,
    "attach large gear to scene": 0.2,
    "remove large gear from scene": 0.2,
    "look at": 0.8,
    "reach": 2.0,
    "trial and error insert": 5.0,
    "retreat arm": 2.0,
    "open gripper": 0.5,
    "close gripper": 0.5,
    "allow partial collision": 0.1,
    "check grasped": 0.3,
    "ask": 1.0,
}
#: Where each detector finds its object (x, y, z in metres, map frame).
OBJECTS = {
    "detect chuck": (1.20, -0.40, 0.95),
    "detect screw": (0.85, 0.30, 0.78),
    "detect caddy": (0.60, -0.25, 0.80),
}
INSERTION_OFFSET = (-0.05, 0.0, 0.02)
#: Optional ports and the value a real skill uses when the tree leaves them out (the
#: paper's v3 trees declare no ports, so "convert to grasp pose" may come without shift_z).
OPTIONAL_PORTS = {
    "convert to grasp pose": {"shift_z": 0.0},
    "reach": {"shift_x": 0.0, "shift_y": 0.0, "shift_z": 0.0},
    "open gripper": {"position": 0.1},
}


class KittingDomain(Domain):
    """The simulated kitting task."""

    name = "kitting"

    def duration(self, node: Node) -> Outcome | None:
        seconds = DURATIONS.get(node.type, 0.5)
        return Outcome(SUCCESS, round(seconds * 1e9))

    def effect(self, node: Node) -> Effect | None:
        if node.type in OBJECTS:
            return self._detect
        if node.type in ("convert to insertion pose", "convert to grasp pose"):
            return self._convert
        if "pose" in node.ports or "where" in node.ports:
            return self._needs_pose
        return None

    def _detect(self, leaf: ScriptedLeaf, status: Status) -> Status:
        if status is not SUCCESS:
            return status
        rng = random.Random(f"{self.seed}/{leaf.uid}/{leaf.activations}")
        x, y, z = OBJECTS[leaf.node.type]
        pose = {
            "frame": "map",
            "x": round(x + rng.uniform(-0.01, 0.01), 4),
            "y": round(y + rng.uniform(-0.01, 0.01), 4),
            "z": z,
        }
        if "part" in leaf.node.ports:
            pose["part"] = leaf.get_input("part")
        leaf.set_output("output", pose)
        return SUCCESS

    def _convert(self, leaf: ScriptedLeaf, status: Status) -> Status:
        if status is not SUCCESS:
            return status
        try:
            pose = dict(leaf.get_input("from", "json"))
        except NodeExecutionError:
            return FAILURE
        if leaf.node.type == "convert to insertion pose":
            dx, dy, dz = INSERTION_OFFSET
        else:
            dx, dy, dz = 0.0, 0.0, optional_input(leaf, "shift_z")
        pose.update(
            x=round(pose["x"] + dx, 4), y=round(pose["y"] + dy, 4), z=round(pose["z"] + dz, 4)
        )
        leaf.set_output("output", pose)
        return SUCCESS

    def _needs_pose(self, leaf: ScriptedLeaf, status: Status) -> Status:
        port = "pose" if "pose" in leaf.node.ports else "where"
        try:
            leaf.get_input(port, "json")
        except NodeExecutionError:
            return FAILURE
        return status


def optional_input(leaf: ScriptedLeaf, port: str) -> float:
    """A numeric optional port: its value when the tree sets it, else the skill's default."""
    if leaf.has_port(port):
        return float(leaf.get_input(port, "float"))
    return OPTIONAL_PORTS[leaf.node.type][port]

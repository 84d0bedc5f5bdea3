"""The registry of node types: what each registration ID is and which ports it has.

BehaviorTree.CPP keeps a manifest per registration ID (its kind and its ports with
direction, type and default). btlog keeps the same declarations here for the built-in
nodes; users add their own leaves (see ``btlog.executor.leaves``), and a tree's
``<TreeNodesModel>`` adds declarations for types that have no implementation, which
then run as scripted leaves. The behaviour of each built-in type lives in the executor;
this module only declares.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

from btlog.tree.model import (
    ACTION,
    CONDITION,
    CONTROL,
    DECORATOR,
    INOUT,
    INPUT,
    OUTPUT,
    SUBTREE,
)

#: Attributes that are never ports (BT.CPP's reserved names and pre/post conditions).
PRECONDITIONS = ("_failureIf", "_successIf", "_skipIf", "_while")
POSTCONDITIONS = ("_onSuccess", "_onFailure", "_post", "_onHalted")
RESERVED = frozenset({"name", "ID", "_autoremap", *PRECONDITIONS, *POSTCONDITIONS})

#: v3 spellings accepted by the loader, mapped to their v4 registration IDs.
V3_ALIASES = {
    "RetryUntilSuccesful": "RetryUntilSuccessful",
    "SequenceStar": "SequenceWithMemory",
    "SubTreePlus": "SubTree",
}


@dataclass(frozen=True)
class PortSpec:
    """A declared port: direction, value type and default (as a string, as in XML)."""

    direction: str = INPUT
    type: str = "str"
    default: str | None = None
    description: str = ""


@dataclass(frozen=True)
class NodeType:
    """A registration ID: its kind, its ports, and for user leaves the factory to build it.

    ``children`` is the allowed number of children as (minimum, maximum or None).
    ``plugin`` marks a type btlog implements from a plugin library whose ports differ
    between its versions (Nav2's): a port btlog does not know is warned about, not refused.
    """

    id: str
    kind: str
    ports: Mapping[str, PortSpec] = field(default_factory=dict)
    factory: Callable | None = None
    children: tuple[int, int | None] = (0, 0)
    declared_only: bool = False
    plugin: bool = False

    def port_direction(self, port: str) -> str:
        """The direction of a port; undeclared ports follow the paper's convention."""
        spec = self.ports.get(port)
        if spec is not None:
            return spec.direction
        return OUTPUT if port == "output" else INPUT


def _in(type_: str = "str", default: str | None = None) -> PortSpec:
    return PortSpec(INPUT, type_, default)


def _switch_ports(cases: int) -> dict[str, PortSpec]:
    ports = {"variable": _in()}
    ports.update({f"case_{i}": _in() for i in range(1, cases + 1)})
    return ports


def _builtins() -> dict[str, NodeType]:
    many = (1, None)
    one = (1, 1)
    entry = {"entry": _in("any")}
    types = [
        NodeType("Sequence", CONTROL, children=many),
        NodeType("AsyncSequence", CONTROL, children=many),
        NodeType("SequenceWithMemory", CONTROL, children=many),
        NodeType("ReactiveSequence", CONTROL, children=many),
        NodeType("Fallback", CONTROL, children=many),
        NodeType("AsyncFallback", CONTROL, children=many),
        NodeType("ReactiveFallback", CONTROL, children=many),
        NodeType("TryCatch", CONTROL, {"catch_on_halt": _in("bool", "false")}, children=(2, None)),
        NodeType(
            "Parallel",
            CONTROL,
            {
                "success_count": _in("int", "-1"),
                "failure_count": _in("int", "1"),
                # v3 spellings
                "success_threshold": _in("int"),
                "failure_threshold": _in("int"),
            },
            children=many,
        ),
        NodeType("ParallelAll", CONTROL, {"max_failures": _in("int", "1")}, children=many),
        NodeType("IfThenElse", CONTROL, children=(2, 3)),
        NodeType("WhileDoElse", CONTROL, children=(2, 3)),
        *(
            NodeType(f"Switch{n}", CONTROL, _switch_ports(n), children=(n + 1, n + 1))
            for n in range(2, 7)
        ),
        NodeType("Inverter", DECORATOR, children=one),
        NodeType("ForceSuccess", DECORATOR, children=one),
        NodeType("ForceFailure", DECORATOR, children=one),
        NodeType("Repeat", DECORATOR, {"num_cycles": _in("int")}, children=one),
        NodeType("RetryUntilSuccessful", DECORATOR, {"num_attempts": _in("int")}, children=one),
        NodeType("KeepRunningUntilFailure", DECORATOR, children=one),
        NodeType("RunOnce", DECORATOR, {"then_skip": _in("bool", "true")}, children=one),
        NodeType("Delay", DECORATOR, {"delay_msec": _in("unsigned")}, children=one),
        NodeType("Timeout", DECORATOR, {"msec": _in("unsigned")}, children=one),
        NodeType(
            "Precondition", DECORATOR, {"if": _in(), "else": _in("status", "FAILURE")}, children=one
        ),
        *(
            NodeType(
                f"Loop{name}",
                DECORATOR,
                {
                    "queue": PortSpec(INOUT, "any"),
                    "if_empty": _in("status", "SUCCESS"),
                    "value": PortSpec(OUTPUT, item),
                },
                children=one,
            )
            for name, item in (
                ("Int", "int"),
                ("Double", "double"),
                ("String", "str"),
                ("Bool", "bool"),
            )
        ),
        NodeType("SkipUnlessUpdated", DECORATOR, entry, children=one),
        NodeType("WaitValueUpdate", DECORATOR, entry, children=one),
        NodeType("SubTree", SUBTREE, children=one),
        NodeType("AlwaysSuccess", ACTION),
        NodeType("AlwaysFailure", ACTION),
        NodeType("Script", ACTION, {"code": _in()}),
        NodeType("ScriptCondition", CONDITION, {"code": _in()}),
        NodeType(
            "SetBlackboard", ACTION, {"value": _in("any"), "output_key": PortSpec(INOUT, "str")}
        ),
        NodeType("UnsetBlackboard", ACTION, {"key": _in()}),
        NodeType("Sleep", ACTION, {"msec": _in("unsigned")}),
        NodeType("WasEntryUpdated", ACTION, entry),
    ]
    nav2 = [replace(t, plugin=True) for t in _nav2_builtins()]
    return {t.id: t for t in [*types, *nav2]}


def _nav2_builtins() -> list[NodeType]:
    """Nav2's control nodes and decorators (nav2_behavior_tree's plugins) with their ports
    and defaults as Nav2 declares them; goals, poses and paths are JSON-like values."""
    many = (1, None)
    one = (1, 1)
    goal_ports = {"goal": _in("any"), "goals": _in("any")}
    return [
        NodeType("RecoveryNode", CONTROL, {"number_of_retries": _in("int", "1")}, children=(2, 2)),
        NodeType("PipelineSequence", CONTROL, children=many),
        NodeType("RoundRobin", CONTROL, {"wrap_around": _in("bool", "false")}, children=many),
        NodeType("NonblockingSequence", CONTROL, children=many),
        NodeType(
            "PersistentSequence",
            CONTROL,
            {"current_child_idx": PortSpec(INOUT, "int")},
            children=many,
        ),
        NodeType(
            "PauseResumeController",
            CONTROL,
            {"pause_service_name": _in(), "resume_service_name": _in()},
            children=(1, 4),
        ),
        NodeType("RateController", DECORATOR, {"hz": _in("float", "10.0")}, children=one),
        NodeType(
            "DistanceController",
            DECORATOR,
            {
                "distance": _in("float", "1.0"),
                "global_frame": _in(),
                "robot_base_frame": _in(),
            },
            children=one,
        ),
        NodeType(
            "SpeedController",
            DECORATOR,
            {
                "min_rate": _in("float", "0.1"),
                "max_rate": _in("float", "1.0"),
                "min_speed": _in("float", "0.0"),
                "max_speed": _in("float", "0.5"),
                **goal_ports,
            },
            children=one,
        ),
        NodeType("GoalUpdatedController", DECORATOR, goal_ports, children=one),
        NodeType(
            "GoalUpdater",
            DECORATOR,
            {
                "input_goal": _in("any"),
                "input_goals": _in("any"),
                "output_goal": PortSpec(OUTPUT, "any"),
                "output_goals": PortSpec(OUTPUT, "any"),
            },
            children=one,
        ),
        NodeType("SingleTrigger", DECORATOR, children=one),
        NodeType(
            "PathLongerOnApproach",
            DECORATOR,
            {
                "path": _in("any"),
                "prox_len": _in("float", "3.0"),
                "length_factor": _in("float", "2.0"),
            },
            children=one,
        ),
    ]


BUILTIN_TYPES: Mapping[str, NodeType] = _builtins()


class Registry:
    """Node types by registration ID: the built-ins plus the user's own leaves."""

    def __init__(self) -> None:
        self._types: dict[str, NodeType] = dict(BUILTIN_TYPES)

    def register(self, node_type: NodeType) -> None:
        """Add or replace a node type."""
        self._types[node_type.id] = node_type

    def get(self, type_id: str) -> NodeType | None:
        """The node type for a registration ID (v3 aliases resolved), or None."""
        return self._types.get(V3_ALIASES.get(type_id, type_id))

    def __contains__(self, type_id: str) -> bool:
        return self.get(type_id) is not None

    def register_leaf(self, leaf_class: type, type_id: str | None = None) -> NodeType:
        """Register a user leaf class (SyncAction, Condition or StatefulAction subclass)
        under ``type_id``, its ``type_id`` attribute, or its class name."""
        node_type = NodeType(
            type_id or getattr(leaf_class, "type_id", None) or leaf_class.__name__,
            getattr(leaf_class, "kind", ACTION),
            dict(getattr(leaf_class, "ports", {})),
            factory=leaf_class,
        )
        self.register(node_type)
        return node_type

    def copy(self) -> Registry:
        """An independent copy (loading a tree may add its model's declarations)."""
        clone = Registry()
        clone._types = dict(self._types)
        return clone


def leaf_kind(tag: str) -> str:
    """The kind implied by a generic XML tag (``Condition`` → condition, else action)."""
    return CONDITION if tag == "Condition" else ACTION

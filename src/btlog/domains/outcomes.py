"""Scripted leaves: run any tree without code, from an outcomes file.

An outcomes file (YAML or JSON) says what each leaf does on each activation (each start
from IDLE, counted per node)::

    default: {status: SUCCESS, duration: 0.5}   # seconds RUNNING before the result
    nodes:
      "look at chuck": [FAILURE, SUCCESS]       # per activation; the last entry repeats
      "detect chuck": [{status: FAILURE, duration: 1.0}, SUCCESS]
      "check grasped": {status: SUCCESS, ticks: 3}   # RUNNING ticks instead of seconds
      "find locations": {status: SUCCESS, outputs: {num_locs: 3}}  # written on completion
    blackboard:                                 # set before the first tick, as a program does
      goal: {x: 2.0, y: 1.0}

Keys are a node's name, its type for nameless nodes, or its path. ``--fail "look at
chuck@2"`` fails that node's second activation; a failure rate fails each activation with
that probability, drawn from the run's seeded random generator. A scripted leaf behaves
as BT.CPP's StatefulActionNode; a condition with no RUNNING time completes in its tick.
An entry's ``outputs`` are written to the blackboard entries its output ports name in the
XML (``port="{key}"``) when it completes; ``blackboard`` entries are set in the root
blackboard before the first tick. Both are converted to the type the ports declare (an
``int`` port reading ``"3"`` gets 3; a value it cannot take is refused naming the line).
"""

from __future__ import annotations

import random
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from btlog import documents
from btlog.domains.halts import HaltCount, find_halt_cause, halt_warning
from btlog.executor.actions import StatefulAction
from btlog.executor.behavior import Behavior, Runtime
from btlog.executor.blackboard import Blackboard
from btlog.executor.engine import Executor
from btlog.status import FAILURE, RUNNING, SUCCESS, Status
from btlog.tree.model import CONDITION, Node, Tree
from btlog.tree.ports import PortValueError, convert

DEFAULT_ACTION = {"status": "SUCCESS", "duration": 0.5}


class OutcomesError(ValueError):
    """An outcomes file or --fail spec that cannot be used; one line naming what is wrong."""


@dataclass(frozen=True)
class Outcome:
    """One activation's script: the result, after ``duration_ns`` or ``ticks`` RUNNING,
    and the values written on output ports when it completes."""

    status: Status = SUCCESS
    duration_ns: int = 0
    ticks: int | None = None
    outputs: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class FailSpec:
    """``--fail KEY[@N]``: fail activation N (default 1) of the nodes matching KEY."""

    key: str
    activation: int = 1

    @classmethod
    def parse(cls, text: str) -> FailSpec:
        """Parse ``KEY`` or ``KEY@N``."""
        key, at, number = text.rpartition("@")
        if at and number.isdigit() and key:
            if int(number) < 1:
                raise OutcomesError(f"--fail {text!r}: activations count from 1")
            return cls(key, int(number))
        if not text.strip():
            raise OutcomesError("--fail needs a node name")
        return cls(text)

    def __str__(self) -> str:
        return self.key if self.activation == 1 else f"{self.key}@{self.activation}"


def _parse_entry(value: Any, base: Outcome) -> Outcome:
    """One entry of a script (already valid by the schema) over the default ``base``."""
    if isinstance(value, str):
        return replace(base, status=_status(value))
    outcome = base
    if "status" in value:
        outcome = replace(outcome, status=_status(value["status"]))
    if "duration" in value:
        outcome = replace(outcome, duration_ns=round(value["duration"] * 1e9), ticks=None)
    if "ticks" in value:
        outcome = replace(outcome, ticks=int(value["ticks"]), duration_ns=0)
    if "outputs" in value:
        outcome = replace(outcome, outputs=dict(value["outputs"]))
    return outcome


def _status(value: str) -> Status:
    return Status[value.strip().upper()]


@dataclass
class Outcomes:
    """A parsed outcomes file: the default, the per-key scripts, and failure overrides."""

    default: Outcome = field(default_factory=lambda: _parse_entry(DEFAULT_ACTION, Outcome()))
    condition_default: Outcome = field(default_factory=Outcome)
    scripts: dict[str, list[Any]] = field(default_factory=dict)
    failures: list[FailSpec] = field(default_factory=list)
    failure_rate: float = 0.0
    source: dict = field(default_factory=dict)
    #: Where the mapping came from (a file name, or "recorded outcomes"), and the line of
    #: each key under ``nodes`` when it is a YAML/JSON file.
    where: str = "outcomes"
    key_lines: dict[str, int] = field(default_factory=dict)
    #: ``blackboard``: root entries set before the first tick (key -> value as written)
    blackboard: dict[str, Any] = field(default_factory=dict)
    blackboard_lines: dict[str, int] = field(default_factory=dict)

    @classmethod
    def from_mapping(cls, data: Any, where: str = "outcomes") -> Outcomes:
        """Build from the mapping of an outcomes file (checked by its schema)."""
        try:
            documents.validate(data, "outcomes", where)
        except documents.DocumentError as error:
            raise OutcomesError(str(error)) from None
        data = data or {}
        outcomes = cls(source=data, where=where)
        if "default" in data:
            outcomes.default = _parse_entry(data["default"], Outcome())
            outcomes.condition_default = Outcome(outcomes.default.status)
        for key, value in (data.get("nodes") or {}).items():
            outcomes.scripts[str(key)] = value if isinstance(value, list) else [value]
        for key, value in (data.get("blackboard") or {}).items():
            outcomes.blackboard[str(key).removeprefix("@")] = value
        return outcomes

    @classmethod
    def load(cls, path: str | Path) -> Outcomes:
        """Read an outcomes file (YAML or JSON)."""
        try:
            data, lines = documents.read(path, "outcomes file")
            documents.validate(data, "outcomes", str(path), lines)
        except documents.DocumentError as error:
            raise OutcomesError(str(error)) from None
        outcomes = cls.from_mapping(data, str(path))
        outcomes.key_lines = {
            str(path_[1]): line
            for path_, line in lines.items()
            if len(path_) == 2 and path_[0] == "nodes"
        }
        outcomes.blackboard_lines = {
            str(path_[1]).removeprefix("@"): line
            for path_, line in lines.items()
            if len(path_) == 2 and path_[0] == "blackboard"
        }
        return outcomes

    def _at(self, line: int | None) -> str:
        return f"{self.where}:{line}" if line else self.where

    def check_keys(self, tree: Tree) -> None:
        """Every key and --fail key must match at least one node of the tree."""
        for key in self.scripts:
            if not tree.lookup(key):
                line = self.key_lines.get(key)
                where = f"{self.where}:{line}" if line else self.where
                raise OutcomesError(f"{where}: key {key!r} matches no node of the tree")
        for spec in self.failures:
            if not tree.lookup(spec.key):
                raise OutcomesError(f"--fail {str(spec)!r}: matches no node of the tree")

    def unapplied(self, tree: Tree, activations: dict[int, int]) -> list[str]:
        """One warning per --fail spec and per outcomes entry that no activation used,
        given how many times each node (by uid) was activated in the run: the entries of
        a script of several (a single entry is the rule for every activation, so a node
        that never ran leaves it unapplied only in name). Keys are looked up among
        execution nodes, as ``plan_for`` finds them (Nav2's RecoveryNode "FollowPath" is
        not the action it shares its name with)."""
        warnings = []

        def ran(key: str) -> tuple[int, str]:
            nodes = tree.lookup(key, leaves_only=True)  # as plan_for finds them
            most = max((activations.get(n.uid, 0) for n in nodes), default=0)
            times = "time" if most == 1 else "times"
            names = " and ".join(sorted({n.description for n in nodes}))
            return most, f"{names} ran {most} {times}"

        for spec in self.failures:
            most, story = ran(spec.key)
            if most < spec.activation:
                warnings.append(f'--fail "{spec}" never applied: {story}')
        for key, entries in self.scripts.items():
            most, story = ran(key)
            # one entry is a rule for every activation, not a script: never running it
            # leaves nothing unapplied
            if most < len(entries) and len(entries) > 1:
                line = self.key_lines.get(key)
                where = f"{self.where}:{line}" if line else self.where
                count = len(entries)
                unused = f"entry {count}" if most + 1 == count else f"entries {most + 1}-{count}"
                warnings.append(f"{where}: {key!r} {unused} never applied: {story}")
        return warnings

    def plan_for(self, node: Node, tree: Tree) -> list[Outcome]:
        """The per-activation script of a node (the last entry repeats). A condition's
        entries take no RUNNING time unless they give one. Outputs must name output ports
        the XML maps to a ``{key}``; their values are converted to the ports' types."""
        base = self.condition_default if node.kind == CONDITION else self.default
        for key in (node.path, node.name, None if node.name else node.type):
            if key and key in self.scripts and node in tree.lookup(key, leaves_only=True):
                plan = [_parse_entry(entry, base) for entry in self.scripts[key]]
                where = self._at(self.key_lines.get(key))
                return [self._typed_outputs(outcome, node, tree, where) for outcome in plan]
        return [base]

    def _typed_outputs(self, outcome: Outcome, node: Node, tree: Tree, where: str) -> Outcome:
        if not outcome.outputs:
            return outcome
        typed = {}
        for port, value in outcome.outputs.items():
            written = node.ports.get(port)
            if written is None:
                raise OutcomesError(
                    f"{where}: outputs: {node.description!r} has no port {port!r} in the tree"
                )
            if written.key is None:
                raise OutcomesError(
                    f"{where}: outputs: port {port!r} of {node.description!r} is "
                    f"{written.value!r} in the tree, not a {{key}} to write"
                )
            type_name = tree.port_types.get(node.type, {}).get(port, "any")
            typed[port] = _typed(value, type_name, f"{where}: outputs: {port!r}")
        return replace(outcome, outputs=typed)

    def typed_blackboard(self, executor: Executor) -> dict[str, Any]:
        """The ``blackboard`` entries, each converted to the type of the ports that read
        it from the root blackboard (as ``executor``'s nodes resolve their keys)."""
        types: dict[str, tuple[str, str]] = {}  # key -> (type, what reads it)
        for behavior in executor.behaviors.values():
            node = behavior.node
            declared = executor.tree.port_types.get(node.type, {})
            for name, port in node.ports.items():
                key = port.key
                if key is None or declared.get(name, "any") in UNTYPED:
                    continue
                scope, resolved, _ = behavior.blackboard.board.locate(name if key == "=" else key)
                if scope == "" and resolved in self.blackboard:
                    reader = f"port {name!r} of {node.description!r}"
                    types.setdefault(resolved, (declared[name], reader))
        typed = {}
        for key, value in self.blackboard.items():
            type_name, reader = types.get(key, ("any", ""))
            where = self._at(self.blackboard_lines.get(key))
            typed[key] = _typed(value, type_name, f"{where}: blackboard {key!r} ({reader})")
        return typed

    def forced_failures(self, node: Node, tree: Tree) -> set[int]:
        """Activations of ``node`` that --fail makes fail."""
        return {f.activation for f in self.failures if node in tree.lookup(f.key, leaves_only=True)}


#: Port types that take any value as it is.
UNTYPED = ("any", "str", "")


def _typed(value: Any, type_name: str, what: str) -> Any:
    """``value`` converted to a port's type, or OutcomesError naming ``what``."""
    if type_name in UNTYPED:
        return value
    try:
        return convert(value, type_name)
    except PortValueError as error:
        raise OutcomesError(f"{what}: {error}") from None


Effect = Callable[["ScriptedLeaf", Status], Status]


class ScriptedLeaf(StatefulAction):
    """A leaf driven by its outcomes: RUNNING for the scripted time, then the result.

    ``effect`` (from a simulated domain) runs at completion; it may write outputs and
    may change the result.
    """

    def __init__(
        self,
        node: Node,
        runtime: Runtime,
        board: Blackboard,
        plan: list[Outcome],
        forced: set[int],
        rng: random.Random | None,
        failure_rate: float,
        effect: Effect | None = None,
    ) -> None:
        super().__init__(node, runtime, board)
        self.kind = node.kind
        self.plan = plan
        self.forced = forced
        self.rng = rng
        self.failure_rate = failure_rate
        self.effect = effect
        self.activations = 0
        self.outcome = plan[0]
        self.remaining = 0
        self.deadline = 0
        self.halts = HaltCount()
        #: the executor's behaviours, to tell what halts this leaf (``watch_halts``)
        self.behaviors: Mapping[int, Behavior] | None = None

    @property
    def takes_time(self) -> bool:
        """True when an activation of its script may stay RUNNING for a while."""
        return any(o.ticks or o.duration_ns for o in self.plan)

    def on_halted(self) -> None:
        """Count the halt and what caused it (``btlog.domains.halts``)."""
        behaviors = self.behaviors
        self.halts.halted(find_halt_cause(self.node, behaviors) if behaviors else None)

    def tick(self) -> Status:
        """Conditions are evaluated afresh on every tick that finds them not RUNNING."""
        if self.kind == CONDITION and self.status is not RUNNING:
            return self.on_start()
        return super().tick()

    def on_start(self) -> Status:
        """Start an activation: take its scripted outcome (forced to FAILURE by --fail or
        the failure rate)."""
        self.activations += 1
        outcome = self.plan[min(self.activations, len(self.plan)) - 1]
        if self.activations in self.forced or (
            self.failure_rate > 0 and self.rng is not None and self.rng.random() < self.failure_rate
        ):
            outcome = replace(outcome, status=FAILURE)
        self.outcome = outcome
        if outcome.ticks:
            self.remaining = outcome.ticks
            return RUNNING
        if outcome.duration_ns > 0:
            self.deadline = self.runtime.clock.now_ns() + outcome.duration_ns
            return RUNNING
        return self._complete()

    def on_running(self) -> Status:
        if self.outcome.ticks:
            self.remaining -= 1
            if self.remaining <= 0:
                return self._complete()
            return RUNNING
        if self.runtime.clock.now_ns() >= self.deadline:
            return self._complete()
        return RUNNING

    def _complete(self) -> Status:
        status = self.outcome.status
        self.halts.finished()
        for port, value in self.outcome.outputs.items():
            self.set_output(port, value)
        if self.effect is not None:
            status = self.effect(self, status)
        return status


def watch_halts(executor: Executor) -> None:
    """Let the scripted leaves of ``executor`` tell what halts them (for ``halt_warnings``)."""
    for behavior in executor.behaviors.values():
        if isinstance(behavior, ScriptedLeaf):
            behavior.behaviors = executor.behaviors


def halt_warnings(executor: Executor) -> list[str]:
    """One warning per scripted leaf halted over and over before it finished (or that
    never finished), with what halted it and the hint that fits."""
    leaves = [b for b in executor.behaviors.values() if isinstance(b, ScriptedLeaf)]
    scripted = {leaf.uid: leaf.takes_time for leaf in leaves}
    found = (halt_warning(leaf.node, leaf.halts, scripted) for leaf in leaves)
    return [warning for warning in found if warning is not None]


def scripted_leaf_factory(
    tree: Tree,
    outcomes: Outcomes,
    seed: int | None = None,
    effects: Callable[[Node], Effect | None] | None = None,
    durations: Callable[[Node], Outcome | None] | None = None,
) -> Callable[[Node, Runtime, Blackboard], ScriptedLeaf]:
    """A ``leaf_factory`` for the executor building ``ScriptedLeaf``s from ``outcomes``.

    ``durations`` lets a domain give per-type defaults where the outcomes say nothing.
    """
    rng = random.Random(seed) if outcomes.failure_rate > 0 else None

    def factory(node: Node, runtime: Runtime, board: Blackboard) -> ScriptedLeaf:
        plan = outcomes.plan_for(node, tree)
        # A domain's durations are for actions: its conditions answer at once (BT.CPP
        # conditions never return RUNNING), unless the outcomes give one a duration.
        if (
            durations is not None
            and node.kind != CONDITION
            and plan[0] in (outcomes.default, outcomes.condition_default)
        ):
            domain_default = durations(node)
            if domain_default is not None and not _has_explicit_script(node, tree, outcomes):
                plan = [domain_default]
        return ScriptedLeaf(
            node,
            runtime,
            board,
            plan,
            outcomes.forced_failures(node, tree),
            rng,
            outcomes.failure_rate,
            effects(node) if effects is not None else None,
        )

    return factory


def _has_explicit_script(node: Node, tree: Tree, outcomes: Outcomes) -> bool:
    return any(
        key in outcomes.scripts and node in tree.lookup(key, leaves_only=True)
        for key in (node.path, node.name, node.type)
        if key
    )

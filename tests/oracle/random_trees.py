"""Random BT.CPP v4 trees with scripted leaves, for differential testing.

``generate(seed)`` returns a :class:`Case`: the XML text of a tree, the scripted outcomes of
its leaves (see :mod:`tests.oracle.scripted`) and a tick budget. The same seed always gives
the same case.

Shape of every tree::

    <root BTCPP_format="4" main_tree_to_execute="Main">
      <BehaviorTree ID="Main">
        <Sequence|SequenceWithMemory|ReactiveSequence name="main">
          <Script name="init" code="x := 0; y := 1"/>
          <SetBlackboard name="initv" value="1" output_key="v"/>
          ...random body (one or two nodes, sometimes under a Repeat or a
             KeepRunningUntilFailure named "loop")...
        </...>
      </BehaviorTree>
      <BehaviorTree ID="Sub1">...</BehaviorTree>    (one per SubTree node)
    </root>

* Every node has a unique ``name``; each ``<BehaviorTree>`` other than Main is instantiated
  exactly once, so names identify nodes in the transitions.
* Leaves: ``ScriptedAction`` / ``ScriptedCondition`` (registered by the oracle and driven by
  the outcomes), ``AlwaysSuccess``, ``AlwaysFailure``, ``Script``, ``ScriptCondition`` and
  ``SetBlackboard``.
* Blackboard: ``x`` and ``y`` are numbers used by scripts and pre/post conditions (only ``x``
  inside subtrees, where it is remapped to the parent's ``x`` or ``y``, or reached through
  ``_autoremap``); ``v`` is a string used only by ``Switch`` and ``SetBlackboard`` (a subtree
  may get a literal for it). BT.CPP 4.8.2 throws ("Can't convert string [..] to type
  [BT::Any]") on the second ``SetBlackboard`` into an entry first created by a ``Script``, so
  ``v`` is created by a ``SetBlackboard`` and never touched by scripts.
* The first child of ``IfThenElse``/``WhileDoElse`` is usually a leaf without ``_skipIf`` or
  ``_while``: BT.CPP 4.8.2 throws when that child returns SKIPPED ("Something unexpected
  happened in IfThenElseNode"; WhileDoElse tries ``setStatus(IDLE)``).
* No time-based node (Delay, Timeout, Sleep), no ``num_cycles``/``num_attempts`` of -1 (an
  endless loop inside one tick), and only Parallel thresholds that BT.CPP accepts.
"""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any

ACTION_ID = "ScriptedAction"
CONDITION_ID = "ScriptedCondition"

_LEAVES = [
    ("action", 58),
    ("condition", 13),
    ("always_success", 5),
    ("always_failure", 3),
    ("script", 9),
    ("script_condition", 7),
    ("set_blackboard", 5),
]

_COMPOSITES = [
    ("Sequence", 12),
    ("SequenceWithMemory", 6),
    ("ReactiveSequence", 7),
    ("Fallback", 10),
    ("ReactiveFallback", 6),
    ("Parallel", 6),
    ("ParallelAll", 4),
    ("IfThenElse", 5),
    ("WhileDoElse", 4),
    ("Switch2", 3),
    ("Switch3", 2),
    ("Inverter", 5),
    ("ForceSuccess", 3),
    ("ForceFailure", 3),
    ("Repeat", 4),
    ("RetryUntilSuccessful", 6),
    ("KeepRunningUntilFailure", 2),
    ("RunOnce", 3),
    ("Precondition", 4),
    ("SubTree", 4),
]

_PREFIX = {
    "action": "a",
    "condition": "c",
    "always_success": "ok",
    "always_failure": "ko",
    "script": "scr",
    "script_condition": "sc",
    "set_blackboard": "sb",
    "Sequence": "seq",
    "SequenceWithMemory": "swm",
    "ReactiveSequence": "rseq",
    "Fallback": "fb",
    "ReactiveFallback": "rfb",
    "Parallel": "par",
    "ParallelAll": "pall",
    "IfThenElse": "ite",
    "WhileDoElse": "wde",
    "Switch2": "sw",
    "Switch3": "sw",
    "Inverter": "inv",
    "ForceSuccess": "fs",
    "ForceFailure": "ff",
    "Repeat": "rep",
    "RetryUntilSuccessful": "retry",
    "KeepRunningUntilFailure": "krf",
    "RunOnce": "once",
    "Precondition": "pre",
    "SubTree": "sub",
}

_DECORATORS = {
    "Inverter",
    "ForceSuccess",
    "ForceFailure",
    "Repeat",
    "RetryUntilSuccessful",
    "KeepRunningUntilFailure",
    "RunOnce",
    "Precondition",
}

_PRE = ["_skipIf", "_successIf", "_failureIf", "_while"]
_POST = ["_onSuccess", "_onFailure", "_post"]

INIT_CODE = "x := 0; y := 1"


@dataclass
class Case:
    """One generated tree: XML, scripted outcomes and tick budget."""

    xml: str
    outcomes: dict[str, Any]
    max_ticks: int
    seed: int = 0
    node_count: int = 0
    names: list[str] = field(default_factory=list)


def _pick(rng: random.Random, weighted: list[tuple[str, int]]) -> str:
    names = [name for name, _ in weighted]
    weights = [weight for _, weight in weighted]
    return rng.choices(names, weights=weights, k=1)[0]


class _Generator:
    def __init__(self, seed: int, max_depth: int, max_children: int) -> None:
        self.rng = random.Random(seed)
        self.max_depth = max_depth
        self.max_children = max(2, max_children)
        self.counter = 0
        self.names: list[str] = []
        self.nodes_outcomes: dict[str, list[dict[str, Any]]] = {}
        self.subtrees: list[ET.Element] = []
        self.fail_first = False  # the next scripted leaf starts with failures (under a Retry)

    # -- helpers ---------------------------------------------------------------------------

    def name(self, kind: str) -> str:
        self.counter += 1
        name = f"{_PREFIX.get(kind, kind.lower())}{self.counter}"
        self.names.append(name)
        return name

    def cond_expr(self, variables: list[str]) -> str:
        rng = self.rng
        var = rng.choice(variables)
        op = rng.choice(["<", ">", "==", "!=", ">=", "<="])
        expr = f"{var} {op} {rng.randint(0, 3)}"
        if len(variables) > 1 and rng.random() < 0.15:
            other = rng.choice(variables)
            expr = f"{expr} {rng.choice(['&&', '||'])} {other} {rng.choice(['<', '>'])} 1"
        return expr

    def assign_expr(self, variables: list[str]) -> str:
        rng = self.rng
        var = rng.choice(variables)
        other = rng.choice(variables)
        return rng.choice(
            [
                f"{var} := {var} + 1",
                f"{var} += 1",
                f"{var} -= 1",
                f"{var} := 0",
                f"{var} = {var} + 2",
                f"{var} := {other} * 2",
                f"{var} := {other} - 1",
            ]
        )

    def action_outcomes(self, name: str) -> None:
        rng = self.rng
        fail_first, self.fail_first = self.fail_first, False
        if not fail_first and rng.random() < 0.2:
            return  # use the default entry
        entries = []
        for i in range(rng.choice([1, 1, 2, 2, 3])):
            p_success = 0.2 if fail_first and i < 2 else 0.72
            status = "SUCCESS" if rng.random() < p_success else "FAILURE"
            entries.append({"status": status, "ticks": rng.choice([0, 0, 1, 1, 1, 2, 2, 3, 4])})
        self.nodes_outcomes[name] = entries

    def condition_outcomes(self, name: str) -> None:
        rng = self.rng
        fail_first, self.fail_first = self.fail_first, False
        if not fail_first and rng.random() < 0.15:
            return
        entries = []
        for i in range(rng.choice([1, 1, 2, 3, 4])):
            p_success = 0.2 if fail_first and i < 2 else 0.7
            entries.append({"status": "SUCCESS" if rng.random() < p_success else "FAILURE"})
        self.nodes_outcomes[name] = entries

    def decorate(self, elem: ET.Element, variables: list[str], can_skip: bool = True) -> None:
        """Attach random pre/post-condition scripts to ``elem``."""
        rng = self.rng
        if rng.random() < 0.14:
            attr = rng.choice(_PRE if can_skip else ["_successIf", "_failureIf"])
            elem.set(attr, self.cond_expr(variables))
        if rng.random() < 0.15:
            attr = rng.choice(_POST)
            elem.set(attr, self.assign_expr(variables))

    # -- nodes -----------------------------------------------------------------------------

    def leaf(self, variables: list[str]) -> ET.Element:
        rng = self.rng
        kind = _pick(rng, _LEAVES)
        name = self.name(kind)
        if kind == "action":
            elem = ET.Element(ACTION_ID, name=name)
            self.action_outcomes(name)
        elif kind == "condition":
            elem = ET.Element(CONDITION_ID, name=name)
            self.condition_outcomes(name)
        elif kind == "always_success":
            elem = ET.Element("AlwaysSuccess", name=name)
        elif kind == "always_failure":
            elem = ET.Element("AlwaysFailure", name=name)
        elif kind == "script":
            code = self.assign_expr(variables)
            if rng.random() < 0.25:
                code += "; " + self.assign_expr(variables)
            elem = ET.Element("Script", name=name, code=code)
        elif kind == "script_condition":
            elem = ET.Element("ScriptCondition", name=name, code=self.cond_expr(variables))
        else:
            value = str(rng.randint(0, 3))
            elem = ET.Element("SetBlackboard", name=name, value=value, output_key="v")
        return elem

    def children(self, parent: ET.Element, count: int, depth: int, variables: list[str]) -> None:
        for _ in range(count):
            parent.append(self.node(depth + 1, variables))

    def node(self, depth: int, variables: list[str], force_composite: bool = False) -> ET.Element:
        rng = self.rng
        p_leaf = 1.0 if depth >= self.max_depth else min(0.9, 0.1 + 0.18 * (depth - 1))
        if not force_composite and rng.random() < p_leaf:
            elem = self.leaf(variables)
            self.decorate(elem, variables)
            return elem
        if depth <= 1:  # the body of a tree: a control node with several children
            kind = _pick(
                rng, [(k, w) for k, w in _COMPOSITES if k not in _DECORATORS and k != "SubTree"]
            )
        else:
            kind = _pick(rng, _COMPOSITES)
        if kind == "SubTree" and (len(self.subtrees) >= 3 or depth >= self.max_depth):
            kind = "Sequence"
        name = self.name(kind)
        elem = ET.Element(kind, name=name)
        n_max = self.max_children
        if kind in _DECORATORS:
            if kind == "Repeat":
                elem.set("num_cycles", str(rng.randint(1, 3)))
            elif kind == "RetryUntilSuccessful":
                elem.set("num_attempts", str(rng.choice([1, 2, 2, 3, 3])))
                self.fail_first = True
            elif kind == "RunOnce":
                elem.set("then_skip", rng.choice(["true", "false"]))
            elif kind == "Precondition":
                elem.set("if", self.cond_expr(variables))
                elem.set("else", rng.choice(["FAILURE", "FAILURE", "SUCCESS", "SKIPPED"]))
            self.children(elem, 1, depth, variables)
            self.fail_first = False
        elif kind == "SubTree":
            self.subtree(elem, depth)
        elif kind in ("IfThenElse", "WhileDoElse"):
            if rng.random() < 0.85:
                first = self.leaf(variables)
                self.decorate(first, variables, can_skip=False)
                elem.append(first)
            else:
                elem.append(self.node(depth + 1, variables))
            self.children(elem, rng.choice([1, 2]), depth, variables)
        elif kind in ("Switch2", "Switch3"):
            cases = 2 if kind == "Switch2" else 3
            roll = rng.random()
            if roll < 0.5:
                elem.set("variable", "{v}")
            elif roll < 0.8:
                elem.set("variable", "{x}")
            else:
                elem.set("variable", str(rng.randint(0, 3)))
            for i, value in enumerate(rng.sample(["0", "1", "2", "3"], cases), start=1):
                elem.set(f"case_{i}", value)
            self.children(elem, cases + 1, depth, variables)
        else:
            count = rng.randint(2 if kind == "Parallel" or depth <= 1 else 1, n_max)
            if kind == "Parallel":
                elem.set("success_count", str(self.threshold(count, default=-1)))
                elem.set("failure_count", str(self.threshold(count, default=1)))
            elif kind == "ParallelAll":
                elem.set("max_failures", str(self.threshold(count, default=1)))
            self.children(elem, count, depth, variables)
        if depth > 1:
            self.decorate(elem, variables)
        return elem

    def threshold(self, count: int, default: int) -> int:
        rng = self.rng
        if rng.random() < 0.5:
            return default
        value = rng.randint(-count, count)
        if value == 0 and rng.random() < 0.7:  # 0 completes at once: keep it rare
            value = default
        return value

    def subtree(self, elem: ET.Element, depth: int) -> None:
        """Fill the SubTree node ``elem`` and create the ``<BehaviorTree>`` it refers to."""
        rng = self.rng
        tree_id = f"Sub{len(self.subtrees) + 1}"
        elem.set("ID", tree_id)
        definition = ET.Element("BehaviorTree", ID=tree_id)
        self.subtrees.append(definition)
        roll = rng.random()
        if roll < 0.35:
            elem.set("_autoremap", "true")
        else:
            elem.set("x", "{x}" if roll < 0.75 else "{y}")
            roll = rng.random()
            if roll < 0.4:
                elem.set("v", "{v}")
            elif roll < 0.7:
                elem.set("v", str(rng.randint(0, 3)))
        definition.append(self.node(depth + 1, ["x"], force_composite=True))

    def main_tree(self) -> ET.Element:
        rng = self.rng
        root = ET.Element("root", BTCPP_format="4", main_tree_to_execute="Main")
        main = ET.SubElement(root, "BehaviorTree", ID="Main")
        kind = rng.choices(
            ["Sequence", "SequenceWithMemory", "ReactiveSequence"], weights=[6, 2, 2]
        )[0]
        top = ET.SubElement(main, kind, name="main")
        self.names.append("main")
        ET.SubElement(top, "Script", name="init", code=INIT_CODE)
        ET.SubElement(top, "SetBlackboard", name="initv", value="1", output_key="v")
        self.names += ["init", "initv"]
        parent = top
        roll = rng.random()
        if roll < 0.3:
            parent = ET.SubElement(top, "Repeat", name="loop", num_cycles=str(rng.randint(2, 4)))
        elif roll < 0.45:
            parent = ET.SubElement(top, "KeepRunningUntilFailure", name="loop")
        if parent is not top:
            self.names.append("loop")
        parent.append(self.node(1, ["x", "y"], force_composite=True))
        if parent is top and rng.random() < 0.3:
            top.append(self.node(1, ["x", "y"]))
        for definition in self.subtrees:
            root.append(definition)
        return root


def generate(seed: int, max_depth: int = 4, max_children: int = 4) -> Case:
    """Generate the random case of ``seed`` (deterministic for a given seed and sizes)."""
    gen = _Generator(seed, max_depth, max_children)
    root = gen.main_tree()
    ET.indent(root, space="  ")
    xml = ET.tostring(root, encoding="unicode")
    rng = gen.rng
    default = {"status": "SUCCESS", "ticks": rng.choice([0, 1, 1, 2])}
    outcomes = {"default": default, "nodes": gen.nodes_outcomes}
    max_ticks = rng.randint(5, 30)
    return Case(
        xml=xml,
        outcomes=outcomes,
        max_ticks=max_ticks,
        seed=seed,
        node_count=len(gen.names),
        names=list(gen.names),
    )


if __name__ == "__main__":
    import sys

    case = generate(int(sys.argv[1]) if len(sys.argv) > 1 else 0)
    print(case.xml)
    print(case.outcomes)
    print("max_ticks", case.max_ticks, "nodes", case.node_count)

"""Differential test against BehaviorTree.CPP itself.

Random trees built from the built-in nodes, with scripted leaves (stateful actions that
run k ticks, conditions), run in BT.CPP (behaviortreepy, in a subprocess: a few trees can
crash it) and in btlog; the complete sequences of (tick, node, prev, new) transitions, IDLE
resets and halts included, must be identical: up to the teardown, the tick after the last
one, in which the destroyed tree is halted (BT.CPP's destructor; btlog's ``teardown``),
for runs that complete and runs stopped by ``max_ticks`` alike.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import EventLog
from btlog.executor.engine import Executor
from btlog.tree.loader import load_tree_text
from btlog.tree.model import CONDITION
from btlog.tree.registry import NodeType, Registry
from tests.oracle.random_trees import generate
from tests.oracle.runner import have_behaviortreepy, run_oracle

CASES = int(os.environ.get("BTLOG_DIFFERENTIAL_CASES", "240"))
pytestmark = pytest.mark.skipif(not have_behaviortreepy(), reason="behaviortreepy missing")


def btlog_transitions(case) -> list[list]:
    """The transitions of the case run by btlog, in the oracle's format."""
    registry = Registry()
    registry.register(NodeType("ScriptedCondition", CONDITION, declared_only=True))
    tree = load_tree_text(case.xml, registry)
    outcomes = Outcomes.from_mapping(case.outcomes)
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    log = EventLog()
    executor.subscribe(log)
    executor.run(case.max_ticks)
    executor.teardown()
    names = {n.uid: n.name for n in tree}
    return [[e.tick, names[e.uid], e.prev.name, e.status.name] for e in log.transitions]


@pytest.fixture(scope="module")
def oracle_results():
    cases = [generate(seed) for seed in range(CASES)]
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(run_oracle, cases))
    return list(zip(cases, results, strict=True))


def test_btlog_matches_btcpp_transition_for_transition(oracle_results) -> None:
    compared, skipped, mismatches = 0, 0, []
    with_teardown = {"completed": 0, "stopped": 0}
    for case, result in oracle_results:
        if result is None or result.get("error"):
            skipped += 1
            continue
        compared += 1
        ours = btlog_transitions(case)
        theirs = result["transitions"]
        if any(t[0] == result["teardown_tick"] for t in theirs):
            with_teardown["stopped" if result["halted"] else "completed"] += 1
        if ours != theirs:
            first = next(
                (i for i, (a, b) in enumerate(zip(ours, theirs, strict=False)) if a != b),
                min(len(ours), len(theirs)),
            )
            mismatches.append(
                (
                    case.seed if hasattr(case, "seed") else "?",
                    first,
                    theirs[first : first + 3],
                    ours[first : first + 3],
                )
            )
    print(
        f"differential: {compared} trees compared, {skipped} skipped (BT.CPP crashed or "
        f"refused the tree); teardown transitions in {with_teardown}"
    )
    assert compared >= CASES * 0.9
    assert min(with_teardown.values()) > 0  # both kinds of ending have a teardown to compare
    assert not mismatches, (
        "\n".join(
            f"seed {seed}: first difference at transition {i}: BT.CPP {a} btlog {b}"
            for seed, i, a, b in mismatches[:10]
        )
        + f"\n({len(mismatches)} mismatching trees)"
    )

"""Helpers shared by the per-node tests (``tests/test_nodes_*.py``) of the executor and the
loader (btcpp-semantics.md, sections 1 and 2).

Every test runs a small XML tree whose nodes all have unique names, with scripted leaves:

- ``<ScriptedAction name="a"/>`` is a scripted leaf of ``btlog.domains.outcomes`` (BT.CPP's
  StatefulActionNode): per activation ``{status, ticks}``, RUNNING for ``ticks`` ticks;
- ``<ScriptedCondition name="c"/>`` is a condition evaluated on every tick, taking the next
  entry's status (the last entry repeats).

These are the leaves of the BT.CPP oracle (``tests/oracle``), so each tree can be run in BT.CPP
4.8.2 as well. The expected transitions ``(name, prev, new)`` per tick, IDLE resets included,
are what BT.CPP logs for the same tree; set ``BTLOG_ORACLE_CROSSCHECK=1`` to re-run every
such tree through the oracle and compare (slow: one subprocess per tree). Trees that depend
on time (Delay, Timeout, Sleep on the simulated clock) or on behaviour that differs between
BT.CPP 4.8.2 and HEAD are marked ``oracle=False``. A known difference from BT.CPP is written
as an ``xfail(strict=True)`` test naming it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import BlackboardWrite, EventLog
from btlog.executor.actions import Condition
from btlog.executor.clock import SimClock
from btlog.executor.engine import Executor
from btlog.status import Status
from btlog.tree.loader import TreeError, load_tree_text
from btlog.tree.model import Tree
from btlog.tree.registry import Registry

ROOT = Path(__file__).resolve().parent.parent
CROSSCHECK = os.environ.get("BTLOG_ORACLE_CROSSCHECK") == "1"
DEFAULT_OUTCOME = {"status": "SUCCESS", "ticks": 0}

Transition = tuple[str, str, str]


def ok(ticks: int = 0) -> dict:
    """An activation that succeeds after ``ticks`` RUNNING ticks."""
    return {"status": "SUCCESS", "ticks": ticks}


def fail(ticks: int = 0) -> dict:
    """An activation that fails after ``ticks`` RUNNING ticks."""
    return {"status": "FAILURE", "ticks": ticks}


def act(name: str, **attributes: str) -> str:
    """A scripted action element."""
    extra = "".join(f' {key}="{value}"' for key, value in attributes.items())
    return f'<ScriptedAction name="{name}"{extra}/>'


def cond(name: str) -> str:
    """A scripted condition element."""
    return f'<ScriptedCondition name="{name}"/>'


def script(name: str, code: str) -> str:
    """A Script element."""
    return f'<Script name="{name}" code="{code}"/>'


def xml(body: str, trees: str = "", fmt: str | None = "4") -> str:
    """A document whose main tree ``Main`` is ``body``; ``trees`` adds more BehaviorTrees."""
    version = f' BTCPP_format="{fmt}"' if fmt else ""
    return (
        f'<root{version} main_tree_to_execute="Main">\n'
        f'<BehaviorTree ID="Main">\n{body}\n</BehaviorTree>\n{trees}\n</root>'
    )


def condition_class(nodes: dict[str, list[dict]]) -> type[Condition]:
    """The oracle's scripted condition: one activation per tick, the next entry's status."""
    counts: dict[int, int] = {}

    class ScriptedCondition(Condition):
        """Returns the status of its next entry (the last one repeats)."""

        def check(self) -> Status:
            entries = nodes.get(self.node.name) or [DEFAULT_OUTCOME]
            count = counts.get(self.uid, 0)
            counts[self.uid] = count + 1
            return Status[entries[min(count, len(entries) - 1)]["status"]]

    return ScriptedCondition


def scripted_registry(nodes: dict[str, list[dict]]) -> Registry:
    """A registry where ``ScriptedCondition`` is the oracle's condition."""
    registry = Registry()
    registry.register_leaf(condition_class(nodes), "ScriptedCondition")
    return registry


@dataclass
class Run:
    """The outcome of one run: transitions grouped by tick, root status per tick."""

    tree: Tree
    executor: Executor
    log: EventLog
    ticks: dict[int, list[Transition]] = field(default_factory=dict)
    roots: list[str] = field(default_factory=list)

    @property
    def flat(self) -> list[list[Any]]:
        """The transitions as the oracle lists them: ``[tick, name, prev, new]``."""
        return [[tick, *t] for tick, items in self.ticks.items() for t in items]

    @property
    def board(self) -> dict[str, Any]:
        """The root blackboard's entries."""
        return self.executor.root_board.entries

    def writes(self) -> list[tuple[str, str, Any]]:
        """Every blackboard write as ``(scope, key, value)``."""
        return [
            (e.scope, e.key, e.value) for e in self.log.events if isinstance(e, BlackboardWrite)
        ]


def build(
    text: str, nodes: dict[str, list[dict]] | None = None, period: float = 0.1
) -> tuple[Tree, Executor, EventLog]:
    """Load ``text`` and build an executor with scripted leaves and an event log."""
    nodes = nodes or {}
    registry = scripted_registry(nodes)
    tree = load_tree_text(text, registry)
    outcomes = Outcomes.from_mapping({"default": DEFAULT_OUTCOME, "nodes": nodes})
    executor = Executor(
        tree, registry, clock=SimClock(period), leaf_factory=scripted_leaf_factory(tree, outcomes)
    )
    log = EventLog()
    executor.subscribe(log)
    return tree, executor, log


def collect(tree: Tree, executor: Executor, log: EventLog) -> Run:
    """Group the logged transitions by tick."""
    result = Run(tree, executor, log)
    for event in log.transitions:
        name = tree.node(event.uid).name
        result.ticks.setdefault(event.tick, []).append((name, event.prev.name, event.status.name))
    result.roots = [record.root_status.name for record in log.ticks if not record.teardown]
    return result


def run(
    body: str,
    nodes: dict[str, list[dict]] | None = None,
    *,
    trees: str = "",
    max_ticks: int = 10,
    period: float = 0.1,
    fmt: str | None = "4",
    oracle: bool = True,
) -> Run:
    """Run ``Executor.run(max_ticks)`` on the tree, then its teardown (a tick of its own
    that halts what still runs and resets every node left non-IDLE, as BT.CPP does when
    the tree is destroyed)."""
    text = xml(body, trees, fmt)
    tree, executor, log = build(text, nodes, period)
    executor.run(max_ticks)
    executor.teardown()
    result = collect(tree, executor, log)
    if CROSSCHECK and oracle:
        crosscheck(text, nodes or {}, max_ticks, result)
    return result


def crosscheck(text: str, nodes: dict, max_ticks: int, result: Run) -> None:
    """Run the same tree in BT.CPP (the oracle) and compare transitions and root statuses."""
    try:
        from tests.oracle.runner import have_behaviortreepy, run_oracle
    except ImportError:  # pragma: no cover - tests/ is not a package
        from oracle.runner import have_behaviortreepy, run_oracle  # type: ignore[no-redef]
    if not have_behaviortreepy():
        pytest.skip("behaviortreepy missing")
    outcome = run_oracle(
        {
            "xml": text,
            "max_ticks": max_ticks,
            "outcomes": {"default": DEFAULT_OUTCOME, "nodes": nodes},
        }
    )
    assert outcome is not None, "BT.CPP crashed"
    assert outcome["error"] is None, outcome["error"]
    assert outcome["transitions"] == result.flat
    assert outcome["root"] == result.roots


def load(body: str, trees: str = "", fmt: str | None = "4", **kwargs: Any) -> Tree:
    """Load a one-tree document."""
    return load_tree_text(xml(body, trees, fmt), **kwargs)


def error_of(text: str, file: str = "tree.xml") -> TreeError:
    """The TreeError raised by loading ``text``."""
    with pytest.raises(TreeError) as caught:
        load_tree_text(text, file=file)
    return caught.value

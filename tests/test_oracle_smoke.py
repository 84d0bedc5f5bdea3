"""Smoke tests of the BT.CPP oracle (tests/oracle) on small hand-written trees.

The expected sequences are what BT.CPP 4.8.2 (bundled by behaviortreepy 0.1.4) really logs;
see btcpp-semantics.md section 2. Each transition is ``[tick, name, prev, new]``.
"""

from __future__ import annotations

import pytest

try:
    from tests.oracle.random_trees import generate
    from tests.oracle.runner import have_behaviortreepy, run_oracle
    from tests.oracle.scripted import ScriptedLeaves
except ImportError:  # "tests" is not importable as a package: pytest put tests/ on sys.path
    from oracle.random_trees import generate  # type: ignore[no-redef]
    from oracle.runner import have_behaviortreepy, run_oracle  # type: ignore[no-redef]
    from oracle.scripted import ScriptedLeaves  # type: ignore[no-redef]

needs_btcpp = pytest.mark.skipif(not have_behaviortreepy(), reason="behaviortreepy missing")


def _xml(body: str) -> str:
    return (
        '<root BTCPP_format="4" main_tree_to_execute="Main">'
        f'<BehaviorTree ID="Main">{body}</BehaviorTree></root>'
    )


def _run(body: str, nodes: dict, max_ticks: int = 5, **extra: str) -> dict:
    case = {"xml": _xml(body), "outcomes": {"nodes": nodes}, "max_ticks": max_ticks, **extra}
    result = run_oracle(case)
    assert result is not None, "the oracle crashed or timed out"
    assert result["error"] is None, result["error"]
    return result


def _ok(ticks: int = 0) -> list[dict]:
    return [{"status": "SUCCESS", "ticks": ticks}]


@needs_btcpp
def test_sequence_stops_at_failing_condition() -> None:
    """Section 3's Sequence[ActOK a, CondFail c, ActOK never], with scripted leaves.

    A scripted (StatefulActionNode) action that completes in on_start logs IDLE->SUCCESS
    directly, without the IDLE->RUNNING that a SimpleActionNode would log. Children are
    reset before the parent's own result, and the root is reset after it by tickRoot.
    """
    result = _run(
        '<Sequence name="s"><ScriptedAction name="a"/><ScriptedCondition name="c"/>'
        '<ScriptedAction name="never"/></Sequence>',
        {"a": _ok(), "c": [{"status": "FAILURE"}]},
    )
    assert result["transitions"] == [
        [1, "s", "IDLE", "RUNNING"],
        [1, "a", "IDLE", "SUCCESS"],
        [1, "c", "IDLE", "FAILURE"],
        [1, "a", "SUCCESS", "IDLE"],
        [1, "c", "FAILURE", "IDLE"],
        [1, "s", "RUNNING", "FAILURE"],
        [1, "s", "FAILURE", "IDLE"],
    ]
    assert result["root"] == ["FAILURE"]
    assert result["halted"] is False


@needs_btcpp
def test_retry_retries_within_one_tick_once() -> None:
    """RetryUntilSuccessful retries a synchronously failing child inside one tick_once.

    In BT.CPP 4.8.2 this is not a loop inside RetryNode::tick: after a failure of a child
    that was IDLE, the Retry emits the tree's wake-up signal and returns RUNNING, and
    Tree::tickOnce re-ticks the whole tree from the root because the signal is set. With
    tickExactlyOnce the same attempts are spread over three ticks.
    """
    body = (
        '<RetryUntilSuccessful name="r" num_attempts="3"><ScriptedAction name="a"/>'
        "</RetryUntilSuccessful>"
    )
    nodes = {
        "a": [
            {"status": "FAILURE", "ticks": 0},
            {"status": "FAILURE", "ticks": 0},
            {"status": "SUCCESS", "ticks": 0},
        ]
    }
    attempts = [
        ["a", "IDLE", "FAILURE"],
        ["a", "FAILURE", "IDLE"],
        ["a", "IDLE", "FAILURE"],
        ["a", "FAILURE", "IDLE"],
        ["a", "IDLE", "SUCCESS"],
        ["a", "SUCCESS", "IDLE"],
    ]
    result = _run(body, nodes)
    assert result["transitions"] == [
        [1, "r", "IDLE", "RUNNING"],
        *[[1, *t] for t in attempts],
        [1, "r", "RUNNING", "SUCCESS"],
        [1, "r", "SUCCESS", "IDLE"],
    ]
    assert result["root"] == ["SUCCESS"]

    exact = _run(body, nodes, tick_mode="exactly_once")
    assert [t[0] for t in exact["transitions"]] == [1, 1, 1, 2, 2, 3, 3, 3, 3]
    assert exact["root"] == ["RUNNING", "RUNNING", "SUCCESS"]


@needs_btcpp
def test_reactive_sequence_resets_earlier_condition_every_tick() -> None:
    """ReactiveSequence re-ticks its condition each tick and halts it (SUCCESS->IDLE)
    as soon as a later child is RUNNING; a RUNNING scripted action is ticked on."""
    result = _run(
        '<ReactiveSequence name="r"><ScriptedCondition name="c"/>'
        '<ScriptedAction name="a"/></ReactiveSequence>',
        {"c": [{"status": "SUCCESS"}], "a": _ok(ticks=2)},
    )
    assert result["transitions"] == [
        [1, "r", "IDLE", "RUNNING"],
        [1, "c", "IDLE", "SUCCESS"],
        [1, "a", "IDLE", "RUNNING"],
        [1, "c", "SUCCESS", "IDLE"],
        [2, "c", "IDLE", "SUCCESS"],
        [2, "c", "SUCCESS", "IDLE"],
        [3, "c", "IDLE", "SUCCESS"],
        [3, "a", "RUNNING", "SUCCESS"],
        [3, "c", "SUCCESS", "IDLE"],
        [3, "a", "SUCCESS", "IDLE"],
        [3, "r", "RUNNING", "SUCCESS"],
        [3, "r", "SUCCESS", "IDLE"],
    ]
    assert result["root"] == ["RUNNING", "RUNNING", "SUCCESS"]


@needs_btcpp
def test_running_action_is_halted_after_max_ticks() -> None:
    """After max_ticks the tree is destroyed and BT.CPP's destructor halts it: the root
    Sequence resets its children in order (the completed 'a' SUCCESS->IDLE, the running 'b'
    RUNNING->IDLE), then itself. The halt transitions carry the teardown tick (last + 1)."""
    result = _run(
        '<Sequence name="s"><ScriptedAction name="a"/><ScriptedAction name="b"/></Sequence>',
        {"a": _ok(), "b": _ok(ticks=5)},
        max_ticks=2,
    )
    assert result["transitions"] == [
        [1, "s", "IDLE", "RUNNING"],
        [1, "a", "IDLE", "SUCCESS"],
        [1, "b", "IDLE", "RUNNING"],
        [3, "a", "SUCCESS", "IDLE"],
        [3, "b", "RUNNING", "IDLE"],
        [3, "s", "RUNNING", "IDLE"],
    ]
    assert result["root"] == ["RUNNING", "RUNNING"]
    assert (result["halted"], result["teardown_tick"]) == (True, 3)


@needs_btcpp
def test_destroying_a_completed_tree_resets_what_memory_kept() -> None:
    """A SequenceWithMemory whose second child fails keeps its first child SUCCESS after the
    run ended; destroying the tree halts it, and the logger sees ``c1 SUCCESS -> IDLE``."""
    result = _run(
        '<SequenceWithMemory name="s"><ScriptedAction name="c1"/>'
        '<ScriptedAction name="c2"/></SequenceWithMemory>',
        {"c1": _ok(), "c2": [{"status": "FAILURE"}]},
    )
    assert result["root"] == ["FAILURE"]
    assert result["transitions"][-2:] == [[1, "s", "FAILURE", "IDLE"], [2, "c1", "SUCCESS", "IDLE"]]
    assert (result["halted"], result["teardown_tick"]) == (False, 2)


def test_scripted_leaves_model() -> None:
    """Entries are per activation, the last repeats, a halt consumes the activation."""
    leaves = ScriptedLeaves(
        {
            "nodes": {
                "a": [{"status": "FAILURE", "ticks": 2}, {"status": "SUCCESS", "ticks": 0}],
                "c": [{"status": "FAILURE"}, {"status": "SUCCESS"}],
            }
        }
    )
    assert leaves.start("a") == "RUNNING"
    assert leaves.running("a") == "RUNNING"
    assert leaves.running("a") == "FAILURE"
    assert leaves.start("a") == "SUCCESS"
    assert leaves.start("a") == "SUCCESS"
    assert [leaves.condition("c") for _ in range(3)] == ["FAILURE", "SUCCESS", "SUCCESS"]
    assert leaves.start("other") == "SUCCESS"  # default entry
    fresh = ScriptedLeaves(
        {"nodes": {"a": [{"status": "FAILURE", "ticks": 1}, {"status": "SUCCESS", "ticks": 1}]}}
    )
    assert fresh.start("a", key=1) == "RUNNING"
    fresh.halted("a", key=1)
    assert fresh.start("a", key=1) == "RUNNING"
    assert fresh.running("a", key=1) == "SUCCESS"
    assert fresh.start("a", key=2) == "RUNNING"  # another instance counts on its own
    assert fresh.running("a", key=2) == "FAILURE"


def test_generator_is_deterministic() -> None:
    """The same seed gives the same case; names are unique."""
    first, again = generate(7), generate(7)
    assert first == again
    assert len(first.names) == len(set(first.names))
    assert first.xml.startswith('<root BTCPP_format="4" main_tree_to_execute="Main">')

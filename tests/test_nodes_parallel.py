"""Parallel and ParallelAll: thresholds, halting, skipped children.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

import pytest

from btlog.executor.behavior import NodeExecutionError
from tests.nodes_support import (
    act,
    build,
    fail,
    ok,
    run,
    xml,
)


def test_parallel_default_thresholds_wait_for_all_successes() -> None:
    """success_count=-1 (all), failure_count=1: completed children are not ticked again."""
    r = run(
        f'<Parallel name="p">{act("a")}{act("b")}{act("c")}</Parallel>',
        {"a": [ok(1)], "b": [ok(2)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
            ("c", "IDLE", "SUCCESS"),
        ],
        2: [("a", "RUNNING", "SUCCESS")],
        3: [
            ("b", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "SUCCESS"),
            ("p", "SUCCESS", "IDLE"),
        ],
    }


@pytest.mark.parametrize(
    "thresholds",
    [
        pytest.param('success_count="2" failure_count="1"', id="failure_count_reached"),
        pytest.param('success_count="3" failure_count="3"', id="success_impossible"),
    ],
)
def test_parallel_failure_halts_the_running_children(thresholds: str) -> None:
    """One failure fails the Parallel, either because failure_count=1 is reached or because
    success_count=3 has become impossible; it halts the RUNNING children (RUNNING->IDLE) in
    child order."""
    r = run(
        f'<Parallel name="p" {thresholds}>{act("a")}{act("b")}{act("c")}</Parallel>',
        {"a": [ok(2)], "b": [fail(1)], "c": [ok(3)]},
    )
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
            ("c", "IDLE", "RUNNING"),
        ],
        2: [
            ("b", "RUNNING", "FAILURE"),
            ("a", "RUNNING", "IDLE"),
            ("b", "FAILURE", "IDLE"),
            ("c", "RUNNING", "IDLE"),
            ("p", "RUNNING", "FAILURE"),
            ("p", "FAILURE", "IDLE"),
        ],
    }


def test_parallel_negative_failure_count_and_one_success() -> None:
    """success_count=1 succeeds at the first success; failure_count=-1 means all three must fail."""
    r = run(
        f'<Parallel name="p" success_count="1" failure_count="-1">'
        f"{act('a')}{act('b')}{act('c')}</Parallel>",
        {"a": [fail()], "b": [ok(2)], "c": [ok(3)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "FAILURE"),
            ("b", "IDLE", "RUNNING"),
            ("c", "IDLE", "RUNNING"),
        ],
        3: [
            ("b", "RUNNING", "SUCCESS"),
            ("a", "FAILURE", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "RUNNING", "IDLE"),
            ("p", "RUNNING", "SUCCESS"),
            ("p", "SUCCESS", "IDLE"),
        ],
    }


def test_parallel_negative_success_count() -> None:
    """success_count=-2 with 3 children means 2 successes (N+t+1); one failure is tolerated."""
    r = run(
        f'<Parallel name="p" success_count="-2" failure_count="2">'
        f"{act('a')}{act('b')}{act('c')}</Parallel>",
        {"a": [fail(1)], "b": [ok(2)], "c": [ok(3)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
            ("c", "IDLE", "RUNNING"),
        ],
        2: [("a", "RUNNING", "FAILURE")],
        3: [("b", "RUNNING", "SUCCESS")],
        4: [
            ("c", "RUNNING", "SUCCESS"),
            ("a", "FAILURE", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "SUCCESS"),
            ("p", "SUCCESS", "IDLE"),
        ],
    }


def test_parallel_all_skipped_with_default_success_count_succeeds() -> None:
    """The quirk: with success_count=-1 the skipped children count as successes -> SUCCESS."""
    r = run(
        '<Parallel name="p"><AlwaysSuccess name="x" _skipIf="true"/>'
        '<AlwaysSuccess name="y" _skipIf="true"/></Parallel>'
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [("p", "IDLE", "RUNNING"), ("p", "RUNNING", "SUCCESS"), ("p", "SUCCESS", "IDLE")],
    }


def test_parallel_all_runs_every_child_then_counts_failures() -> None:
    """ParallelAll waits for every child; 2 failures >= max_failures=2 -> FAILURE."""
    r = run(
        f'<ParallelAll name="p" max_failures="2">{act("a")}{act("b")}{act("c")}</ParallelAll>',
        {"a": [fail(1)], "b": [ok(2)], "c": [fail()]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
            ("c", "IDLE", "FAILURE"),
        ],
        2: [("a", "RUNNING", "FAILURE")],
        3: [
            ("b", "RUNNING", "SUCCESS"),
            ("a", "FAILURE", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "FAILURE", "IDLE"),
            ("p", "RUNNING", "FAILURE"),
            ("p", "FAILURE", "IDLE"),
        ],
    }


def test_parallel_all_negative_max_failures() -> None:
    """max_failures=-1 means N: one failure out of two children still succeeds."""
    r = run(
        f'<ParallelAll name="p" max_failures="-1">{act("a")}{act("b")}</ParallelAll>',
        {"a": [fail(1)]},
    )
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("p", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING"), ("b", "IDLE", "SUCCESS")],
        2: [
            ("a", "RUNNING", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "SUCCESS"),
            ("p", "SUCCESS", "IDLE"),
        ],
    }


def test_parallel_with_fewer_children_than_its_threshold_raises() -> None:
    """BT.CPP throws when N < success_count ("can never succeed")."""
    _, executor, _ = build(
        xml(f'<Parallel name="p" success_count="3">{act("a")}{act("b")}</Parallel>')
    )
    with pytest.raises(NodeExecutionError, match=r"node 'p'.*success_count"):
        executor.tick()

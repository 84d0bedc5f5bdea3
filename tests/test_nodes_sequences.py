"""Sequence, SequenceWithMemory and ReactiveSequence, one small tree per behaviour; the
expected transitions are BT.CPP 4.8.2's (btcpp-semantics.md, section 1).

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

import pytest

from btlog.status import IDLE
from tests.nodes_support import (
    act,
    cond,
    fail,
    ok,
    run,
)


# -- control nodes (expected transitions checked against BT.CPP 4.8.2) ------------------------
def test_sequence_resumes_at_the_running_child() -> None:
    """Sequence resumes at the RUNNING child (a is not ticked again); on completion every child
    is reset (in order) before the Sequence's own result, and the root is reset after it."""
    r = run(f'<Sequence name="s">{act("a")}{act("b")}{act("c")}</Sequence>', {"b": [ok(1)]})
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("s", "IDLE", "RUNNING"), ("a", "IDLE", "SUCCESS"), ("b", "IDLE", "RUNNING")],
        2: [
            ("b", "RUNNING", "SUCCESS"),
            ("c", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "SUCCESS", "IDLE"),
            ("s", "RUNNING", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
        ],
    }


def test_sequence_failure_resets_all_children_and_restarts() -> None:
    """A FAILURE resets every child (completed ones SUCCESS->IDLE) and the index: the Sequence,
    re-ticked by the Retry, starts again from its first child."""
    r = run(
        '<RetryUntilSuccessful name="r" num_attempts="2"><Sequence name="s">'
        f"{act('a')}{act('b')}{act('c')}</Sequence></RetryUntilSuccessful>",
        {"b": [ok(1)], "c": [fail(), ok()]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("s", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
        ],
        2: [
            ("b", "RUNNING", "SUCCESS"),
            ("c", "IDLE", "FAILURE"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "FAILURE", "IDLE"),
            ("s", "RUNNING", "FAILURE"),
            ("s", "FAILURE", "IDLE"),
            ("s", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
        ],
        3: [
            ("b", "RUNNING", "SUCCESS"),
            ("c", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "SUCCESS", "IDLE"),
            ("s", "RUNNING", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }


@pytest.mark.parametrize(
    "control",
    [
        'Sequence name="n"',
        'Fallback name="n"',
        'Parallel name="n" success_count="2"',
        'ParallelAll name="n"',
    ],
)
def test_control_of_skipped_children_is_skipped_and_stays_running(control: str) -> None:
    """All children skipped: the node returns SKIPPED (never stored), so it stays RUNNING in
    the log (btcpp-semantics.md, root quirk) until the final halt resets it. (A Parallel
    with the default success_count=-1 succeeds instead: see the quirk test below.)"""
    tag = control.split()[0]
    r = run(
        f'<{control}><AlwaysSuccess name="x" _skipIf="true"/>'
        f'<AlwaysSuccess name="y" _skipIf="true"/></{tag}>',
        max_ticks=2,
    )
    assert r.roots == ["SKIPPED", "SKIPPED"]
    assert r.ticks == {
        1: [("n", "IDLE", "RUNNING")],
        3: [("n", "RUNNING", "IDLE")],
    }


def test_sequence_with_some_skipped_children_succeeds() -> None:
    """A skipped child counts as done; the skipped node itself never appears in the log."""
    r = run(f'<Sequence name="s"><AlwaysFailure name="x" _skipIf="true"/>{act("a")}</Sequence>')
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("s", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("s", "RUNNING", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
        ],
    }


def test_nested_all_skipped_sequence_stays_running_until_its_parent_resets_it() -> None:
    """The inner Sequence set itself RUNNING, returned SKIPPED: it stays RUNNING until the outer
    Sequence resets its children (RUNNING->IDLE, no halt needed)."""
    r = run(
        '<Sequence name="top"><Sequence name="s"><AlwaysSuccess name="x" _skipIf="true"/>'
        f"</Sequence>{act('a')}</Sequence>"
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("s", "RUNNING", "IDLE"),
            ("a", "SUCCESS", "IDLE"),
            ("top", "RUNNING", "SUCCESS"),
            ("top", "SUCCESS", "IDLE"),
        ],
    }


def test_sequence_with_memory_retries_the_failed_child_only() -> None:
    """SequenceWithMemory keeps its index on FAILURE: when re-ticked (by the Retry) it resumes at
    the failed child b; a is not run again. b's first attempt fails synchronously from IDLE, so
    the Retry signals a wake-up and the root is re-ticked within the same tick."""
    r = run(
        '<RetryUntilSuccessful name="r" num_attempts="3"><SequenceWithMemory name="m">'
        f"{act('a')}{act('b')}{act('c')}</SequenceWithMemory></RetryUntilSuccessful>",
        {"b": [fail(), ok(1)]},
    )
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("m", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("b", "IDLE", "FAILURE"),
            ("b", "FAILURE", "IDLE"),
            ("m", "RUNNING", "FAILURE"),
            ("m", "FAILURE", "IDLE"),
            ("m", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
        ],
        2: [
            ("b", "RUNNING", "SUCCESS"),
            ("c", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("c", "SUCCESS", "IDLE"),
            ("m", "RUNNING", "SUCCESS"),
            ("m", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }
    assert [t for t in r.flat if t[1] == "a"] == [
        [1, "a", "IDLE", "SUCCESS"],
        [2, "a", "SUCCESS", "IDLE"],
    ]


def test_sequence_with_memory_keeps_earlier_successes_in_the_log() -> None:
    """On FAILURE only children from the failed one on are reset: a stays SUCCESS in the log,
    even after the ReactiveFallback resets the SequenceWithMemory itself. (a succeeded from
    IDLE: a wake-up, so c is evaluated twice in the tick.)"""
    r = run(
        f'<ReactiveFallback name="f">{cond("c")}<SequenceWithMemory name="m">'
        f"{act('a')}{act('b')}{act('d')}</SequenceWithMemory></ReactiveFallback>",
        {"c": [fail()], "b": [fail()]},
    )
    assert r.roots == ["FAILURE"]
    assert r.ticks == {
        1: [
            ("f", "IDLE", "RUNNING"),
            ("c", "IDLE", "FAILURE"),
            ("m", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("c", "FAILURE", "IDLE"),
            ("c", "IDLE", "FAILURE"),
            ("b", "IDLE", "FAILURE"),
            ("b", "FAILURE", "IDLE"),
            ("m", "RUNNING", "FAILURE"),
            ("c", "FAILURE", "IDLE"),
            ("m", "FAILURE", "IDLE"),
            ("f", "RUNNING", "FAILURE"),
            ("f", "FAILURE", "IDLE"),
        ],
        2: [("a", "SUCCESS", "IDLE")],  # until the teardown resets it (BT.CPP's haltTree)
    }
    assert r.executor.statuses()[r.tree.lookup("a")[0].uid] is IDLE


def test_sequence_with_memory_wakes_up_after_a_success_from_idle() -> None:
    """A child succeeding from IDLE with more children to go makes SequenceWithMemory return
    RUNNING with a wake-up: the ReactiveSequence halts its condition, the root is re-ticked in
    the same tick and the condition is evaluated a second time (tick 1)."""
    r = run(
        f'<ReactiveSequence name="r">{cond("c")}<SequenceWithMemory name="m">'
        f"{act('a')}{act('b')}</SequenceWithMemory></ReactiveSequence>",
        {"b": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("c", "IDLE", "SUCCESS"),
            ("m", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("c", "SUCCESS", "IDLE"),
            ("c", "IDLE", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
        ],
        2: [
            ("c", "IDLE", "SUCCESS"),
            ("b", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("m", "RUNNING", "SUCCESS"),
            ("c", "SUCCESS", "IDLE"),
            ("m", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }


def test_reactive_sequence_reticks_and_resets_earlier_conditions_every_tick() -> None:
    """ReactiveSequence ticks from its first child every tick and halts every other child when one
    is RUNNING: c goes SUCCESS->IDLE each tick; when c fails, the running a is halted."""
    r = run(
        f'<ReactiveSequence name="r">{cond("c")}{act("a")}</ReactiveSequence>',
        {"c": [ok(), fail()], "a": [ok(3)]},
    )
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("c", "IDLE", "SUCCESS"),
            ("a", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
        ],
        2: [
            ("c", "IDLE", "FAILURE"),
            ("c", "FAILURE", "IDLE"),
            ("a", "RUNNING", "IDLE"),
            ("r", "RUNNING", "FAILURE"),
            ("r", "FAILURE", "IDLE"),
        ],
    }


def test_reactive_sequence_halts_a_later_running_child() -> None:
    """a completed synchronously (activation 1), then RUNNING again on its second activation:
    the later RUNNING b is halted (RUNNING->IDLE), and restarted once a completes."""
    r = run(
        f'<ReactiveSequence name="r">{cond("c")}{act("a")}{act("b")}</ReactiveSequence>',
        {"a": [ok(), ok(1)], "b": [ok(3)]},
        max_ticks=4,
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "RUNNING"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("c", "IDLE", "SUCCESS"),
            ("a", "IDLE", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
            ("a", "SUCCESS", "IDLE"),
        ],
        2: [
            ("c", "IDLE", "SUCCESS"),
            ("a", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
            ("b", "RUNNING", "IDLE"),
        ],
        3: [
            ("c", "IDLE", "SUCCESS"),
            ("a", "RUNNING", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
            ("a", "SUCCESS", "IDLE"),
        ],
        4: [
            ("c", "IDLE", "SUCCESS"),
            ("a", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
            ("b", "RUNNING", "IDLE"),
        ],
        5: [("a", "RUNNING", "IDLE"), ("r", "RUNNING", "IDLE")],
    }

"""Decorators: Inverter, Force*, Repeat, Retry, KeepRunningUntilFailure, RunOnce,
Precondition, and the time-based Delay, Timeout and Sleep on the simulated clock.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

import pytest

from btlog.executor.behavior import NodeExecutionError
from btlog.executor.engine import MAX_WAKE_UPS
from btlog.status import RUNNING, SKIPPED, SUCCESS
from tests.nodes_support import (
    act,
    build,
    collect,
    cond,
    fail,
    ok,
    run,
    script,
    xml,
)


# -- decorators -------------------------------------------------------------------------------
def test_inverter_flips_results_and_resets_its_child() -> None:
    """Inverter: SUCCESS<->FAILURE; the child is reset before the Inverter's own result."""
    r = run(
        f'<Sequence name="q"><Inverter name="i">{act("a")}</Inverter>'
        f'<Inverter name="j">{act("b")}</Inverter></Sequence>',
        {"a": [fail(1)]},
    )
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("q", "IDLE", "RUNNING"), ("i", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        2: [
            ("a", "RUNNING", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("i", "RUNNING", "SUCCESS"),
            ("j", "IDLE", "RUNNING"),
            ("b", "IDLE", "SUCCESS"),
            ("b", "SUCCESS", "IDLE"),
            ("j", "RUNNING", "FAILURE"),
            ("i", "SUCCESS", "IDLE"),
            ("j", "FAILURE", "IDLE"),
            ("q", "RUNNING", "FAILURE"),
            ("q", "FAILURE", "IDLE"),
        ],
    }


def test_inverter_passes_skipped_through() -> None:
    """A skipped child makes the Inverter return SKIPPED: it stays RUNNING until its parent
    resets it."""
    r = run(
        f'<Sequence name="q"><Inverter name="i"><AlwaysSuccess name="x" _skipIf="true"/>'
        f"</Inverter>{act('a')}</Sequence>"
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("i", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("i", "RUNNING", "IDLE"),
            ("a", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
        ],
    }


def test_force_success_and_force_failure() -> None:
    """ForceSuccess turns a FAILURE into SUCCESS, ForceFailure a SUCCESS into FAILURE."""
    r = run(
        f'<Sequence name="q"><ForceSuccess name="fs">{act("a")}</ForceSuccess>'
        f'<ForceFailure name="ff">{act("b")}</ForceFailure></Sequence>',
        {"a": [fail(1)]},
    )
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("q", "IDLE", "RUNNING"), ("fs", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        2: [
            ("a", "RUNNING", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("fs", "RUNNING", "SUCCESS"),
            ("ff", "IDLE", "RUNNING"),
            ("b", "IDLE", "SUCCESS"),
            ("b", "SUCCESS", "IDLE"),
            ("ff", "RUNNING", "FAILURE"),
            ("fs", "SUCCESS", "IDLE"),
            ("ff", "FAILURE", "IDLE"),
            ("q", "RUNNING", "FAILURE"),
            ("q", "FAILURE", "IDLE"),
        ],
    }


def test_repeat_loops_within_one_tick_while_the_child_succeeds_synchronously() -> None:
    """num_cycles=3 of a synchronous child: three runs in tick 1 (each one a wake-up re-tick)."""
    r = run(f'<Repeat name="r" num_cycles="3">{act("a")}</Repeat>')
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }


def test_repeat_with_a_running_child() -> None:
    """A child completing after RUNNING does not wake up; a synchronous run does."""
    r = run(f'<Repeat name="r" num_cycles="3">{act("a")}</Repeat>', {"a": [ok(1), ok(), ok(1)]})
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("r", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        2: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("a", "IDLE", "RUNNING"),
        ],
        3: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }


def test_repeat_fails_with_its_child() -> None:
    """FAILURE of the child ends the Repeat (and resets its count)."""
    r = run(f'<Repeat name="r" num_cycles="3">{act("a")}</Repeat>', {"a": [ok(), fail(1)]})
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("a", "IDLE", "RUNNING"),
        ],
        2: [
            ("a", "RUNNING", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("r", "RUNNING", "FAILURE"),
            ("r", "FAILURE", "IDLE"),
        ],
    }


def test_repeat_of_a_skipped_child_is_skipped() -> None:
    """The child is skipped: Repeat returns SKIPPED (and stays RUNNING in the log)."""
    r = run(
        '<Repeat name="r" num_cycles="3"><AlwaysSuccess name="x" _skipIf="true"/></Repeat>',
        max_ticks=2,
    )
    assert r.roots == ["SKIPPED", "SKIPPED"]
    assert r.ticks == {
        1: [("r", "IDLE", "RUNNING")],
        3: [("r", "RUNNING", "IDLE")],
    }


def test_retry_retries_within_one_tick() -> None:
    """A synchronously failing child is retried in the same tick (IDLE->FAILURE->IDLE, twice),
    and the third attempt succeeds."""
    r = run(
        f'<Sequence name="q">{act("p")}<RetryUntilSuccessful name="r" num_attempts="3">'
        f"{act('a')}</RetryUntilSuccessful></Sequence>",
        {"a": [fail(), fail(), ok()]},
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("p", "IDLE", "SUCCESS"),
            ("r", "IDLE", "RUNNING"),
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("p", "SUCCESS", "IDLE"),
            ("r", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
        ],
    }


def test_retry_exhausted_fails() -> None:
    """Three failed attempts out of num_attempts=3: FAILURE."""
    r = run(
        f'<RetryUntilSuccessful name="r" num_attempts="3">{act("a")}</RetryUntilSuccessful>',
        {"a": [fail()]},
    )
    assert r.roots == ["FAILURE"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("r", "RUNNING", "FAILURE"),
            ("r", "FAILURE", "IDLE"),
        ],
    }


def test_retry_after_a_running_attempt() -> None:
    """An attempt that failed after RUNNING is retried at once (no wake-up: it did not start from
    IDLE in this tick); the retry that fails synchronously is retried again in the same tick."""
    r = run(
        f'<RetryUntilSuccessful name="r" num_attempts="3">{act("a")}</RetryUntilSuccessful>',
        {"a": [fail(1), fail(), ok(1)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("r", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        2: [
            ("a", "RUNNING", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("a", "IDLE", "RUNNING"),
        ],
        3: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }


def test_retry_wake_up_reticks_the_root() -> None:
    """A failure of a child that started from IDLE makes Retry return RUNNING with a wake-up:
    the ReactiveSequence halts its condition and the root is re-ticked within tick 1."""
    r = run(
        f'<ReactiveSequence name="r">{cond("c")}'
        '<RetryUntilSuccessful name="t" num_attempts="3">'
        f"{act('a')}</RetryUntilSuccessful></ReactiveSequence>",
        {"a": [fail(), ok(1)]},
    )
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("c", "IDLE", "SUCCESS"),
            ("t", "IDLE", "RUNNING"),
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("c", "SUCCESS", "IDLE"),
            ("c", "IDLE", "SUCCESS"),
            ("a", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
        ],
        2: [
            ("c", "IDLE", "SUCCESS"),
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("t", "RUNNING", "SUCCESS"),
            ("c", "SUCCESS", "IDLE"),
            ("t", "SUCCESS", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }


def test_keep_running_until_failure() -> None:
    """Each SUCCESS resets the child and returns RUNNING; the FAILURE ends it."""
    r = run(
        f'<KeepRunningUntilFailure name="k">{act("a")}</KeepRunningUntilFailure>',
        {"a": [ok(), ok(1), fail()]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("k", "IDLE", "RUNNING"), ("a", "IDLE", "SUCCESS"), ("a", "SUCCESS", "IDLE")],
        2: [("a", "IDLE", "RUNNING")],
        3: [("a", "RUNNING", "SUCCESS"), ("a", "SUCCESS", "IDLE")],
        4: [
            ("a", "IDLE", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("k", "RUNNING", "FAILURE"),
            ("k", "FAILURE", "IDLE"),
        ],
    }


def test_run_once_then_skips() -> None:
    """then_skip (default true): after its first completion RunOnce returns SKIPPED without
    ticking its child; being reset by its parent (o SUCCESS->IDLE) does not forget it."""
    r = run(
        f'<Repeat name="rep" num_cycles="3"><Sequence name="q"><RunOnce name="o">{act("a")}'
        f"</RunOnce>{act('b')}</Sequence></Repeat>",
        {"b": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("rep", "IDLE", "RUNNING"),
            ("q", "IDLE", "RUNNING"),
            ("o", "IDLE", "RUNNING"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("o", "RUNNING", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
        ],
        2: [
            ("b", "RUNNING", "SUCCESS"),
            ("o", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
            ("q", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
        ],
        3: [
            ("b", "RUNNING", "SUCCESS"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
            ("q", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
        ],
        4: [
            ("b", "RUNNING", "SUCCESS"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
            ("rep", "RUNNING", "SUCCESS"),
            ("rep", "SUCCESS", "IDLE"),
        ],
    }


def test_run_once_without_skip_returns_the_remembered_status() -> None:
    """then_skip=false: later ticks return the remembered SUCCESS (o IDLE->SUCCESS) and the child
    is never ticked again."""
    r = run(
        f'<Repeat name="rep" num_cycles="3"><Sequence name="q">'
        f'<RunOnce name="o" then_skip="false">{act("a")}</RunOnce>{act("b")}</Sequence>'
        "</Repeat>",
        {"a": [ok(1)], "b": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("rep", "IDLE", "RUNNING"),
            ("q", "IDLE", "RUNNING"),
            ("o", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
        ],
        2: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("o", "RUNNING", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
        ],
        3: [
            ("b", "RUNNING", "SUCCESS"),
            ("o", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
            ("q", "IDLE", "RUNNING"),
            ("o", "IDLE", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
        ],
        4: [
            ("b", "RUNNING", "SUCCESS"),
            ("o", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
            ("q", "IDLE", "RUNNING"),
            ("o", "IDLE", "SUCCESS"),
            ("b", "IDLE", "RUNNING"),
        ],
        5: [
            ("b", "RUNNING", "SUCCESS"),
            ("o", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
            ("rep", "RUNNING", "SUCCESS"),
            ("rep", "SUCCESS", "IDLE"),
        ],
    }


def test_run_once_halted_while_running_runs_again_but_halted_after_completion_does_not() -> None:
    """A halt while the child runs leaves RunOnce not done (the next tick restarts the child);
    once it completed, even ``Executor.halt()`` does not make it run again."""
    tree, executor, log = build(
        xml(f'<RunOnce name="o">{act("a")}</RunOnce>'), {"a": [ok(1), ok(1)]}
    )
    assert executor.tick() is RUNNING
    executor.halt()
    assert [executor.tick(), executor.tick()] == [RUNNING, SUCCESS]
    executor.halt()
    assert [executor.tick(), executor.tick()] == [SKIPPED, SKIPPED]
    assert executor.behaviors[2].activations == 2
    assert collect(tree, executor, log).ticks == {
        1: [
            ("o", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
            ("a", "RUNNING", "IDLE"),
            ("o", "RUNNING", "IDLE"),
        ],
        2: [("o", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        3: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("o", "RUNNING", "SUCCESS"),
            ("o", "SUCCESS", "IDLE"),
        ],
    }


def test_precondition_if_and_else() -> None:
    """A true ``if`` ticks the child; a false one returns ``else`` (default FAILURE) without
    ticking it. Precondition never sets RUNNING itself."""
    r = run(
        f'<Sequence name="top">{script("s", "x:=1")}'
        f'<Precondition name="p1" if="x==1" else="FAILURE">{act("a")}</Precondition>'
        f'<Precondition name="p2" if="x==2" else="SUCCESS">{act("b")}</Precondition>'
        f'<Precondition name="p3" if="x==3">{act("c")}</Precondition></Sequence>'
    )
    assert r.roots == ["FAILURE"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("p1", "IDLE", "SUCCESS"),
            ("p2", "IDLE", "SUCCESS"),
            ("p3", "IDLE", "FAILURE"),
            ("s", "SUCCESS", "IDLE"),
            ("p1", "SUCCESS", "IDLE"),
            ("p2", "SUCCESS", "IDLE"),
            ("p3", "FAILURE", "IDLE"),
            ("top", "RUNNING", "FAILURE"),
            ("top", "FAILURE", "IDLE"),
        ],
    }


def test_precondition_is_not_reevaluated_while_the_child_runs() -> None:
    """x becomes 2 while a runs: the Precondition keeps ticking a until it completes."""
    r = run(
        f'<Sequence name="top">{script("s", "x:=1")}<Parallel name="p" success_count="2">'
        f'<Precondition name="pc" if="x==1">{act("a")}</Precondition>'
        f'<Sequence name="q">{act("b")}{script("s2", "x:=2")}</Sequence></Parallel></Sequence>',
        {"a": [ok(2)], "b": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
            ("pc", "IDLE", "RUNNING"),
            ("q", "IDLE", "RUNNING"),
            ("b", "IDLE", "RUNNING"),
        ],
        2: [
            ("b", "RUNNING", "SUCCESS"),
            ("s2", "IDLE", "SUCCESS"),
            ("b", "SUCCESS", "IDLE"),
            ("s2", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
        ],
        3: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("pc", "RUNNING", "SUCCESS"),
            ("pc", "SUCCESS", "IDLE"),
            ("q", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("p", "SUCCESS", "IDLE"),
            ("top", "RUNNING", "SUCCESS"),
            ("top", "SUCCESS", "IDLE"),
        ],
    }


def test_delay_on_the_simulated_clock() -> None:
    """Delay 250 ms with a 100 ms tick period: RUNNING at t=0, 100, 200 ms; the child is ticked
    at t=300 ms (tick 4)."""
    r = run(f'<Delay name="d" delay_msec="250">{act("a")}</Delay>', oracle=False)
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("d", "IDLE", "RUNNING")],
        4: [
            ("a", "IDLE", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("d", "RUNNING", "SUCCESS"),
            ("d", "SUCCESS", "IDLE"),
        ],
    }


def test_timeout_halts_the_running_child() -> None:
    """Timeout 250 ms: at t=300 ms (tick 4) the child is still running; it is halted
    (RUNNING->IDLE) and the Timeout fails."""
    r = run(f'<Timeout name="t" msec="250">{act("a")}</Timeout>', {"a": [ok(5)]}, oracle=False)
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("t", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        4: [("a", "RUNNING", "IDLE"), ("t", "RUNNING", "FAILURE"), ("t", "FAILURE", "IDLE")],
    }


def test_timeout_passes_a_result_in_time() -> None:
    """The child completes at tick 3 (t=200 ms < 250 ms): its result passes through."""
    r = run(f'<Timeout name="t" msec="250">{act("a")}</Timeout>', {"a": [fail(2)]}, oracle=False)
    assert r.roots == ["RUNNING", "RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("t", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        3: [
            ("a", "RUNNING", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("t", "RUNNING", "FAILURE"),
            ("t", "FAILURE", "IDLE"),
        ],
    }


def test_sleep_on_the_simulated_clock() -> None:
    """Sleep 250 ms: RUNNING from t=0, SUCCESS at the first tick at or after 250 ms (t=300 ms)."""
    r = run('<Sleep name="z" msec="250"/>', oracle=False)
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("z", "IDLE", "RUNNING")],
        4: [("z", "RUNNING", "SUCCESS"), ("z", "SUCCESS", "IDLE")],
    }


def test_sleep_is_halted_by_a_timeout() -> None:
    """Sleep 500 ms under Timeout 150 ms: halted at t=200 ms (tick 3)."""
    r = run('<Timeout name="t" msec="150"><Sleep name="z" msec="500"/></Timeout>', oracle=False)
    assert r.roots == ["RUNNING", "RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("t", "IDLE", "RUNNING"), ("z", "IDLE", "RUNNING")],
        3: [("z", "RUNNING", "IDLE"), ("t", "RUNNING", "FAILURE"), ("t", "FAILURE", "IDLE")],
    }


def test_timeout_zero_never_times_out() -> None:
    """BT.CPP ``TimeoutNode::tick``: ``if(msec_ > 0) timer_.add(...)``. Verified with BT.CPP
    4.8.2: the child runs its 3 ticks and the Timeout succeeds at tick 4."""
    r = run(f'<Timeout name="t" msec="0">{act("a")}</Timeout>', {"a": [ok(3)]})
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("t", "IDLE", "RUNNING"), ("a", "IDLE", "RUNNING")],
        4: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("t", "RUNNING", "SUCCESS"),
            ("t", "SUCCESS", "IDLE"),
        ],
    }


def test_precondition_without_if_is_an_error() -> None:
    """BT.CPP ``PreconditionNode::loadExecutor`` throws when the ``if`` port is missing."""
    _, executor, _ = build(
        xml('<Precondition name="p" else="SUCCESS"><AlwaysSuccess name="a"/></Precondition>')
    )
    with pytest.raises(NodeExecutionError, match=r"node 'p' \(uid 1\): missing port 'if'$"):
        executor.tick()


def test_a_retry_that_fails_at_once_forever_ends_the_tick_and_lets_time_pass() -> None:
    """BT.CPP's test Parallel.PauseWithRetry: a RetryUntilSuccessful (num_attempts -1) of
    AlwaysFailure wakes the tree up after every attempt until a Sleep beside it sets
    ``paused`` false. BT.CPP re-ticks while real time passes; on btlog's simulated clock
    a tick ends after MAX_WAKE_UPS re-ticks (it looped forever before), so the Sleeps
    finish and the tree succeeds."""
    r = run(
        '<Parallel name="p"><Sequence name="s1"><Sleep msec="150"/>'
        '<Script code="paused := false"/><Sleep msec="150"/></Sequence>'
        '<Sequence name="s2"><Script code="paused := true; done := false"/>'
        '<RetryUntilSuccessful name="t" _while="paused" num_attempts="-1" '
        '_onHalted="done = true"><AlwaysFailure name="f"/></RetryUntilSuccessful>'
        "</Sequence></Parallel>",
        max_ticks=20,
        oracle=False,  # BT.CPP's own test ticks exactly once per tick: no wake-up loop
    )
    assert r.roots[-1] == "SUCCESS" and len(r.roots) <= 5, r.roots
    attempts = sum(c == ("f", "IDLE", "FAILURE") for changes in r.ticks.values() for c in changes)
    assert attempts == 2 * (MAX_WAKE_UPS + 1), attempts  # two ticks of 0.1 s before 0.15 s

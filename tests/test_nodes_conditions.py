"""The special attributes (``_skipIf``, ``_failureIf``, ``_successIf``, ``_while``,
``_onHalted``, post conditions) and halting at the end of a run.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

import pytest

from tests.nodes_support import (
    act,
    fail,
    ok,
    run,
    script,
)


# -- pre/post conditions, halting, SubTree ----------------------------------------------------
def test_skip_if_emits_no_transition() -> None:
    """A skipped node (``_skipIf`` true) is not ticked and logs nothing; b (``_skipIf`` false)
    runs normally."""
    r = run(
        f'<Sequence name="q">{script("s", "x:=1")}{act("a", _skipIf="x==1")}'
        f"{act('b', _skipIf='x==2')}</Sequence>"
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("b", "IDLE", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
        ],
    }


def test_failure_if_and_success_if_replace_the_tick_when_idle() -> None:
    """``_successIf`` true: a logs IDLE->SUCCESS without being ticked. ``_failureIf`` is checked
    first: b fails although its ``_successIf`` is true too."""
    r = run(
        f'<Sequence name="q">{script("s", "x:=1")}{act("a", _successIf="x==1")}'
        f"{act('b', _failureIf='x==1', _successIf='true')}</Sequence>"
    )
    assert r.roots == ["FAILURE"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("a", "IDLE", "SUCCESS"),
            ("b", "IDLE", "FAILURE"),
            ("s", "SUCCESS", "IDLE"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "FAILURE", "IDLE"),
            ("q", "RUNNING", "FAILURE"),
            ("q", "FAILURE", "IDLE"),
        ],
    }
    assert r.executor.behaviors[r.tree.lookup("a")[0].uid].activations == 0


@pytest.mark.parametrize("attribute", ["_failureIf", "_skipIf"])
def test_failure_if_and_skip_if_are_not_checked_while_running(attribute: str) -> None:
    """x becomes 1 while a runs: ``_failureIf`` and ``_skipIf`` are only checked from IDLE,
    a completes normally."""
    r = run(
        f'<Sequence name="top">{script("s", "x:=0")}<Parallel name="p" success_count="2">'
        f'{act("a", **{attribute: "x==1"})}<Sequence name="q">{act("b")}{script("s2", "x:=1")}'
        "</Sequence></Parallel></Sequence>",
        {"a": [ok(3)], "b": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
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
        4: [
            ("a", "RUNNING", "SUCCESS"),
            ("a", "SUCCESS", "IDLE"),
            ("q", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("p", "SUCCESS", "IDLE"),
            ("top", "RUNNING", "SUCCESS"),
            ("top", "SUCCESS", "IDLE"),
        ],
    }


def test_while_false_halts_a_running_node_and_runs_on_halted() -> None:
    """``_while`` is re-evaluated while RUNNING: when x becomes 1, a is halted (RUNNING->IDLE),
    ``_onHalted`` runs, and a is skipped from then on (the Parallel keeps RUNNING)."""
    r = run(
        f'<Sequence name="top">{script("s", "x:=0")}<Parallel name="p" success_count="2">'
        f'{act("a", _while="x==0", _onHalted="h:=1")}<Sequence name="q">{act("b")}'
        f"{script('s2', 'x:=1')}</Sequence></Parallel></Sequence>",
        {"a": [ok(3)], "b": [ok(1)]},
        max_ticks=5,
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "RUNNING", "RUNNING"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("p", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
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
        3: [("a", "RUNNING", "IDLE")],
        6: [
            ("s", "SUCCESS", "IDLE"),
            ("q", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "IDLE"),
            ("top", "RUNNING", "IDLE"),
        ],
    }
    assert r.board["h"] == 1


def test_while_false_halts_a_running_control_node() -> None:
    """``_while`` on a Sequence halts it and its running child."""
    r = run(
        f'<Sequence name="top">{script("s", "x:=0")}<Parallel name="p" success_count="2">'
        f'<Sequence name="inner" _while="x==0">{act("a")}{act("c")}</Sequence>'
        f'<Sequence name="q">{act("b")}{script("s2", "x:=1")}</Sequence></Parallel></Sequence>',
        {"a": [ok(3)], "b": [ok(1)]},
        max_ticks=4,
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "RUNNING"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("p", "IDLE", "RUNNING"),
            ("inner", "IDLE", "RUNNING"),
            ("a", "IDLE", "RUNNING"),
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
        3: [("a", "RUNNING", "IDLE"), ("inner", "RUNNING", "IDLE")],
        5: [
            ("s", "SUCCESS", "IDLE"),
            ("q", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "IDLE"),
            ("top", "RUNNING", "IDLE"),
        ],
    }


def test_while_false_when_idle_skips() -> None:
    """``_while`` false from IDLE: skipped, no transition."""
    r = run(
        f'<Sequence name="q">{script("s", "x:=1")}{act("a", _while="x==0")}{act("b")}</Sequence>'
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("b", "IDLE", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
        ],
    }


def test_post_conditions_run_on_completion() -> None:
    """``_onSuccess``/``_onFailure`` run first, then ``_post``: n = (0 + 1) * 10 = 10 after a,
    then 10 + 5 = 15 after b, and m = 15."""
    r = run(
        f'<Sequence name="q">{script("s", "n:=0")}'
        f"{act('a', _onSuccess='n:=n+1', _post='n:=n*10')}"
        f"{act('b', _onFailure='n:=n+5', _post='m:=n')}</Sequence>",
        {"b": [fail()]},
    )
    assert r.roots == ["FAILURE"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("a", "IDLE", "SUCCESS"),
            ("b", "IDLE", "FAILURE"),
            ("s", "SUCCESS", "IDLE"),
            ("a", "SUCCESS", "IDLE"),
            ("b", "FAILURE", "IDLE"),
            ("q", "RUNNING", "FAILURE"),
            ("q", "FAILURE", "IDLE"),
        ],
    }
    assert (r.board["n"], r.board["m"]) == (15, 15)


def test_halted_run_at_max_ticks() -> None:
    """The teardown halts a tree still running after the last tick: children are reset in
    order (a SUCCESS->IDLE, the running b RUNNING->IDLE), then the Sequence; the halt is a
    tick of its own (tick 3), marked as the teardown."""
    r = run(f'<Sequence name="s">{act("a")}{act("b")}</Sequence>', {"b": [ok(5)]}, max_ticks=2)
    assert r.roots == ["RUNNING", "RUNNING"]
    assert r.ticks == {
        1: [("s", "IDLE", "RUNNING"), ("a", "IDLE", "SUCCESS"), ("b", "IDLE", "RUNNING")],
        3: [("a", "SUCCESS", "IDLE"), ("b", "RUNNING", "IDLE"), ("s", "RUNNING", "IDLE")],
    }
    assert [t.teardown for t in r.log.ticks] == [False, False, True]
    assert r.log.ticks[-1].root_status.name == "IDLE"
    assert r.log.ticks[-1].start_ns == r.log.ticks[-1].end_ns == r.log.ticks[-2].end_ns

"""Fallback and ReactiveFallback; the expected transitions are BT.CPP 4.8.2's.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

from tests.nodes_support import (
    act,
    cond,
    fail,
    ok,
    run,
)


def test_reactive_fallback_halts_the_running_child_when_the_condition_succeeds() -> None:
    """ReactiveFallback: the failed condition is reset every tick; its SUCCESS halts the
    running a."""
    r = run(
        f'<ReactiveFallback name="r">{cond("c")}{act("a")}</ReactiveFallback>',
        {"c": [fail(), fail(), ok()], "a": [ok(5)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("r", "IDLE", "RUNNING"),
            ("c", "IDLE", "FAILURE"),
            ("a", "IDLE", "RUNNING"),
            ("c", "FAILURE", "IDLE"),
        ],
        2: [("c", "IDLE", "FAILURE"), ("c", "FAILURE", "IDLE")],
        3: [
            ("c", "IDLE", "SUCCESS"),
            ("c", "SUCCESS", "IDLE"),
            ("a", "RUNNING", "IDLE"),
            ("r", "RUNNING", "SUCCESS"),
            ("r", "SUCCESS", "IDLE"),
        ],
    }


def test_fallback_resumes_and_succeeds() -> None:
    """Fallback resumes at the running child and resets all children on SUCCESS."""
    r = run(
        f'<Fallback name="f">{act("a")}{act("b")}{act("c")}</Fallback>',
        {"a": [fail()], "b": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("f", "IDLE", "RUNNING"), ("a", "IDLE", "FAILURE"), ("b", "IDLE", "RUNNING")],
        2: [
            ("b", "RUNNING", "SUCCESS"),
            ("a", "FAILURE", "IDLE"),
            ("b", "SUCCESS", "IDLE"),
            ("f", "RUNNING", "SUCCESS"),
            ("f", "SUCCESS", "IDLE"),
        ],
    }


def test_fallback_fails_when_every_child_fails() -> None:
    """All children failed: reset all, FAILURE."""
    r = run(f'<Fallback name="f">{act("a")}{act("b")}</Fallback>', {"a": [fail()], "b": [fail(1)]})
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("f", "IDLE", "RUNNING"), ("a", "IDLE", "FAILURE"), ("b", "IDLE", "RUNNING")],
        2: [
            ("b", "RUNNING", "FAILURE"),
            ("a", "FAILURE", "IDLE"),
            ("b", "FAILURE", "IDLE"),
            ("f", "RUNNING", "FAILURE"),
            ("f", "FAILURE", "IDLE"),
        ],
    }

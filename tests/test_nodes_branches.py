"""IfThenElse, WhileDoElse and Switch: which branch runs, and what is halted.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

import pytest

from tests.nodes_support import (
    act,
    cond,
    fail,
    ok,
    run,
    script,
)


def test_if_then_else_runs_the_then_branch() -> None:
    """The condition runs until it completes, then the then-branch; all reset at the end."""
    r = run(
        f'<IfThenElse name="i">{act("c")}{act("t")}{act("e")}</IfThenElse>',
        {"c": [ok(1)], "t": [fail(1)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("i", "IDLE", "RUNNING"), ("c", "IDLE", "RUNNING")],
        2: [("c", "RUNNING", "SUCCESS"), ("t", "IDLE", "RUNNING")],
        3: [
            ("t", "RUNNING", "FAILURE"),
            ("c", "SUCCESS", "IDLE"),
            ("t", "FAILURE", "IDLE"),
            ("i", "RUNNING", "FAILURE"),
            ("i", "FAILURE", "IDLE"),
        ],
    }


def test_if_then_else_runs_the_else_branch() -> None:
    """A failed condition selects the else-branch."""
    r = run(
        f'<IfThenElse name="i">{cond("c")}{act("t")}{act("e")}</IfThenElse>',
        {"c": [fail()], "e": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [("i", "IDLE", "RUNNING"), ("c", "IDLE", "FAILURE"), ("e", "IDLE", "RUNNING")],
        2: [
            ("e", "RUNNING", "SUCCESS"),
            ("c", "FAILURE", "IDLE"),
            ("e", "SUCCESS", "IDLE"),
            ("i", "RUNNING", "SUCCESS"),
            ("i", "SUCCESS", "IDLE"),
        ],
    }


def test_if_then_else_without_else_fails() -> None:
    """Two children and a failed condition: FAILURE. IfThenElse returns before resetting its
    children, so the condition stays FAILURE in the log."""
    r = run(f'<IfThenElse name="i">{cond("c")}{act("t")}</IfThenElse>', {"c": [fail()]})
    assert r.roots == ["FAILURE"]
    assert r.ticks == {
        1: [
            ("i", "IDLE", "RUNNING"),
            ("c", "IDLE", "FAILURE"),
            ("i", "RUNNING", "FAILURE"),
            ("i", "FAILURE", "IDLE"),
        ],
        2: [("c", "FAILURE", "IDLE")],  # the teardown resets it
    }


def test_if_then_else_is_not_reactive() -> None:
    """The condition is not evaluated again while the branch runs (c would fail on tick 2)."""
    r = run(
        f'<Sequence name="q"><IfThenElse name="i">{cond("c")}{act("t")}{act("e")}'
        "</IfThenElse></Sequence>",
        {"c": [ok(), fail()], "t": [ok(2)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("i", "IDLE", "RUNNING"),
            ("c", "IDLE", "SUCCESS"),
            ("t", "IDLE", "RUNNING"),
        ],
        3: [
            ("t", "RUNNING", "SUCCESS"),
            ("c", "SUCCESS", "IDLE"),
            ("t", "SUCCESS", "IDLE"),
            ("i", "RUNNING", "SUCCESS"),
            ("i", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
        ],
    }


def test_while_do_else_halts_the_other_branch() -> None:
    """WhileDoElse re-evaluates the condition every tick: its change halts the running branch
    (d RUNNING->IDLE) and starts the other one, and back."""
    r = run(
        f'<WhileDoElse name="w">{cond("c")}{act("d")}{act("e")}</WhileDoElse>',
        {"c": [ok(), fail(), ok()], "d": [ok(5)], "e": [ok(5)]},
        max_ticks=4,
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "RUNNING"]
    assert r.ticks == {
        1: [("w", "IDLE", "RUNNING"), ("c", "IDLE", "SUCCESS"), ("d", "IDLE", "RUNNING")],
        2: [("c", "SUCCESS", "FAILURE"), ("d", "RUNNING", "IDLE"), ("e", "IDLE", "RUNNING")],
        3: [("c", "FAILURE", "SUCCESS"), ("e", "RUNNING", "IDLE"), ("d", "IDLE", "RUNNING")],
        5: [("c", "SUCCESS", "IDLE"), ("d", "RUNNING", "IDLE"), ("w", "RUNNING", "IDLE")],
    }


def test_while_do_else_without_else_fails_and_halts_the_do_branch() -> None:
    """Two children: a failed condition halts the do-branch and fails."""
    r = run(
        f'<WhileDoElse name="w">{cond("c")}{act("d")}</WhileDoElse>',
        {"c": [ok(), fail()], "d": [ok(5)]},
    )
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [("w", "IDLE", "RUNNING"), ("c", "IDLE", "SUCCESS"), ("d", "IDLE", "RUNNING")],
        2: [
            ("c", "SUCCESS", "FAILURE"),
            ("c", "FAILURE", "IDLE"),
            ("d", "RUNNING", "IDLE"),
            ("w", "RUNNING", "FAILURE"),
            ("w", "FAILURE", "IDLE"),
        ],
    }


@pytest.mark.parametrize(
    ("value", "case"),
    [
        pytest.param("&apos;b&apos;", "b", id="strings"),
        pytest.param("2", "02", id="integers"),  # compared as integers
        pytest.param("0.5", "0.50", id="reals"),  # compared as reals
    ],
)
def test_switch_matches(value: str, case: str) -> None:
    """Switch2 compares the variable to each case as strings, then as integers, then as reals.
    It never sets itself RUNNING before ticking: its own IDLE->SUCCESS comes after the child's
    reset."""
    r = run(
        f'<Sequence name="q">{script("s", f"v:={value}")}<Switch2 name="w" variable="{{v}}" '
        f'case_1="1" case_2="{case}">{act("x")}{act("y")}{act("z")}</Switch2></Sequence>'
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("q", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("y", "IDLE", "SUCCESS"),
            ("y", "SUCCESS", "IDLE"),
            ("w", "IDLE", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("w", "SUCCESS", "IDLE"),
            ("q", "RUNNING", "SUCCESS"),
            ("q", "SUCCESS", "IDLE"),
        ],
    }


def test_switch_without_a_matching_case_or_entry_runs_the_default() -> None:
    """A missing blackboard entry selects the default (last) child."""
    r = run(
        f'<Switch2 name="w" variable="{{nothing}}" case_1="1" case_2="2">'
        f"{act('x')}{act('y')}{act('z')}</Switch2>"
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("z", "IDLE", "SUCCESS"),
            ("z", "SUCCESS", "IDLE"),
            ("w", "IDLE", "SUCCESS"),
            ("w", "SUCCESS", "IDLE"),
        ],
    }


def test_switch_change_of_case_halts_the_running_child() -> None:
    """The variable changes while x runs: x is halted (RUNNING->IDLE) and y starts, same tick."""
    r = run(
        f'<Sequence name="top">{script("s", "v:=1")}<Parallel name="p" success_count="2">'
        f'<Switch2 name="w" variable="{{v}}" case_1="1" case_2="2">{act("x")}{act("y")}'
        f'{act("d")}</Switch2><Sequence name="q">{act("b")}{script("s2", "v:=2")}</Sequence>'
        "</Parallel></Sequence>",
        {"x": [ok(5)], "y": [ok(1)], "b": [ok(1)]},
    )
    assert r.roots == ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("p", "IDLE", "RUNNING"),
            ("x", "IDLE", "RUNNING"),
            ("w", "IDLE", "RUNNING"),
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
        3: [("x", "RUNNING", "IDLE"), ("y", "IDLE", "RUNNING")],
        4: [
            ("y", "RUNNING", "SUCCESS"),
            ("y", "SUCCESS", "IDLE"),
            ("w", "RUNNING", "SUCCESS"),
            ("w", "SUCCESS", "IDLE"),
            ("q", "SUCCESS", "IDLE"),
            ("p", "RUNNING", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("p", "SUCCESS", "IDLE"),
            ("top", "RUNNING", "SUCCESS"),
            ("top", "SUCCESS", "IDLE"),
        ],
    }


def test_switch_with_a_skipped_child_is_skipped() -> None:
    """The selected child is skipped: the Switch returns SKIPPED and logs nothing."""
    r = run(
        f'<Switch2 name="w" variable="1" case_1="1" case_2="2">'
        f'<AlwaysSuccess name="x" _skipIf="true"/>{act("y")}{act("z")}</Switch2>',
        max_ticks=2,
    )
    assert r.roots == ["SKIPPED", "SKIPPED"]
    assert r.ticks == {}


def test_switch_does_not_accept_digit_separators() -> None:
    """BT.CPP's CheckStringEquality parses with from_chars/stoi: "1_0" is not the integer 10,
    so the default child runs (verified with BT.CPP 4.8.2)."""
    r = run(
        f'<Switch2 name="w" variable="1_0" case_1="10" case_2="2">'
        f"{act('x')}{act('y')}{act('z')}</Switch2>"
    )
    assert r.ticks[1][0] == ("z", "IDLE", "SUCCESS")

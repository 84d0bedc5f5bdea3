"""Every node BehaviorTree.CPP 4 registers by default is built into btlog, with BT.CPP's
ports and semantics: the list below is the ``BehaviorTreeFactory`` constructor of BT.CPP
4.10.0 (``src/bt_factory.cpp``); the newer nodes' runs are compared with BT.CPP itself
(behaviortreepy, BT.CPP 4.8.2) where it has them, and with hand-checked transitions."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from btlog.executor.engine import BUILTIN_BEHAVIORS
from btlog.tree.model import ACTION, CONDITION, CONTROL, DECORATOR, INOUT, INPUT, OUTPUT, SUBTREE
from btlog.tree.registry import Registry
from tests.nodes_support import DEFAULT_OUTCOME, act, cond, fail, ok, run, xml
from tests.oracle.runner import have_behaviortreepy, run_oracle


def _switch(cases: int) -> dict:
    return {"variable": (INPUT, None), **{f"case_{i}": (INPUT, None) for i in range(1, cases + 1)}}


_LOOP = {"queue": (INOUT, None), "if_empty": (INPUT, "SUCCESS"), "value": (OUTPUT, None)}
_ENTRY = {"entry": (INPUT, None)}

#: BT.CPP 4.10.0's default registrations, in the constructor's order: ID -> (kind, ports as
#: name -> (direction, default)), from each node's ``providedPorts``. SequenceStar (only
#: with USE_BTCPP3_OLD_NAMES) is btlog's v3 alias of SequenceWithMemory.
BTCPP_DEFAULT_REGISTRATIONS: dict[str, tuple[str, dict]] = {
    "Fallback": (CONTROL, {}),
    "AsyncFallback": (CONTROL, {}),
    "Sequence": (CONTROL, {}),
    "AsyncSequence": (CONTROL, {}),
    "SequenceWithMemory": (CONTROL, {}),
    "Parallel": (CONTROL, {"success_count": (INPUT, "-1"), "failure_count": (INPUT, "1")}),
    "ParallelAll": (CONTROL, {"max_failures": (INPUT, "1")}),
    "ReactiveSequence": (CONTROL, {}),
    "ReactiveFallback": (CONTROL, {}),
    "IfThenElse": (CONTROL, {}),
    "WhileDoElse": (CONTROL, {}),
    "TryCatch": (CONTROL, {"catch_on_halt": (INPUT, "false")}),
    "Inverter": (DECORATOR, {}),
    "RetryUntilSuccessful": (DECORATOR, {"num_attempts": (INPUT, None)}),
    "KeepRunningUntilFailure": (DECORATOR, {}),
    "Repeat": (DECORATOR, {"num_cycles": (INPUT, None)}),
    "Timeout": (DECORATOR, {"msec": (INPUT, None)}),
    "Delay": (DECORATOR, {"delay_msec": (INPUT, None)}),
    "RunOnce": (DECORATOR, {"then_skip": (INPUT, "true")}),
    "ForceSuccess": (DECORATOR, {}),
    "ForceFailure": (DECORATOR, {}),
    "AlwaysSuccess": (ACTION, {}),
    "AlwaysFailure": (ACTION, {}),
    "Script": (ACTION, {"code": (INPUT, None)}),
    "ScriptCondition": (CONDITION, {"code": (INPUT, None)}),
    "SetBlackboard": (ACTION, {"value": (INPUT, None), "output_key": (INOUT, None)}),
    "Sleep": (ACTION, {"msec": (INPUT, None)}),
    "UnsetBlackboard": (ACTION, {"key": (INPUT, None)}),
    "SubTree": (SUBTREE, {}),
    "Precondition": (DECORATOR, {"if": (INPUT, None), "else": (INPUT, "FAILURE")}),
    **{f"Switch{n}": (CONTROL, _switch(n)) for n in range(2, 7)},
    "LoopInt": (DECORATOR, _LOOP),
    "LoopBool": (DECORATOR, _LOOP),
    "LoopDouble": (DECORATOR, _LOOP),
    "LoopString": (DECORATOR, _LOOP),
    "WasEntryUpdated": (ACTION, _ENTRY),
    "SkipUnlessUpdated": (DECORATOR, _ENTRY),
    "WaitValueUpdate": (DECORATOR, _ENTRY),
}


@pytest.mark.parametrize("type_id", list(BTCPP_DEFAULT_REGISTRATIONS))
def test_every_default_registration_is_built_in(type_id: str) -> None:
    """Declared with BT.CPP's kind and ports (direction, default), and implemented."""
    kind, ports = BTCPP_DEFAULT_REGISTRATIONS[type_id]
    declared = Registry().get(type_id)
    assert declared is not None, f"{type_id} is not declared in btlog's registry"
    assert not declared.declared_only
    assert declared.kind == kind
    assert type_id in BUILTIN_BEHAVIORS, f"{type_id} has no implementation"
    for port, (direction, default) in ports.items():
        assert port in declared.ports, f"{type_id} lacks port {port!r}"
        spec = declared.ports[port]
        assert (spec.direction, spec.default) == (direction, default), (type_id, port)


def test_every_builtin_behaviour_documents_its_policy() -> None:
    """Each class states its own policy (a docstring of its own, not its base's)."""
    for type_id in BTCPP_DEFAULT_REGISTRATIONS:
        doc = vars(BUILTIN_BEHAVIORS[type_id]).get("__doc__") or ""
        assert doc.strip(), f"{type_id} has no docstring stating its policy"


# -- runs compared with BT.CPP -----------------------------------------------------------
def _loop_body(loop: str, queue: str, extra: str = "") -> str:
    return (
        f'<Sequence name="s"><{loop} name="L" queue="{queue}" value="{{v}}"{extra}>'
        f'<Sequence name="b"><ScriptCondition name="seen" code="v != 99"/>{act("a")}'
        f"</Sequence></{loop}>"
        f'<ScriptCondition name="last" code="v == 3"/></Sequence>'
    )


#: name -> (body, scripted outcomes); each runs for 12 ticks in btlog and in BT.CPP 4.8.2.
CASES: dict[str, tuple[str, dict]] = {
    "LoopInt pops each element": (_loop_body("LoopInt", "1;2;3"), {"a": [ok(1)]}),
    "LoopDouble from a blackboard string": (
        '<Sequence name="s"><Script name="set" code="q:=\'0.5;1.5;3\'"/>'
        + _loop_body("LoopDouble", "{q}").removeprefix('<Sequence name="s">'),
        {},
    ),
    "LoopString child failure fails": (
        '<LoopString name="L" queue="x;y;z" value="{v}">' + act("a") + "</LoopString>",
        {"a": [ok(), fail()]},
    ),
    "LoopBool empty queue is if_empty": (
        '<Fallback name="f"><LoopBool name="L" queue="" if_empty="FAILURE" value="{v}">'
        + act("a")
        + "</LoopBool>"
        + act("other")
        + "</Fallback>",
        {},
    ),
    "AsyncSequence yields to its reactive parent": (
        '<ReactiveSequence name="r">'
        + cond("c")
        + '<AsyncSequence name="s">'
        + act("a")
        + act("b")
        + act("d")
        + "</AsyncSequence></ReactiveSequence>",
        {"c": [ok(), ok(), fail()]},
    ),
    "AsyncFallback yields after a failure": (
        '<AsyncFallback name="f">' + act("a") + act("b") + act("d") + "</AsyncFallback>",
        {"a": [fail()], "b": [fail(1)]},
    ),
    "SkipUnlessUpdated and WasEntryUpdated": (
        '<Sequence name="s"><Script name="w0" code="x:=1"/>'
        '<Repeat name="twice" num_cycles="2"><ForceSuccess name="fs">'
        '<WasEntryUpdated name="stale" entry="x"/></ForceSuccess></Repeat>'
        '<Repeat name="rep" num_cycles="2"><Sequence name="s2">'
        '<SkipUnlessUpdated name="u" entry="{x}">' + act("a") + "</SkipUnlessUpdated>"
        '<Script name="w" code="x:=1"/></Sequence></Repeat>'
        '<SkipUnlessUpdated name="missing" entry="{y}">' + act("b") + "</SkipUnlessUpdated>"
        "</Sequence>",
        {},
    ),
    "a port's entry exists, empty, from the start: = assigns it": (
        '<Sequence name="s"><Script name="set" code="x = 5"/>'
        '<ScriptCondition name="chk" code="x == 5"/>'
        '<LoopInt name="L" queue="1;2" value="{x}"><AlwaysSuccess name="ok"/></LoopInt>'
        "</Sequence>",
        {},
    ),
    "WaitValueUpdate waits for a write": (
        '<Parallel name="p" success_count="2"><WaitValueUpdate name="u" entry="{x}">'
        + act("a")
        + '</WaitValueUpdate><Sequence name="s2">'
        + act("slow")
        + '<Script name="w" code="x:=2"/></Sequence></Parallel>',
        {"slow": [ok(2)]},
    ),
}


@pytest.fixture(scope="module")
def btcpp_runs() -> dict[str, dict | None]:
    if not have_behaviortreepy():
        pytest.skip("behaviortreepy missing")

    def oracle(case: tuple[str, dict]) -> dict | None:
        body, nodes = case
        outcomes = {"default": DEFAULT_OUTCOME, "nodes": nodes}
        return run_oracle({"xml": xml(body), "max_ticks": 12, "outcomes": outcomes})

    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(zip(CASES, pool.map(oracle, CASES.values()), strict=True))


@pytest.mark.parametrize("name", list(CASES))
def test_run_equals_btcpp(btcpp_runs, name: str) -> None:
    body, nodes = CASES[name]
    ours = run(body, nodes, max_ticks=12, oracle=False)
    theirs = btcpp_runs[name]
    assert theirs is not None and theirs["error"] is None, theirs
    assert theirs["transitions"] == ours.flat
    assert theirs["root"] == ours.roots


def test_loop_writes_each_element_typed() -> None:
    result = run(*CASES["LoopInt pops each element"], max_ticks=12, oracle=False)
    assert [value for _, key, value in result.writes() if key == "v"] == [1, 2, 3]
    assert result.roots[-1] == "SUCCESS"
    doubles = run(*CASES["LoopDouble from a blackboard string"], max_ticks=12, oracle=False)
    assert [value for _, key, value in doubles.writes() if key == "v"] == [0.5, 1.5, 3.0]


def test_loop_over_a_list_entry_copies_it() -> None:
    """A list (what a scripted leaf's output or an outcomes file's blackboard holds) is
    iterated over a copy: the entry keeps its elements."""
    from btlog.executor.engine import Executor
    from btlog.tree.loader import load_tree_text

    tree = load_tree_text(
        xml('<LoopString name="L" queue="{q}" value="{v}"><AlwaysSuccess/></LoopString>')
    )
    executor = Executor(tree)
    executor.root_board.preset("q", ["a", "b"])
    seen = []
    for _ in range(4):
        status = executor.tick()
        seen.append((executor.root_board.entries.get("v"), status.name))
    # the queue emptied: if_empty (SUCCESS); the next run starts over from the entry
    assert seen == [("a", "RUNNING"), ("b", "RUNNING"), ("b", "SUCCESS"), ("a", "RUNNING")]
    assert executor.root_board.entries["q"] == ["a", "b"]


def test_entry_updated_counts_writes_not_values() -> None:
    """A node sees a write once; a write of the same value is a write; a missing entry is
    no update."""
    result = run(*CASES["SkipUnlessUpdated and WasEntryUpdated"], max_ticks=12, oracle=False)
    transitions = [t for items in result.ticks.values() for t in items]
    stale = [t for t in transitions if t[0] == "stale" and t[1] == "IDLE"]
    assert stale == [("stale", "IDLE", "SUCCESS"), ("stale", "IDLE", "FAILURE")]
    assert transitions.count(("a", "IDLE", "SUCCESS")) == 2
    assert not any(t[0] == "b" for t in transitions)
    assert result.roots[-1] == "SUCCESS"


# -- TryCatch (BT.CPP 4.9+, not in behaviortreepy): checked by hand against its source -----
def test_try_catch_succeeds_like_a_sequence() -> None:
    result = run(
        '<TryCatch name="t">' + act("a") + act("b") + act("catch") + "</TryCatch>",
        {"a": [ok(1)]},
        oracle=False,
    )
    assert result.roots == ["RUNNING", "SUCCESS"]
    assert not any(t[0] == "catch" for items in result.ticks.values() for t in items)


def test_try_catch_runs_the_catch_then_fails() -> None:
    result = run(
        '<TryCatch name="t">' + act("a") + act("b") + act("catch") + "</TryCatch>",
        {"b": [fail()], "catch": [ok(1)]},
        oracle=False,
    )
    assert result.roots == ["RUNNING", "FAILURE"]
    assert result.ticks[1] == [
        ("t", "IDLE", "RUNNING"),
        ("a", "IDLE", "SUCCESS"),
        ("b", "IDLE", "FAILURE"),
        ("a", "SUCCESS", "IDLE"),
        ("b", "FAILURE", "IDLE"),
        ("catch", "IDLE", "RUNNING"),
    ]
    assert result.ticks[2] == [
        ("catch", "RUNNING", "SUCCESS"),
        ("catch", "SUCCESS", "IDLE"),
        ("t", "RUNNING", "FAILURE"),
        ("t", "FAILURE", "IDLE"),
    ]


@pytest.mark.parametrize("catch_on_halt", ["true", "false"])
def test_try_catch_on_halt(catch_on_halt: str) -> None:
    """Halted while the try block runs: with ``catch_on_halt`` the catch is ticked once
    (and halted, being RUNNING); without, it never runs."""
    result = run(
        '<ReactiveSequence name="r">'
        + cond("c")
        + f'<TryCatch name="t" catch_on_halt="{catch_on_halt}">'
        + act("a")
        + act("catch")
        + "</TryCatch></ReactiveSequence>",
        {"c": [ok(), fail()], "a": [ok(5)], "catch": [ok(3)]},
        oracle=False,
    )
    catch = [t for t in result.ticks[2] if t[0] == "catch"]
    if catch_on_halt == "true":
        assert catch == [("catch", "IDLE", "RUNNING"), ("catch", "RUNNING", "IDLE")]
    else:
        assert catch == []
    assert result.roots == ["RUNNING", "FAILURE"]


def test_try_catch_needs_a_catch() -> None:
    from btlog.tree.loader import TreeError, load_tree_text

    with pytest.raises(TreeError, match="TryCatch must have at least 2 children"):
        load_tree_text(xml('<TryCatch name="t"><AlwaysSuccess/></TryCatch>'))


# -- "What will you do next?" knows the new nodes ----------------------------------------
def _next_after(body: str, nodes: dict, ticks: int, node: str, status: str) -> list[str] | None:
    """The execution nodes ticked next if ``node`` completed with ``status`` after
    ``ticks`` ticks (``explain.flow.after``), by name."""
    from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
    from btlog.executor.engine import Executor
    from btlog.explain.flow import after
    from btlog.history import LiveHistory
    from btlog.status import Status
    from btlog.tree.loader import load_tree_text

    tree = load_tree_text(xml(body))
    outcomes = Outcomes.from_mapping({"default": DEFAULT_OUTCOME, "nodes": nodes})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    live = LiveHistory(tree)
    executor.subscribe(live)
    for _ in range(ticks):
        executor.tick()
    [target] = tree.lookup(node)
    following = after(target, Status[status], live.state, live)
    return None if following is None else [n.name for n in following]


def test_what_next_in_a_try_catch() -> None:
    body = '<TryCatch name="t">' + act("a") + act("b") + act("catch") + "</TryCatch>"
    nodes = {"a": [ok(5)]}
    assert _next_after(body, nodes, 1, "a", "SUCCESS") == ["b"]
    assert _next_after(body, nodes, 1, "a", "FAILURE") == ["catch"]
    assert _next_after(body, nodes, 1, "catch", "SUCCESS") is None  # the tree fails


def test_what_next_in_a_loop() -> None:
    body = (
        '<Sequence name="s"><LoopInt name="L" queue="1;2" value="{v}">'
        + act("a")
        + "</LoopInt>"
        + act("after")
        + "</Sequence>"
    )
    nodes = {"a": [ok(2)]}
    assert _next_after(body, nodes, 1, "a", "SUCCESS") == ["a"]  # element 2 is next
    assert _next_after(body, nodes, 4, "a", "SUCCESS") == ["after"]  # the last element

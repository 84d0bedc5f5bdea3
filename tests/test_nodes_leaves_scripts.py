"""Built-in leaves: Script, ScriptCondition, SetBlackboard, UnsetBlackboard, typed ports
and the scripted leaves of an outcomes file.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

from typing import ClassVar

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import BlackboardWrite, EventLog
from btlog.executor.actions import InputPort, OutputPort, SyncAction
from btlog.executor.behavior import NodeExecutionError
from btlog.executor.engine import Executor
from btlog.status import SUCCESS, Status
from btlog.tree.loader import TreeError, load_tree_text
from btlog.tree.registry import Registry
from tests.nodes_support import (
    DEFAULT_OUTCOME,
    Run,
    act,
    build,
    collect,
    error_of,
    fail,
    ok,
    run,
    script,
    xml,
)


# -- Script, ScriptCondition ------------------------------------------------------------------
@pytest.mark.parametrize(
    ("setup", "check"),
    [
        ("a:=3; b:=4", "a + b == 7"),
        ("a:=3; b:=4", "a * b - 2 == 10"),
        ("a:=7; b:=2", "a / b == 3.5"),
        ("a:=1", "(a + 2) * 3 == 9"),
        ("a:=3", "a += 2; a == 5"),
        ("a:=3", "a -= 5; a == -2"),
        ("a:=3", "a *= 3; a == 9"),
        ("a:=2", "a = 5; a == 5"),
        ("a:=2", "-a * -a == 4"),
        ("a:=0x10", "a == 16"),
        ("a:=6", "(a &amp; 3) == 2"),
        ("a:=6", "(a | 1) == 7"),
        ("a:=6", "(a ^ 2) == 4"),
        ("a:=3; b:=5", "a &lt; b &amp;&amp; b &lt;= 5 &amp;&amp; !(a &gt;= b)"),
        ("a:=3; b:=5", "a &gt; b || b == 5"),
        ("a:=3", "a == 3.0"),
        ("a:='5'", "a == 5"),
        ("a:=true", "a"),
        ("a:=false", "!a"),
        ("a:=true", "a + 1 == 2"),
        ("s:='ab'", "s .. 'cd' == 'abcd'"),
        ("s:='5'", "s + '1' == '51'"),  # + joins two strings, numbers or not (BT.CPP)
        ("s:='ab'", "s == 'ab' &amp;&amp; s != 'ba'"),
        ("s:='abc'", "s &lt; 'abd'"),
        ("a:=1", "a .. 'x' == '1x'"),
        ("a:=3", "a &gt; 2 ? true : false"),
        ("a:=3", "x := a &gt; 2 ? 'big' : 'small'; x == 'big'"),
        ("a:=1", "(a &gt; 2) ? false : true"),
    ],
)
def test_script_condition_is_true(setup: str, check: str) -> None:
    """Assignments, arithmetic (left-associative, as BT.CPP HEAD), comparisons, logic,
    bitwise operators, strings and the ternary, each checked by a ScriptCondition."""
    r = run(
        f'<Sequence name="q">{script("s", setup)}'
        f'<ScriptCondition name="c" code="{check}"/></Sequence>'
    )
    assert r.roots == ["SUCCESS"]


def test_script_arithmetic_is_left_associative() -> None:
    """``a - 2 - 3`` is ``(a - 2) - 3`` and ``a / 2 / 3`` is ``(a / 2) / 3``, as in BT.CPP HEAD
    (BT.CPP 4.8.2 grouped them from the right: 10 - (2 - 3) = 11; fixed by the new parser)."""
    r = run(
        f'<Sequence name="q">{script("s", "a:=10; b:=12")}'
        '<ScriptCondition name="c" code="a - 2 - 3 == 5 &amp;&amp; b / 2 / 3 == 2"/>'
        "</Sequence>",
        oracle=False,
    )
    assert r.roots == ["SUCCESS"]


def test_script_condition_false_fails() -> None:
    """A false ScriptCondition logs IDLE->FAILURE."""
    r = run('<ScriptCondition name="c" code="1 &gt; 2"/>')
    assert r.roots == ["FAILURE"]
    assert r.ticks == {1: [("c", "IDLE", "FAILURE"), ("c", "FAILURE", "IDLE")]}


def test_script_writes_typed_values() -> None:
    """Script creates entries with ``:=``; every write is reported with its writer."""
    r = run(
        script(
            "s",
            "a:=3; b:=a*2+1; s:='x' .. 'y'; t:= a &gt; 2 ? 'big' : 'small'; "
            "a += 1; f:=1.5; ok:=true",
        )
    )
    assert r.board == {"a": 4, "b": 7, "s": "xy", "t": "big", "f": 1.5, "ok": True}
    uid = r.tree.lookup("s")[0].uid
    writes = [e for e in r.log.events if isinstance(e, BlackboardWrite)]
    assert [(e.key, e.type, e.writer_uid) for e in writes] == [
        ("a", "int", uid),
        ("b", "int", uid),
        ("s", "str", uid),
        ("t", "str", uid),
        ("a", "int", uid),
        ("f", "float", uid),
        ("ok", "bool", uid),
    ]


@pytest.mark.parametrize(
    ("code", "problem"),
    [
        ("x := y + 1", "variable 'y' is not on the blackboard"),
        ("z = 1", "variable 'z' does not exist"),
        ("s := 'a'; s + 1", "'a' is not a number"),
    ],
)
def test_script_runtime_errors_name_the_node(code: str, problem: str) -> None:
    """A script failing at run time raises NodeExecutionError naming the node and file:line."""
    _, executor, _ = build(xml(f'<Sequence name="q">\n{script("bad", code)}\n</Sequence>'))
    with pytest.raises(NodeExecutionError) as caught:
        executor.tick()
    assert caught.value.node.name == "bad"
    assert "node 'bad'" in str(caught.value) and problem in str(caught.value)
    assert str(caught.value).startswith("<string>:4:")


def test_script_bitwise_operators_bind_tighter_than_comparisons() -> None:
    """BT.CPP HEAD binding powers: comparison 10 < bitwise or/xor 12 < bitwise and 14.
    Verified with BT.CPP 4.8.2: ``a & 3 == 2`` with a=6 is true, ``a | 2 == 2`` with a=1
    is false."""
    r = run(
        f'<Sequence name="q">{script("s", "a:=6; b:=1")}'
        '<ScriptCondition name="c" code="a &amp; 3 == 2"/>'
        '<Inverter name="i"><ScriptCondition name="d" code="b | 2 == 2"/></Inverter>'
        "</Sequence>"
    )
    assert r.roots == ["SUCCESS"]


def test_script_chained_comparisons() -> None:
    """BT.CPP parses ``x < y < z`` as a chain of comparisons (parseChainedComparison at HEAD;
    verified with BT.CPP 4.8.2: ``a > 2 > 1`` with a=3 is true)."""
    r = run(
        f'<Sequence name="q">{script("s", "a:=3")}'
        '<ScriptCondition name="c" code="a &gt; 2 &gt; 1"/></Sequence>'
    )
    assert r.roots == ["SUCCESS"]


def test_script_division_by_zero_is_infinite() -> None:
    """BT.CPP ``ExprBinaryArithmetic``: numbers are cast to double, ``lv / rv``. Verified with
    BT.CPP 4.8.2: ``a / 0 > 1000`` with a=1 is true, ``a / 0 == a / 0`` with a=0 is false."""
    r = run(
        f'<Sequence name="q">{script("s", "a:=1; z:=0")}'
        '<ScriptCondition name="c" code="a / 0 &gt; 1000"/>'
        '<Inverter name="i"><ScriptCondition name="d" code="z / 0 == z / 0"/></Inverter>'
        "</Sequence>"
    )
    assert r.roots == ["SUCCESS"]


@pytest.mark.parametrize(
    ("element", "attribute"),
    [
        ('<Script name="n" code="x :="/>', "code"),
        ('<ScriptCondition name="n" code="x =="/>', "code"),
        ('<Precondition name="n" if="x =="><AlwaysSuccess/></Precondition>', "if"),
    ],
)
def test_script_syntax_errors_name_the_node(element: str, attribute: str) -> None:
    """BT.CPP parses the script in the node's constructor and refuses the tree: the loader
    refuses it with a TreeError naming the line of the element and the attribute."""
    with pytest.raises(TreeError) as caught:
        load_tree_text(xml(f'<Sequence name="q">\n{element}</Sequence>'), file="tree.xml")
    assert (caught.value.file, caught.value.line) == ("tree.xml", 4)
    assert str(caught.value) == f"tree.xml:4: {attribute}: unexpected 'end of script'"


# -- SetBlackboard, UnsetBlackboard -----------------------------------------------------------
def test_set_and_unset_blackboard() -> None:
    """SetBlackboard writes a literal (as a string) or copies another entry (with its type);
    UnsetBlackboard removes an entry (reported as a write of type "unset"), and removing a
    missing entry is not an error."""
    r = run(
        f'<Sequence name="q">{script("s", "src:=42")}'
        '<SetBlackboard name="s1" value="7" output_key="k"/>'
        '<SetBlackboard name="s2" value="{src}" output_key="k2"/>'
        '<UnsetBlackboard name="u" key="k"/><UnsetBlackboard name="u2" key="absent"/>'
        "</Sequence>"
    )
    assert r.roots == ["SUCCESS"]
    assert r.board == {"src": 42, "k2": 42}
    writes = [e for e in r.log.events if isinstance(e, BlackboardWrite)]
    assert [(e.key, e.value, e.type) for e in writes] == [
        ("src", 42, "int"),
        ("k", "7", "str"),
        ("k2", 42, "int"),
        ("k", None, "unset"),
    ]


def test_set_blackboard_output_key_reference_is_read_through() -> None:
    """BT.CPP: ``getInput("output_key", output_key)`` (verified with BT.CPP 4.8.2: "missing
    port [output_key]" when entry k2 does not exist)."""
    _, executor, _ = build(xml('<SetBlackboard name="s" value="1" output_key="{k2}"/>'))
    with pytest.raises(NodeExecutionError, match="node 's'"):
        executor.tick()


def test_unset_blackboard_key_reference_is_read_through() -> None:
    """BT.CPP: ``getInput("key", key); blackboard->unset(key)``. Verified with BT.CPP 4.8.2:
    with k = 1, ``key="{k}"`` removes entry "1", so k still exists afterwards."""
    r = run(
        '<Sequence name="q"><SetBlackboard name="s" value="1" output_key="k"/>'
        '<UnsetBlackboard name="u" key="{k}"/>'
        '<ScriptCondition name="c" code="k == 1"/></Sequence>'
    )
    assert r.roots == ["SUCCESS"]


@pytest.mark.parametrize(
    "element",
    [
        '<SetBlackboard name="n" value="1"/>',
        '<SetBlackboard name="n" output_key="k"/>',
        '<UnsetBlackboard name="n"/>',
    ],
)
def test_blackboard_nodes_without_ports_name_the_node(element: str) -> None:
    """BT.CPP throws "missing port [output_key]" / "missing input port [key]"."""
    _, executor, _ = build(xml(element))
    with pytest.raises(NodeExecutionError, match="node 'n'"):
        executor.tick()


# -- typed ports --------------------------------------------------------------------------
class Typed(SyncAction):
    """A leaf reading one port of each type and writing them as a list."""

    ports: ClassVar[dict] = {
        "i": InputPort("int"),
        "f": InputPort("float"),
        "b": InputPort("bool"),
        "s": InputPort("str"),
        "j": InputPort("json"),
        "out": OutputPort(),
    }

    def tick(self) -> Status:
        self.set_output("out", [self.get_input(name) for name in "ifbsj"])
        return SUCCESS


def typed_run(attributes: str, setup: str = "") -> Run:
    """Run a Typed leaf after an optional Script."""
    registry = Registry()
    registry.register_leaf(Typed)
    text = xml(
        f'<Sequence name="q">{script("s", setup) if setup else ""}'
        f'\n<Typed name="t" {attributes} out="{{out}}"/></Sequence>'
    )
    tree = load_tree_text(text, registry)
    executor = Executor(tree, registry)
    log = EventLog()
    executor.subscribe(log)
    executor.run(3)
    return collect(tree, executor, log)


def test_typed_port_literals() -> None:
    """Literals are converted to the declared type when read. A JSON object needs BT.CPP's
    ``json:`` prefix: ``{...}`` alone is a blackboard reference."""
    r = typed_run('i="-3" f="2.5" b="true" s=" x " j="json:{&quot;a&quot;: [1, 2]}"')
    assert r.board["out"] == [-3, 2.5, True, " x ", {"a": [1, 2]}]


def test_typed_port_blackboard_values() -> None:
    """Blackboard entries are converted too: strings are parsed, an integral float is an int."""
    r = typed_run(
        'i="{i}" f="{f}" b="{b}" s="{s}" j="{j}"', "i:='7'; f:=2; b:='false'; s:=5; j:='json:[1]'"
    )
    assert r.board["out"] == [7, 2.0, False, 5, [1]]
    r = typed_run('i="{i}" f="1" b="1" s="" j="null"', "i:=7.0")
    assert r.board["out"][0] == 7


@pytest.mark.parametrize(
    ("attributes", "port"),
    [
        ('i="x" f="1" b="1" s="" j="1"', "i"),
        ('i="1" f="one" b="1" s="" j="1"', "f"),
        ('i="1" f="1" b="2" s="" j="1"', "b"),
        ('i="1" f="1" b="1" s="" j="{nope"', "j"),
    ],
)
def test_bad_typed_literal_is_refused_at_load(attributes: str, port: str) -> None:
    """A literal that cannot be converted is a load error with file:line, naming the port."""
    registry = Registry()
    registry.register_leaf(Typed)
    with pytest.raises(TreeError) as caught:
        load_tree_text(
            xml(f'<Sequence name="q">\n<Typed name="t" {attributes} out="{{o}}"/></Sequence>'),
            registry,
            file="t.xml",
        )
    assert caught.value.line == 4 and f"port '{port}'" in str(caught.value)


@pytest.mark.parametrize(
    ("setup", "problem"),
    [
        ("i:='x'", "port 'i': 'x' is not a valid int"),
        ("i:=7.5", "port 'i': 7.5 is not a valid int"),
        ("", "port 'i': blackboard entry 'i' does not exist"),
    ],
)
def test_bad_port_value_at_run_time_names_the_node(setup: str, problem: str) -> None:
    """A blackboard value that cannot be converted raises NodeExecutionError naming the node."""
    with pytest.raises(NodeExecutionError) as caught:
        typed_run('i="{i}" f="1" b="1" s="" j="1"', setup)
    assert caught.value.node.name == "t"
    assert "node 't'" in str(caught.value) and problem in str(caught.value)


def test_missing_required_port_names_the_node() -> None:
    """A required port without value or default is refused when the executor is built
    (before any tick: ``btlog validate`` finds it too), naming the node."""
    with pytest.raises(NodeExecutionError, match=r"node 'r'.*'num_cycles' is not set"):
        build(xml('<Repeat name="r"><AlwaysSuccess name="a"/></Repeat>'))


@pytest.mark.parametrize("value", ["yes", "off", "tRuE"])
def test_bool_port_accepts_only_btcpp_words(value: str) -> None:
    """BT.CPP ``convertFromString<bool>``; the loader checks literals of built-in ports."""
    error_of(xml(f'<RunOnce name="o" then_skip="{value}"><AlwaysSuccess/></RunOnce>'))


def test_scripted_condition_from_outcomes_is_reevaluated_every_tick() -> None:
    """A ``<Condition ID=..>`` leaf built by ``scripted_leaf_factory`` should behave as a
    BT.CPP ConditionNode: evaluated on every tick. Under WhileDoElse the condition is not
    reset between ticks, so its second entry (FAILURE) must be used at tick 2."""
    text = xml(
        f'<WhileDoElse name="w"><Condition ID="Check" name="c"/>{act("d")}{act("e")}</WhileDoElse>'
    )
    tree = load_tree_text(text)
    outcomes = Outcomes.from_mapping(
        {"default": DEFAULT_OUTCOME, "nodes": {"c": [ok(), fail()], "d": [ok(5)]}}
    )
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    log = EventLog()
    executor.subscribe(log)
    executor.run(2)
    result = collect(tree, executor, log)
    assert ("c", "SUCCESS", "FAILURE") in result.ticks[2]

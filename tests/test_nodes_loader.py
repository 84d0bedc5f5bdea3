"""The loader: uids, names and paths as BT.CPP gives them, v3 trees, and load errors
that name the file and line.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.domains import make_domain
from btlog.domains.outcomes import Outcomes
from btlog.executor.engine import Executor
from btlog.status import SUCCESS
from btlog.tree.loader import load_tree, load_tree_text
from tests.nodes_support import (
    ROOT,
    error_of,
    load,
    xml,
)

# -- loader: uids, names, paths ---------------------------------------------------------------
NESTED = xml(
    '<Sequence name="top"><Leaf/><Leaf name="x"/><Leaf name=""/><SubTree ID="Sub"/>'
    '<SubTree ID="Sub" name="named"/><Leaf name="Leaf"/><Sequence><Leaf name="after"/>'
    "</Sequence></Sequence>",
    '<BehaviorTree ID="Sub"><Sequence name="ss"><Leaf name="in"/><SubTree ID="Sub2"/>'
    '<SubTree ID="Sub2" name="deep"/></Sequence></BehaviorTree>'
    '<BehaviorTree ID="Sub2"><Leaf name="in2"/></BehaviorTree>',
)


def test_uids_names_and_paths_follow_btcpp() -> None:
    """UIDs in DFS pre-order with each subtree's nodes right after its SubTree node; a
    missing name is the type and the path gets ``::uid``; ``name=""`` stays empty; a
    subtree's prefix is its name or ``ID::uid``. The leaves' uids and paths were checked
    against BT.CPP 4.8.2 (``TreeNode::full_path``)."""
    tree = load_tree_text(NESTED)
    assert [(n.uid, n.type, n.name, n.path) for n in tree] == [
        (1, "Sequence", "top", "top"),
        (2, "Leaf", "Leaf", "Leaf::2"),
        (3, "Leaf", "x", "x"),
        (4, "Leaf", "", ""),
        (5, "SubTree", "Sub", "Sub::5"),
        (6, "Sequence", "ss", "Sub::5/ss"),
        (7, "Leaf", "in", "Sub::5/in"),
        (8, "SubTree", "Sub2", "Sub::5/Sub2::8"),
        (9, "Leaf", "in2", "Sub::5/Sub2::8/in2"),
        (10, "SubTree", "deep", "Sub::5/deep"),
        (11, "Leaf", "in2", "Sub::5/deep/in2"),
        (12, "SubTree", "named", "named"),
        (13, "Sequence", "ss", "named/ss"),
        (14, "Leaf", "in", "named/in"),
        (15, "SubTree", "Sub2", "named/Sub2::15"),
        (16, "Leaf", "in2", "named/Sub2::15/in2"),
        (17, "SubTree", "deep", "named/deep"),
        (18, "Leaf", "in2", "named/deep/in2"),
        (19, "Leaf", "Leaf", "Leaf::19"),
        (20, "Sequence", "Sequence", "Sequence::20"),
        (21, "Leaf", "after", "after"),
    ]
    assert tree.node(9).scope == "Sub::5/Sub2::8"
    assert [c.uid for c in tree.node(5).children] == [6]


def test_generic_form_and_default_ports() -> None:
    """``<Action ID=..>`` takes the ID as its type and name; declared defaults fill ports."""
    tree = load(
        '<Sequence name="s"><Action ID="Go"/><Condition ID="Check" name="c"/>'
        '<Parallel name="p"><AlwaysSuccess/></Parallel></Sequence>'
    )
    go, check, parallel = tree.node(2), tree.node(3), tree.node(4)
    assert (go.type, go.name, go.path, go.kind) == ("Go", "Go", "Go::2", "action")
    assert (check.type, check.name, check.kind) == ("Check", "c", "condition")
    assert {k: p.value for k, p in parallel.ports.items()} == {
        "success_count": "-1",
        "failure_count": "1",
    }
    assert tree.node(5).path == "AlwaysSuccess::5"


@pytest.mark.parametrize(
    ("tree_file", "nodes", "first"),
    [
        (
            "tests/data/v3-delivery.xml",
            21,
            ["deliver a passenger", "collect passenger", "collect passenger"],
        ),
        (
            "tests/data/v3-gear-pair.xml",
            29,
            ["assemble a gear pair", "fetch gear", "fetch gear", "fetch gear", ""],
        ),
        (
            "paper/taxi-domain-tree.xml",
            21,
            ["go deliver passenger", "go pick up passenger", "go pick up passenger"],
        ),
        (
            "paper/kitting-tree.xml",
            79,
            ["build a gearbox kit", "go insert large gear", "go insert large gear"],
        ),
    ],
    indirect=["tree_file"],
)
def test_v3_trees_load(tree_file: Path, nodes: int, first: list[str]) -> None:
    """v3 trees (ours and the paper's) load: uids 1..N in DFS pre-order, SubTree names
    forced to their ID, the v3 spelling ``RetryUntilSuccesful`` accepted."""
    tree = load_tree(tree_file)
    assert tree.format == 3 and len(tree) == nodes
    assert [n.uid for n in tree] == list(range(1, nodes + 1))
    assert [n.name for n in tree][: len(first)] == first
    subtrees = [n for n in tree if n.type == "SubTree"]
    assert subtrees and all(n.name == n.attributes["subtree_id"] for n in subtrees)
    own = [n for n in subtrees if "shared_blackboard" not in n.attributes]
    assert all(n.children[0].scope == n.path for n in own)
    shared = [n for n in subtrees if "shared_blackboard" in n.attributes]
    assert all(n.children[0].scope == n.parent.scope for n in shared)


@pytest.mark.parametrize(
    ("tree_file", "retries", "first_leaf"),
    [
        ("tests/data/v3-gear-pair.xml", 3, "drive to the gear tray"),
        ("paper/kitting-tree.xml", 6, "move to see chuck"),
    ],
    indirect=["tree_file"],
)
def test_v3_retry_spelling(tree_file: Path, retries: int, first_leaf: str) -> None:
    """``RetryUntilSuccesful`` is loaded as RetryUntilSuccessful, with its port."""
    tree = load_tree(tree_file)
    found = [n for n in tree if n.type == "RetryUntilSuccessful"]
    assert len(found) == retries
    assert all(n.ports["num_attempts"].value in ("2", "3") for n in found)
    assert tree.node(5).kind == "decorator" and tree.node(5).children[0].name == first_leaf


def test_v3_gear_pair_runs_with_shared_blackboards() -> None:
    """Our v3 tree under the kitting domain: ``__shared_blackboard`` subtrees pass the gear's
    pose through the root blackboard, ``SubTreePlus`` remaps a literal and a ``{key}``."""
    tree = load_tree(ROOT / "tests" / "data" / "v3-gear-pair.xml")
    leaves = make_domain("kitting").leaf_factory(tree, Outcomes())
    executor = Executor(tree, leaf_factory=leaves)
    assert executor.run(max_ticks=5000) is SUCCESS
    boards = executor.blackboards()
    assert set(boards[""]) == {"gear pose", "grip pose", "mount pose"}
    assert boards[""]["mount pose"]["z"] == round(boards[""]["gear pose"]["z"] + 0.1, 4)
    [operator] = [scope for scope in boards if scope.startswith("tell operator")]
    assert boards[operator] == {"note": "gear pair assembled"}


# -- loader errors ---------------------------------------------------------------------------
def body(text: str, trees: str = "") -> str:
    """A document with the body on line 3 (and the trees after)."""
    return xml(text, trees)


@pytest.mark.parametrize(
    ("text", "line", "problem"),
    [
        (body('<Sequence name="s">\n<AlwaysSuccess/>\n</Sequenc>'), 5, "malformed XML"),
        (
            body('<Sequence name="s">\n<Frobnicate><AlwaysSuccess/></Frobnicate></Sequence>'),
            4,
            "unknown node type 'Frobnicate' with children",
        ),
        (
            body('<Inverter name="i">\n<AlwaysSuccess/><AlwaysSuccess/></Inverter>'),
            3,
            "Inverter must have 1 children, found 2",
        ),
        (body('<Sequence name="s"/>'), 3, "Sequence must have at least 1 children, found 0"),
        (
            body('<AlwaysSuccess name="a"><AlwaysSuccess/></AlwaysSuccess>'),
            3,
            "AlwaysSuccess must have 0 children",
        ),
        (
            body('<IfThenElse name="i"><AlwaysSuccess/></IfThenElse>'),
            3,
            "IfThenElse must have 2 to 3 children",
        ),
        (
            body('<Switch2 name="w" variable="1"><AlwaysSuccess/><AlwaysSuccess/></Switch2>'),
            3,
            "Switch2 must have 3 children, found 2",
        ),
        (
            body('<Sequence name="s">\n<SubTree ID="Nope"/></Sequence>'),
            4,
            "subtree 'Nope' is not defined",
        ),
        (
            body(
                '<SubTree ID="A"/>',
                '<BehaviorTree ID="A">\n<SubTree ID="B"/></BehaviorTree>\n'
                '<BehaviorTree ID="B"><SubTree ID="A"/></BehaviorTree>',
            ),
            7,
            "subtree cycle: A -> B -> A",
        ),
        (body('<SubTree ID="Main"/>'), 3, "subtree cycle: Main -> Main"),
        (
            '<root BTCPP_format="4" main_tree_to_execute="Nope">\n<BehaviorTree ID="Main">'
            "<AlwaysSuccess/></BehaviorTree></root>",
            1,
            "main tree 'Nope' is not defined",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="A"><AlwaysSuccess/></BehaviorTree>'
            '<BehaviorTree ID="B"><AlwaysSuccess/></BehaviorTree></root>',
            1,
            "2 trees and no main_tree_to_execute; the trees no other tree calls: 'A', 'B'",
        ),
        (
            body(
                '<Sequence name="s">\n<Repeat name="r" num_cycles="three"><AlwaysSuccess/></Repeat>'
                "</Sequence>"
            ),
            4,
            "bad value 'three' for port 'num_cycles'",
        ),
        (
            body(
                '<Sequence name="s">\n<Timeout name="t" msec="1.5"><AlwaysSuccess/></Timeout>'
                "</Sequence>"
            ),
            4,
            "bad value '1.5' for port 'msec'",
        ),
        (
            body(
                '<Sequence name="s">\n<Precondition name="p" if="true" else="MAYBE">'
                "<AlwaysSuccess/></Precondition></Sequence>"
            ),
            4,
            "bad value 'MAYBE' for port 'else'",
        ),
        (
            body(
                '<Sequence name="s">\n<Sequence name="i" foo="1"><AlwaysSuccess/></Sequence>'
                "</Sequence>"
            ),
            4,
            "Sequence has no port 'foo'",
        ),
        (
            body('<Sequence name="s">\n<AlwaysSuccess name="a" bar="1"/></Sequence>'),
            4,
            "AlwaysSuccess has no port 'bar'",
        ),
        (
            body('<Sequence name="s">\n<AlwaysSuccess name="a" _skipIf="x =="/></Sequence>'),
            4,
            "_skipIf:",
        ),
        (
            body('<Sequence name="s">\n<AlwaysSuccess ID="x"/></Sequence>'),
            4,
            "must not have an ID attribute",
        ),
        (body('<Sequence name="s">\n<Action name="x"/></Sequence>'), 4, "<Action> needs an ID"),
        (
            '<root BTCPP_format="4"><BehaviorTree ID="Main"><AlwaysSuccess/><AlwaysSuccess/>'
            "</BehaviorTree></root>",
            1,
            "must have exactly one child, found 2",
        ),
        (
            '<tree><BehaviorTree ID="Main"><AlwaysSuccess/></BehaviorTree></tree>',
            1,
            "the top element must be <root>",
        ),
    ],
)
def test_loader_errors_name_file_and_line(text: str, line: int, problem: str) -> None:
    """Every load error is a TreeError whose message starts with ``file:line:``."""
    error = error_of(text)
    assert (error.file, error.line) == ("tree.xml", line)
    assert str(error).startswith(f"tree.xml:{line}: ")
    assert problem in str(error)


def test_doctype_and_entities_are_refused() -> None:
    """A DOCTYPE (here declaring an entity) is refused, even when nothing references it."""
    error = error_of(
        '<?xml version="1.0"?>\n<!DOCTYPE root [<!ENTITY a "aaaa">]>\n'
        '<root BTCPP_format="4"><BehaviorTree ID="Main"><AlwaysSuccess/>'
        "</BehaviorTree></root>"
    )
    assert "DOCTYPE" in str(error)


def test_external_entity_is_refused() -> None:
    """An external entity is never read."""
    error = error_of(
        '<?xml version="1.0"?>\n<!DOCTYPE root [<!ENTITY x SYSTEM '
        '"file:///etc/passwd">]>\n<root BTCPP_format="4"><BehaviorTree ID="Main">'
        '<AlwaysSuccess name="&x;"/></BehaviorTree></root>'
    )
    assert error.file == "tree.xml" and "root:" not in str(error)


@pytest.mark.parametrize("where", ["attribute", "text"])
def test_xml_bomb_is_refused_before_expansion(where: str) -> None:
    """A billion-laughs document is refused by the parser's entity limit, without expanding it
    (the expansion would be 3 GB): the error is a one-line "malformed XML" naming entities."""
    entities = ['<!ENTITY lol0 "lollollollollollollollollollol">'] + [
        f'<!ENTITY lol{i} "{f"&lol{i - 1};" * 10}">' for i in range(1, 10)
    ]
    use = (
        '<AlwaysSuccess name="&lol9;"/>'
        if where == "attribute"
        else '<AlwaysSuccess name="a"/><!-- -->&lol9;'
    )
    text = (
        '<?xml version="1.0"?>\n<!DOCTYPE root [\n' + "\n".join(entities) + "\n]>\n"
        f'<root BTCPP_format="4"><BehaviorTree ID="Main"><Sequence name="s">{use}'
        "</Sequence></BehaviorTree></root>"
    )
    error = error_of(text)
    assert error.file == "tree.xml"
    message = str(error)
    assert "malformed XML" in message and "entity" in message
    assert "lollol" not in message and "\n" not in message

"""SubTree: remapping, autoremap, root-blackboard keys, v3 subtrees and shared
blackboards.

The trees, the scripted leaves and the oracle cross-check are described in
``tests/nodes_support.py``.
"""

from __future__ import annotations

import pytest

from tests.nodes_support import (
    act,
    cond,
    fail,
    load,
    ok,
    run,
    script,
)


def test_subtree_remapping_literals_and_outputs() -> None:
    """``x="{v}"`` maps the inner x to the outer v, ``lit="7"`` is a literal in the subtree's own
    blackboard, ``y="{out}"`` writes back. The SubTree node stays SUCCESS until its parent
    resets it."""
    r = run(
        f'<Sequence name="top">{script("s", "v:=42")}'
        '<SubTree ID="Sub" name="st" x="{v}" lit="7" y="{out}"/>'
        '<ScriptCondition name="post" code="out == 43"/></Sequence>',
        {"ia": [ok(1)]},
        trees='<BehaviorTree ID="Sub"><Sequence name="inner">'
        '<ScriptCondition name="chk" code="x == 42 &amp;&amp; lit == 7"/>'
        f"{script('w', 'y := x + 1')}{act('ia')}</Sequence></BehaviorTree>",
    )
    assert r.roots == ["RUNNING", "SUCCESS"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("st", "IDLE", "RUNNING"),
            ("inner", "IDLE", "RUNNING"),
            ("chk", "IDLE", "SUCCESS"),
            ("w", "IDLE", "SUCCESS"),
            ("ia", "IDLE", "RUNNING"),
        ],
        2: [
            ("ia", "RUNNING", "SUCCESS"),
            ("chk", "SUCCESS", "IDLE"),
            ("w", "SUCCESS", "IDLE"),
            ("ia", "SUCCESS", "IDLE"),
            ("inner", "RUNNING", "SUCCESS"),
            ("inner", "SUCCESS", "IDLE"),
            ("st", "RUNNING", "SUCCESS"),
            ("post", "IDLE", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("st", "SUCCESS", "IDLE"),
            ("post", "SUCCESS", "IDLE"),
            ("top", "RUNNING", "SUCCESS"),
            ("top", "SUCCESS", "IDLE"),
        ],
    }
    assert r.board == {"v": 42, "out": 43}


def test_subtree_autoremap() -> None:
    """``_autoremap="true"``: keys missing in the subtree resolve in the parent (the SubTree's
    name defaults to its ID)."""
    r = run(
        f'<Sequence name="top">{script("s", "x:=42; lit:=7")}'
        '<SubTree ID="Sub" _autoremap="true"/>'
        '<ScriptCondition name="post" code="y == 43"/></Sequence>',
        trees='<BehaviorTree ID="Sub"><Sequence name="inner">'
        '<ScriptCondition name="chk" code="x == 42 &amp;&amp; lit == 7"/>'
        f"{script('w', 'y := x + 1')}</Sequence></BehaviorTree>",
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("Sub", "IDLE", "RUNNING"),
            ("inner", "IDLE", "RUNNING"),
            ("chk", "IDLE", "SUCCESS"),
            ("w", "IDLE", "SUCCESS"),
            ("chk", "SUCCESS", "IDLE"),
            ("w", "SUCCESS", "IDLE"),
            ("inner", "RUNNING", "SUCCESS"),
            ("inner", "SUCCESS", "IDLE"),
            ("Sub", "RUNNING", "SUCCESS"),
            ("post", "IDLE", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("Sub", "SUCCESS", "IDLE"),
            ("post", "SUCCESS", "IDLE"),
            ("top", "RUNNING", "SUCCESS"),
            ("top", "SUCCESS", "IDLE"),
        ],
    }


def test_subtree_root_blackboard_keys() -> None:
    """``@key`` reads and writes the root blackboard from inside an isolated subtree."""
    r = run(
        f'<Sequence name="top">{script("s", "g:=1")}<SubTree ID="Sub" name="st"/>'
        '<ScriptCondition name="post" code="g == 2 &amp;&amp; h == 3"/></Sequence>',
        trees=f'<BehaviorTree ID="Sub">{script("w", "@g := @g + 1; @h := 3")}</BehaviorTree>',
    )
    assert r.roots == ["SUCCESS"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("s", "IDLE", "SUCCESS"),
            ("st", "IDLE", "RUNNING"),
            ("w", "IDLE", "SUCCESS"),
            ("w", "SUCCESS", "IDLE"),
            ("st", "RUNNING", "SUCCESS"),
            ("post", "IDLE", "SUCCESS"),
            ("s", "SUCCESS", "IDLE"),
            ("st", "SUCCESS", "IDLE"),
            ("post", "SUCCESS", "IDLE"),
            ("top", "RUNNING", "SUCCESS"),
            ("top", "SUCCESS", "IDLE"),
        ],
    }
    assert r.board == {"g": 2, "h": 3}


def test_subtree_failure_and_halt() -> None:
    """A ReactiveSequence halts the running SubTree: the halt goes down to the inner leaf first."""
    r = run(
        f'<ReactiveSequence name="top">{cond("c")}<SubTree ID="Sub" name="st"/></ReactiveSequence>',
        {"c": [ok(), fail()], "ia": [ok(3)]},
        trees=f'<BehaviorTree ID="Sub"><Sequence name="inner">{act("ia")}</Sequence>'
        "</BehaviorTree>",
    )
    assert r.roots == ["RUNNING", "FAILURE"]
    assert r.ticks == {
        1: [
            ("top", "IDLE", "RUNNING"),
            ("c", "IDLE", "SUCCESS"),
            ("st", "IDLE", "RUNNING"),
            ("inner", "IDLE", "RUNNING"),
            ("ia", "IDLE", "RUNNING"),
            ("c", "SUCCESS", "IDLE"),
        ],
        2: [
            ("c", "IDLE", "FAILURE"),
            ("c", "FAILURE", "IDLE"),
            ("ia", "RUNNING", "IDLE"),
            ("inner", "RUNNING", "IDLE"),
            ("st", "RUNNING", "IDLE"),
            ("top", "RUNNING", "FAILURE"),
            ("top", "FAILURE", "IDLE"),
        ],
    }


# -- v3 subtrees (btlog only: behaviortreepy is BT.CPP v4) ------------------------------------
def test_v3_subtree_remaps_raw_keys_and_is_named_by_its_id() -> None:
    """v3 (no BTCPP_format): ``inner="outer"`` names the parent key directly, the instance
    name is forced to the ID, and the subtree's own entries stay in its scope."""
    r = run(
        f'<Sequence name="top">{script("s", "outer:=5")}<SubTree ID="Sub" name="ignored" '
        'inner="outer"/></Sequence>',
        fmt=None,
        oracle=False,
        trees=f'<BehaviorTree ID="Sub">{script("w", "inner := inner + 1; mine := 1")}'
        "</BehaviorTree>",
    )
    assert r.roots == ["SUCCESS"]
    assert r.executor.blackboards() == {"": {"outer": 6}, "Sub": {"mine": 1}}
    assert [(n.uid, n.name, n.path) for n in r.tree] == [
        (1, "top", "top"),
        (2, "s", "s"),
        (3, "Sub", "Sub"),
        (4, "w", "Sub/w"),
    ]


def test_v3_shared_blackboard_and_subtree_plus() -> None:
    """v3 ``__shared_blackboard="true"`` shares the parent's entries; ``<SubTreePlus>`` takes
    ``{key}`` remappings, literals and ``__autoremap``."""
    sub = f'<BehaviorTree ID="Sub">{script("w", "outer := outer + 1; mine := 1")}</BehaviorTree>'
    shared = run(
        f'<Sequence name="top">{script("s", "outer:=5")}'
        '<SubTree ID="Sub" __shared_blackboard="true"/></Sequence>',
        trees=sub,
        fmt=None,
        oracle=False,
    )
    assert shared.executor.blackboards() == {"": {"outer": 6, "mine": 1}}
    plus = run(
        f'<Sequence name="top">{script("s", "outer:=5; other:=1")}'
        '<SubTreePlus ID="Plus" inner="{outer}" lit="3" __autoremap="true"/></Sequence>',
        trees='<BehaviorTree ID="Plus">'
        f"{script('w', 'inner := inner + lit + other')}</BehaviorTree>",
        fmt=None,
        oracle=False,
    )
    assert plus.roots == ["SUCCESS"]
    assert plus.board == {"outer": 9, "other": 1}


def test_subtree_same_key_remapping_and_literal_types() -> None:
    """``x="{=}"`` maps x to the parent's x; literals are stored as int, float or string
    (BT.CPP HEAD) and reported as the first blackboard writes of the run."""
    r = run(
        f'<Sequence name="top">{script("s", "x:=1")}'
        '<SubTree ID="Sub" name="st" x="{=}" i="4" f="2.5" t="hello"/></Sequence>',
        trees=f'<BehaviorTree ID="Sub">{script("w", "x := x + i + f; u := t .. &apos;!&apos;")}'
        "</BehaviorTree>",
        oracle=False,
    )
    assert r.board == {"x": 7.5}
    assert r.executor.blackboards()["st"] == {"i": 4, "f": 2.5, "t": "hello", "u": "hello!"}
    assert r.writes()[:3] == [("st", "i", 4), ("st", "f", 2.5), ("st", "t", "hello")]


@pytest.mark.xfail(
    strict=True,
    reason='loader: a v4 SubTree with name="" gets the inner '
    "prefix 'Sub::2/'; BT.CPP uses the empty name, giving the prefix '/'",
)
def test_subtree_with_empty_name_has_an_empty_path_segment() -> None:
    """BT.CPP ``recursivelyCreateSubtree``: ``if(auto name = element->Attribute("name"))
    subtree_path += name`` (an empty attribute counts). Verified with BT.CPP 4.8.2: the inner
    leaf's ``full_path()`` is ``/in``."""
    tree = load(
        '<Sequence name="top"><SubTree ID="Sub" name=""/></Sequence>',
        '<BehaviorTree ID="Sub"><Leaf name="in"/></BehaviorTree>',
    )
    assert (tree.node(2).path, tree.node(3).path) == ("", "/in")

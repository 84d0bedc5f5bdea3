"""Each of py_trees' own demo trees (``py_trees.demos``, the ones that need no ROS)
recorded and explained: after every tick the state btlog replays is the live tree's, and
every question answered live is answered the same post hoc; ``btlog record-py`` records
a demo from the command line, with live questions answered as ``btlog ask`` answers them."""

from __future__ import annotations

import importlib
from pathlib import Path

import py_trees
import pytest

from btlog.sources.py_trees import record
from tests.cli_support import assert_bad_input, btlog
from tests.py_trees_support import Seen, assert_replay_equals_live, questions_about, tick_and_watch

#: (module of py_trees.demos, factory, its arguments)
DEMOS = [
    ("selector", "create_root", ()),
    ("sequence", "create_root", ()),
    ("blackboard", "create_root", ()),
    ("context_switching", "create_root", ()),
    ("dot_graphs", "create_tree", ("all",)),
    ("either_or", "create_root", ()),
    ("eternal_guard", "create_root", ()),
    ("logging", "create_tree", ()),
    ("pick_up_where_you_left_off", "create_root", ()),
    ("stewardship", "create_tree", ()),
    ("display_modes", "create_root", ()),
]


def seed_blackboard() -> None:
    """What the blackboard demo's ``main`` writes before building its tree."""
    client = py_trees.blackboard.Client(name="Configuration")
    client.register_key(key="dude", access=py_trees.common.Access.WRITE)
    client.register_key(
        key="/parameters/default_speed", access=py_trees.common.Access.EXCLUSIVE_WRITE
    )
    client.dude = "Bob"
    client.parameters.default_speed = 30.0


@pytest.mark.parametrize(("module", "factory", "args"), DEMOS, ids=[d[0] for d in DEMOS])
def test_demo_recorded_and_explained(tmp_path: Path, module: str, factory: str, args) -> None:
    py_trees.blackboard.Blackboard.clear()
    if module == "blackboard":
        seed_blackboard()
    demo = importlib.import_module(f"py_trees.demos.{module}")
    tree = py_trees.trees.BehaviourTree(getattr(demo, factory)(*args))
    tree.setup(timeout=15)
    about = [b.name for b in tree.root.iterate()][:2]
    asked = questions_about(about)
    seen = Seen()
    path = tmp_path / f"{module}.mcap"
    with record(tree, path) as recorder:
        tick_and_watch(tree, recorder, 12, asked, seen)
    assert recorder.result is not None
    assert recorder.result.ticks == 12
    assert recorder.result.transitions > 0
    assert_replay_equals_live(path, seen, asked)
    explained = btlog("explain", path)
    assert explained.returncode == 0, explained.stderr
    assert "Goal:" in explained.stdout


def test_record_py_answers_live_as_ask_does(tmp_path: Path) -> None:
    out = tmp_path / "either.mcap"
    result = btlog(
        "record-py",
        "py_trees.demos.either_or:create_root",
        "-o",
        out,
        "--ticks",
        "15",
        "--ask",
        "tick:6=What are you doing?",
        "--ask",
        "end=What went wrong?",
        "--ask",
        "tick:99=What are you doing?",
    )
    assert result.returncode == 0, result.stderr
    assert "15 ticks" in result.stdout
    assert "tick:99" in result.stderr and "after the end of the run" in result.stderr
    lines = result.stdout.splitlines()
    live_doing = lines[lines.index("[tick:6] What are you doing?") + 1].strip()
    live_wrong = lines[lines.index("[end] What went wrong?") + 1].strip()
    post_doing = btlog("ask", out, "What are you doing?", "--at", "tick:6")
    post_wrong = btlog("ask", out, "What went wrong?", "--at", "end")
    assert post_doing.stdout.strip() == live_doing
    assert post_wrong.stdout.strip() == live_wrong


def test_record_py_from_a_file_with_a_root_behaviour(tmp_path: Path) -> None:
    script = tmp_path / "mytree.py"
    script.write_text(
        "import py_trees\n"
        "def root():\n"
        "    return py_trees.composites.Sequence('patrol', memory=True, children=[\n"
        "        py_trees.behaviours.Success('go to door'),\n"
        "        py_trees.behaviours.Failure('open door')])\n"
    )
    out = tmp_path / "run.mcap"
    result = btlog("record-py", f"{script}:root", "-o", out, "--until-done")
    assert result.returncode == 0, result.stderr
    assert "1 ticks" in result.stdout and "FAILURE" in result.stdout
    wrong = btlog("ask", out, "What went wrong?", "--at", "end")
    assert "open door" in wrong.stdout


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ("nocolon", ["MODULE:FACTORY"]),
        ("no_such_module_xyz:root", ["cannot import", "no_such_module_xyz"]),
        ("py_trees.demos.selector:nothing", ["has no function nothing"]),
        ("py_trees.demos.selector:description", ["returned a str"]),
    ],
)
def test_record_py_bad_factory_is_one_line(tmp_path: Path, spec: str, words) -> None:
    result = btlog("record-py", spec, "-o", tmp_path / "x.mcap")
    assert_bad_input(result, *words)

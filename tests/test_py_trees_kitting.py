"""The paper's kitting task as a py_trees tree (``trees/py_trees/kitting_py_trees.py``):
recorded with ``btlog record-py``, its answers are those of its expectations file
(``btlog check --expect``), and recorded in-process, every question asked live after
every tick is answered the same post hoc."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import py_trees

from btlog.sources.py_trees import record
from tests.cli_support import ROOT, btlog
from tests.py_trees_support import Seen, assert_replay_equals_live, questions_about, tick_and_watch

TREE = ROOT / "trees" / "py_trees" / "kitting_py_trees.py"
EXPECT = ROOT / "trees" / "py_trees" / "kitting_py_trees.expect.yaml"


def test_kitting_answers_match_expectations(tmp_path: Path) -> None:
    run = tmp_path / "kitting.mcap"
    recorded = btlog(
        "record-py",
        f"{TREE}:look_at_chuck_fails",
        "-o",
        run,
        "--until-done",
        "--ticks",
        "500",
        "--ask",
        "0.85s=What went wrong?",
    )
    assert recorded.returncode == 0, recorded.stderr
    assert "I could not insert large gear because look at chuck failed." in recorded.stdout
    checked = btlog("check", run, "--expect", EXPECT)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "0 failed" in checked.stdout


def test_kitting_live_equals_post_hoc(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location("kitting_py_trees", TREE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    py_trees.blackboard.Blackboard.clear()
    tree = py_trees.trees.BehaviourTree(module.create_root({"check if grasped": 1}))
    asked = [
        *questions_about(["look at chuck", "grasp screw"]),
        "Can you insert large gear?",
    ]
    seen = Seen()
    path = tmp_path / "run.mcap"
    with record(tree, path, clock=lambda: tree.count * 0.1) as recorder:
        tick_and_watch(tree, recorder, 45, asked, seen)
    assert any("check if grasped failed" in " ".join(a) for a in seen.answers)
    assert_replay_equals_live(path, seen, asked)

"""Choosing trees as BT.CPP programs do: files registered one by one (``--trees``), then
``createTree(ID)`` (``--main-tree``), else main_tree_to_execute, else the only tree, else
the one tree no other tree calls; on every command that loads trees."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from btlog.tree.loader import TreeError, load_tree, load_tree_text
from tests.cli_support import assert_bad_input, btlog

DATA = Path(__file__).resolve().parent / "data" / "trees"
OBJECTIVES = DATA / "objectives"


def test_the_tree_no_other_tree_calls_is_the_main_tree() -> None:
    tree = load_tree(DATA / "several_trees.xml")
    assert (tree.name, tree.main_choice) == ("MainTree", "uncalled")
    assert tree.root.name == "go through the door"


def test_several_candidates_are_named_with_the_flag() -> None:
    with pytest.raises(TreeError) as caught:
        load_tree(DATA / "two_roots.xml")
    message = str(caught.value)
    assert "two_roots.xml:4:" in message
    assert "'Patrol', 'Dock'" in message and "--main-tree ID" in message
    assert load_tree(DATA / "two_roots.xml", main_tree="Dock").root.children[0].name == (
        "go to dock"
    )


def test_main_tree_flag_overrides_main_tree_to_execute_and_must_exist() -> None:
    text = (
        '<root BTCPP_format="4" main_tree_to_execute="A"><BehaviorTree ID="A"><AlwaysSuccess/>'
        '</BehaviorTree><BehaviorTree ID="B"><AlwaysFailure/></BehaviorTree></root>'
    )
    assert load_tree_text(text).name == "A"
    assert load_tree_text(text, main_tree="B").main_choice == "--main-tree"
    with pytest.raises(TreeError, match=r"main tree 'C' is not defined \(trees: 'A', 'B'\)"):
        load_tree_text(text, main_tree="C")


def test_when_every_tree_is_called_the_error_lists_them_all() -> None:
    text = (
        '<root BTCPP_format="4"><BehaviorTree ID="A"><SubTree ID="B"/></BehaviorTree>'
        '<BehaviorTree ID="B"><SubTree ID="A"/></BehaviorTree></root>'
    )
    with pytest.raises(TreeError, match=r"each is called by another.*'A', 'B'"):
        load_tree_text(text)


def test_a_folder_of_objectives_is_registered_like_registerBehaviorTreeFromFile() -> None:
    """Subtrees of other files of the folder, without <include>; the folder's files that
    are not trees are skipped; only the files the tree uses are the tree's files."""
    with pytest.raises(TreeError, match="subtree 'Open Gripper' is not defined"):
        load_tree(OBJECTIVES / "pick_object.xml")
    tree = load_tree(OBJECTIVES / "pick_object.xml", trees=[OBJECTIVES])
    assert tree.name == "Pick Object"
    assert [n.name for n in tree if n.kind == "subtree"] == ["Open Gripper", "Grasp"]
    assert sorted(Path(f).name for f in tree.files) == [
        "grasp.xml",
        "open_gripper.xml",
        "pick_object.xml",
    ]
    assert load_tree(OBJECTIVES / "grasp.xml", trees=[OBJECTIVES]).name == "Grasp"


def test_bad_trees_entries(tmp_path: Path) -> None:
    with pytest.raises(TreeError, match="--trees: no such file or folder"):
        load_tree(OBJECTIVES / "pick_object.xml", trees=[tmp_path / "nowhere"])
    with pytest.raises(TreeError, match=r"launch_settings\.xml:3: the top element must be <root>"):
        load_tree(OBJECTIVES / "pick_object.xml", trees=[OBJECTIVES / "launch_settings.xml"])
    twice = tmp_path / "twice.xml"
    twice.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="Grasp"><AlwaysSuccess/></BehaviorTree></root>'
    )
    with pytest.raises(TreeError, match=r"twice\.xml:1: tree 'Grasp' is defined twice"):
        load_tree(OBJECTIVES / "pick_object.xml", trees=[OBJECTIVES, twice])


def test_other_elements_under_root_are_ignored_as_btcpp_ignores_them() -> None:
    tree = load_tree_text(
        '<root BTCPP_format="4"><Groot version="1"/><BehaviorTree ID="A"><AlwaysSuccess/>'
        "</BehaviorTree></root>",
        file="t.xml",
    )
    assert tree.warnings == [
        "t.xml:1: <Groot> under <root> is ignored (BT.CPP reads only <BehaviorTree>, "
        "<include> and <TreeNodesModel>)"
    ]


def test_commands_that_load_trees_take_the_flags(tmp_path: Path) -> None:
    """validate, run, check --rerun (recorded), diff."""
    objectives = tmp_path / "objectives"
    shutil.copytree(OBJECTIVES, objectives)
    main = objectives / "pick_object.xml"
    result = btlog("validate", main, "--trees", objectives, "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert (report["main_tree"], report["main_tree_choice"]) == ("Pick Object", "main_tree")
    shown = btlog("validate", DATA / "several_trees.xml")
    assert "main tree: MainTree (the only tree no other tree calls" in shown.stdout
    assert_bad_input(btlog("validate", DATA / "two_roots.xml"), "--main-tree ID", "'Patrol'")
    assert btlog("validate", DATA / "two_roots.xml", "--main-tree", "Patrol").returncode == 0

    recording = tmp_path / "pick.mcap"
    result = btlog("run", main, "--trees", objectives, "-o", recording)
    assert result.returncode == 0, result.stderr
    assert "final status: SUCCESS" in result.stdout
    rerun = btlog("check", recording, "--rerun")
    assert rerun.returncode == 0, rerun.stdout + rerun.stderr

    other = tmp_path / "dock.mcap"
    result = btlog("run", DATA / "two_roots.xml", "--main-tree", "Dock", "-o", other)
    assert result.returncode == 0, result.stderr
    same = btlog("diff", other, DATA / "two_roots.xml", "--main-tree", "Dock")
    assert same.returncode == 0, same.stdout + same.stderr
    differs = btlog("diff", other, DATA / "two_roots.xml", "--main-tree", "Patrol")
    assert differs.returncode == 1


def test_import_chooses_the_tree_of_its_tree_file_too(tmp_path: Path) -> None:
    """``import --tree F`` takes ``--main-tree`` and ``--trees``; the chosen tree must be
    the log's."""
    recording = tmp_path / "dock.mcap"
    result = btlog("run", DATA / "two_roots.xml", "--main-tree", "Dock", "-o", recording)
    assert result.returncode == 0, result.stderr
    log = tmp_path / "dock.btlog"
    assert btlog("export", recording, "--to", "btlog", log).returncode == 0
    assert_bad_input(
        btlog("import", log, "--tree", DATA / "two_roots.xml", "-o", tmp_path / "a.mcap"),
        "--main-tree ID",
    )
    chosen = btlog(
        "import",
        log,
        "--tree",
        DATA / "two_roots.xml",
        "--main-tree",
        "Dock",
        "-o",
        tmp_path / "b.mcap",
    )
    assert chosen.returncode == 0, chosen.stderr
    wrong = btlog(
        "import",
        log,
        "--tree",
        DATA / "two_roots.xml",
        "--main-tree",
        "Patrol",
        "-o",
        tmp_path / "c.mcap",
    )
    assert_bad_input(wrong, "not the tree of this log")
    assert_bad_input(btlog("import", log, "--main-tree", "Dock"), "give it")

"""Divergence between behaviours (the paper's section 7.2.1), on the Taxi worked example.

The optimal Taxi policy detours around the toll; the human-expectation policy drives
through it. By hand, subgoal by subgoal:

    go pick up passenger   optimal: R R R U U L pick      human: R R U U pick
                           LCS = R R U U pick (5); edit distance 7 + 5 - 2*5 = 2;
                           divergent: one "move right" and the "move left", both in
                           "navigate to passenger"
    go drop off passenger  optimal: R D D L L L drop      human: D D L L drop
                           LCS = D D L L drop (5); edit distance 2;
                           divergent: the "move right" and one "move left", both in
                           "navigate to destination"
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest

from btlog.algorithms.sequence_diff import compare
from btlog.checks.behaviours import diff_paths, executed_actions, nominal_actions
from btlog.explain import divergence
from btlog.explain.divergence import (
    ExecutedAction,
    actions_from_events,
    compare_subgoal,
    diverge,
    iter_json,
    to_json,
)
from btlog.record.reader import open_recording, stream_events
from btlog.render.divergence import render
from btlog.runner import RunConfig, execute

ROOT = Path(__file__).resolve().parents[1]
TREES = ROOT / "trees"
PICK, DROP = "go pick up passenger", "go drop off passenger"


@pytest.fixture(scope="module")
def taxi_runs(tmp_path_factory) -> dict[str, Path]:
    """The optimal tree and the human-expectation tree, each recorded in the Taxi domain."""
    folder = tmp_path_factory.mktemp("taxi")
    runs = {}
    for label, tree in (("optimal", "taxi.xml"), ("human", "taxi-human.xml")):
        result = execute(RunConfig(tree=str(TREES / tree), domain="taxi"), folder / f"{label}.mcap")
        assert result.final_status.name == "SUCCESS"
        runs[label] = result.path
    return runs


def _descriptions(actions) -> list[str]:
    return [action.description for action in actions]


def _check_taxi_divergence(divergence) -> None:
    assert [s.subgoal for s in divergence.subgoals] == [PICK, DROP]
    pick, drop = divergence.subgoal(PICK), divergence.subgoal(DROP)
    assert (pick.edit_distance, len(pick.lcs)) == (2, 5)
    assert (drop.edit_distance, len(drop.lcs)) == (2, 5)
    assert list(pick.lcs) == ["move right", "move right", "move up", "move up", "pick up passenger"]
    assert list(drop.lcs) == [
        "move down",
        "move down",
        "move left",
        "move left",
        "drop off passenger",
    ]
    assert sorted(_descriptions(pick.only_a)) == ["move left", "move right"]
    assert sorted(_descriptions(drop.only_a)) == ["move left", "move right"]
    assert pick.only_b == [] and drop.only_b == []
    assert {a.parent for a in pick.only_a} == {"navigate to passenger"}
    assert {a.parent for a in drop.only_a} == {"navigate to destination"}
    assert divergence.edit_distance == 4 and not divergence.identical


def test_executed_actions_of_the_optimal_taxi_run(taxi_runs):
    actions = executed_actions(open_recording(taxi_runs["optimal"]))
    assert _descriptions(actions) == [
        "move right",
        "move right",
        "move right",
        "move up",
        "move up",
        "move left",
        "pick up passenger",
        "move right",
        "move down",
        "move down",
        "move left",
        "move left",
        "move left",
        "drop off passenger",
    ]
    assert [a.subgoal for a in actions] == [PICK] * 7 + [DROP] * 7
    assert actions[0].parent == "navigate to passenger"
    assert actions[6].parent == PICK and actions[6].type == "pick up"
    assert all(a.result == "SUCCESS" for a in actions)
    assert [a.seq for a in actions] == sorted(a.seq for a in actions)


def test_nominal_sequence_of_a_tree_equals_its_recorded_run(taxi_runs):
    nominal = nominal_actions(TREES / "taxi.xml")
    recorded = executed_actions(taxi_runs["optimal"])
    assert _descriptions(nominal) == _descriptions(recorded)
    assert diverge(recorded, nominal).identical


def test_taxi_optimal_run_against_the_human_expectation_tree(taxi_runs):
    divergence = diverge(
        executed_actions(taxi_runs["optimal"]), nominal_actions(TREES / "taxi-human.xml")
    )
    _check_taxi_divergence(divergence)


def test_taxi_optimal_run_against_a_recorded_human_run(taxi_runs):
    divergence = diff_paths(taxi_runs["optimal"], taxi_runs["human"])
    _check_taxi_divergence(divergence)


def test_render_is_side_by_side_with_marked_rows_and_parents(taxi_runs):
    text = render(diff_paths(taxi_runs["optimal"], TREES / "taxi-human.xml"))
    lines = text.splitlines()
    assert f'subgoal "{PICK}": edit distance 2, LCS length 5 (7 vs 5 actions)' in lines
    marked = [line for line in lines if line.startswith("  !")]
    assert len(marked) == 4
    assert sum("(in navigate to passenger)" in line for line in marked) == 2
    assert sum("(in navigate to destination)" in line for line in marked) == 2
    both = [line for line in lines if line.strip().startswith("move up")]
    assert all(line.split().count("move") == 2 for line in both)  # A and B columns
    assert lines[-1] == "total edit distance 4: 2 of 2 subgoals diverge"


def test_json_lists_divergent_actions_with_parents(taxi_runs):
    data = to_json(diff_paths(taxi_runs["optimal"], TREES / "taxi-human.xml"))
    json.dumps(data)
    pick = data["subgoals"][0]
    assert (pick["subgoal"], pick["edit_distance"], pick["lcs_length"]) == (PICK, 2, 5)
    assert {(d["side"], d["action"], d["parent"]) for d in pick["divergent"]} == {
        ("a", "move right", "navigate to passenger"),
        ("a", "move left", "navigate to passenger"),
    }
    assert [row["op"] for row in pick["rows"]].count("equal") == 5


def _action(description: str, seq: int, subgoal: str = "s") -> ExecutedAction:
    return ExecutedAction(seq, seq + 1, description, description, "action", "step", 0, subgoal)


def test_swapped_actions_are_reported_as_a_move():
    a = [_action(x, i) for i, x in enumerate(["p", "q", "r", "s"])]
    b = [_action(x, i) for i, x in enumerate(["p", "r", "q", "s"])]
    found = diverge(a, b).subgoal("s")
    assert found.edit_distance == 2
    assert len(found.moves) == 1
    move = found.moves[0]
    assert {move.action, *move.past} == {"q", "r"}


def test_subgoals_in_order_of_first_appearance_and_missing_on_one_side():
    a = [_action("x", 0, "one"), _action("y", 1, "two")]
    b = [_action("y", 0, "two"), _action("z", 1, "three")]
    divergence = diverge(a, b)
    assert [s.subgoal for s in divergence.subgoals] == ["one", "two", "three"]
    assert [s.edit_distance for s in divergence.subgoals] == [1, 0, 1]


def test_names_from_trees_are_printed_safely():
    evil = "look\x1b[31m at\nme"
    text = render(diverge([_action(evil, 0)], []))
    assert "\x1b" not in text and "\\x1b" in text
    assert all(line.strip() != "me" for line in text.splitlines())


def test_inserted_nodes_are_known_to_executed_actions(tmp_path):
    """A live "Can you …?" inserts nodes; their activations appear with their subgoal."""
    result = execute(
        RunConfig(
            tree=str(TREES / "kitting.xml"),
            domain="kitting",
            seed=1,
            questions=["tick:100=Can you detect chuck?"],
        ),
        tmp_path / "asked.mcap",
    )
    recording = open_recording(result.path)
    actions = executed_actions(recording)
    inserted = [a for a in actions if a.uid not in recording.tree.nodes]
    assert _descriptions(inserted) == ["lift torso", "look at chuck roughly", "detect chuck"]
    assert {a.parent for a in inserted} == {"detect chuck"}


def test_diff_command_plain_and_json(taxi_runs):
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]),
    }
    base = [
        sys.executable,
        "-m",
        "btlog.cli.main",
        "diff",
        str(taxi_runs["optimal"]),
        str(TREES / "taxi-human.xml"),
    ]
    plain = subprocess.run([*base, "--plain"], capture_output=True, text=True, env=env, timeout=60)
    assert plain.returncode == 1, plain.stderr  # they diverge, as diff(1) says
    assert f'subgoal "{DROP}": edit distance 2, LCS length 5' in plain.stdout
    assert "\x1b" not in plain.stdout
    as_json = subprocess.run([*base, "--json"], capture_output=True, text=True, env=env, timeout=60)
    assert as_json.returncode == 1, as_json.stderr
    data = json.loads(as_json.stdout)
    assert [s["edit_distance"] for s in data["subgoals"]] == [2, 2]
    missing = subprocess.run(
        [*base[:-2], "nope.mcap", str(TREES / "taxi.xml")],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert missing.returncode == 2
    assert len(missing.stderr.strip().splitlines()) == 1 and "nope.mcap" in missing.stderr


def test_a_recording_is_streamed_into_the_same_actions_as_read_whole(taxi_runs):
    """``executed_actions`` of a path folds the file front to back into compact arrays;
    every action (seq, node, parent, subgoal, result) is what the whole read gives."""
    for path in taxi_runs.values():
        assert stream_events(path) is not None  # a tidy file: read front to back
        recording = open_recording(path)
        whole = actions_from_events(recording.tree, list(recording.events))
        streamed = executed_actions(path)
        assert len(streamed) == len(whole) >= 10
        assert list(streamed) == list(whole)
        assert {a.result for a in streamed} == {"SUCCESS"}


def test_the_common_prefix_walked_first_gives_the_alignment_of_the_whole():
    """Walking the shared first actions before the O(NP) search changes no row: the same
    alignment as comparing the whole sequences, on many random pairs."""
    generator = random.Random(7)
    for _ in range(2000):
        a = [_action(generator.choice("xyz"), i) for i in range(generator.randint(0, 9))]
        b = [_action(generator.choice("xyz"), i) for i in range(generator.randint(0, 9))]
        found = compare_subgoal("s", a, b)
        whole = compare([x.description for x in a], [x.description for x in b])
        rows = [(r.op, r.a_index, r.b_index) for r in found.rows]
        ops = {"equal": "equal", "delete": "only_a", "insert": "only_b"}
        expected = [(ops[p.op], p.a_index, p.b_index) for p in whole.alignment]
        assert rows == expected
        assert found.lcs == whole.lcs and found.lcs_length == whole.lcs_length
        assert found.edit_distance == whole.edit_distance


def test_past_the_limit_only_a_window_after_the_first_divergence_is_aligned(monkeypatch):
    """When what follows the common prefix is longer than ``ALIGNED_LIMIT`` actions, only
    ``WINDOW`` actions of each side past the first divergence are aligned, and the
    report says how many of each side were not compared."""
    monkeypatch.setattr(divergence, "ALIGNED_LIMIT", 40)
    monkeypatch.setattr(divergence, "WINDOW", 10)
    a = [_action(name, i) for i, name in enumerate("abcde" + "xy" * 30)]
    b = [_action(name, i) for i, name in enumerate("abcde" + "yx" * 25)]
    found = compare_subgoal("s", a, b)
    assert found.prefix == 5 and found.cut == divergence.Cut(65 - 15, 55 - 15)
    assert [r.a_index for r in found.rows if r.a is not None] == list(range(15))
    assert [r.b_index for r in found.rows if r.b is not None] == list(range(15))
    assert found.edit_distance == 2 and found.diverges
    text = render(diverge(a, b))
    assert "compared 10 actions of each side past the first divergence" in text
    assert "the next 50 of A and 40 of B are not compared" in text
    assert to_json(diverge(a, b))["subgoals"][0]["cut"] == {"window": 10, "a": 50, "b": 40}
    short = compare_subgoal("s", a[:20], b[:20])  # within the limit: aligned whole
    assert short.cut is None and len([r for r in short.rows if r.a]) == 20


def test_json_written_in_pieces_is_the_json_of_the_whole(taxi_runs):
    """``iter_json`` (what ``btlog diff --json`` prints) is ``json.dumps(to_json(...),
    indent=2)`` exactly: on the Taxi runs, on random pairs, with subgoals on one side."""
    cases = [diff_paths(taxi_runs["optimal"], taxi_runs["human"])]
    generator = random.Random(3)
    for _ in range(200):
        a = [_action(generator.choice("xy"), i, generator.choice("st")) for i in range(5)]
        b = [_action(generator.choice("xyz"), i, generator.choice("su")) for i in range(4)]
        cases.append(diverge(a, b))
    cases.append(diverge([], []))
    for found in cases:
        assert "".join(iter_json(found)) == json.dumps(to_json(found), indent=2)


def test_the_limit_is_shared_by_the_subgoals(monkeypatch):
    """What all the subgoals' alignments hold is bounded together: once the first has
    used the limit, the next is aligned within the window only."""
    monkeypatch.setattr(divergence, "ALIGNED_LIMIT", 40)
    monkeypatch.setattr(divergence, "WINDOW", 10)
    a = [_action(n, i, "s") for i, n in enumerate("xy" * 8)]
    a += [_action(n, 100 + i, "t") for i, n in enumerate("xy" * 8)]
    b = [_action(n, i, "s") for i, n in enumerate("yx" * 8)]
    b += [_action(n, 100 + i, "t") for i, n in enumerate("yx" * 8)]
    first, second = diverge(a, b).subgoals
    assert first.cut is None and len(first.rows) == 17  # 16 + 16 - LCS 15
    assert second.cut == divergence.Cut(6, 6)  # 40 - 17 left < 32
    tiny = diverge(a[:3] + a[16:19], b[:3] + b[16:19])  # under the window: never cut
    assert [s.cut for s in tiny.subgoals] == [None, None]

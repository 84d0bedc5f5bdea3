"""Tests of the Taxi domain (paper section 7.2): the MDP, its policies, and the generated tree."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import deque
from pathlib import Path

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from lxml import etree

from btlog.domains import taxi_world
from btlog.domains.taxi_world import (
    ACTIONS,
    Policy,
    SwitchListener,
    TaxiState,
    TaxiWorld,
    default_world,
    discounted_return,
    generate_tree_xml,
    generate_tree_xml_for,
    human_expectation_policy,
    render_grid,
    rollout,
    trace,
    tree_file_text,
    value_iteration,
)

ROOT = Path(__file__).resolve().parents[1]

R, L, U, D = "move right", "move left", "move up", "move down"
PAPER_PICK_UP = [R, R, R, U, U, L, "pick up"]
PAPER_DROP_OFF = [R, D, D, L, L, L, "drop off"]
PAPER_ACTIONS = PAPER_PICK_UP + PAPER_DROP_OFF
HUMAN_ACTIONS = [R, R, U, U, "pick up", D, D, L, L, "drop off"]
TOLL = (2, 3)


@pytest.fixture(scope="module")
def world() -> TaxiWorld:
    return default_world()


@pytest.fixture(scope="module")
def optimal(world: TaxiWorld) -> Policy:
    return value_iteration(world)


@pytest.fixture(scope="module")
def human(world: TaxiWorld) -> Policy:
    return human_expectation_policy(world)


def outline(root: etree._Element) -> dict:
    """The paper's semantic sets of a tree, v3 or v4: goal, subgoals, steps and actions."""
    trees = {bt.get("ID"): bt for bt in root.iterfind("BehaviorTree")}
    main = trees[root.get("main_tree_to_execute")]
    (goal,) = main
    subgoals = []
    for ref in goal:
        assert ref.tag == "SubTree"
        (subgoal,) = trees[ref.get("ID")]
        assert subgoal.tag == "Sequence"
        children = []
        for child in subgoal:
            if child.tag == "Sequence":
                actions = [a.get("ID") for a in child]
                assert all(a.tag == "Action" and a.get("name") == "" for a in child)
                children.append(("step", child.get("name"), actions))
            else:
                assert child.tag == "Action"
                children.append(("action", child.get("name"), child.get("ID")))
        subgoals.append((ref.get("ID"), subgoal.get("name"), children))
    return {"goal": goal.get("name"), "subgoals": subgoals}


def leaf_ids(root: etree._Element) -> list[str]:
    """Action IDs in execution order (subtrees expanded where their SubTree node stands)."""
    trees = {bt.get("ID"): bt for bt in root.iterfind("BehaviorTree")}

    def walk(node: etree._Element) -> list[str]:
        if node.tag == "SubTree":
            return [i for child in trees[node.get("ID")] for i in walk(child)]
        if node.tag == "Action":
            return [node.get("ID")]
        return [i for child in node for i in walk(child)]

    return [i for child in trees[root.get("main_tree_to_execute")] for i in walk(child)]


def parse(text: str) -> etree._Element:
    return etree.fromstring(text.encode())


# --- the paper's instance ----------------------------------------------------------------------


def test_default_world_matches_the_paper_layout(world: TaxiWorld) -> None:
    assert (world.width, world.height) == (4, 3)
    assert world.toll_at(TOLL) < 0
    assert [cell for cell, _ in world.tolls] == [TOLL]
    assert world.start == world.destination == (1, 1)
    assert world.passenger == (3, 3)


def test_module_docstring_shows_the_default_grid(world: TaxiWorld) -> None:
    drawing = "".join("    " + line + "\n" for line in render_grid(world).splitlines())
    assert drawing in taxi_world.__doc__


def test_optimal_rollout_is_the_papers_action_sequence(world: TaxiWorld, optimal: Policy) -> None:
    assert rollout(world, optimal) == PAPER_ACTIONS


def test_generated_tree_matches_the_papers_file(
    world: TaxiWorld, optimal: Policy, paper_trees: Path
) -> None:
    """The paper's own taxi tree has our optimal policy's actions and our outline."""
    reference = etree.parse(str(paper_trees / "taxi-domain-tree.xml")).getroot()
    assert leaf_ids(reference) == rollout(world, optimal)
    assert outline(parse(generate_tree_xml_for(world, optimal))) == outline(reference)


def test_optimal_path_avoids_the_toll_and_delivers(world: TaxiWorld, optimal: Policy) -> None:
    states = trace(world, rollout(world, optimal))
    assert TOLL not in [s.cell for s in states]
    assert states[-1] == TaxiState(1, 1, in_taxi=False, delivered=True)
    pick_up_state = states[len(PAPER_PICK_UP)]
    assert pick_up_state == TaxiState(3, 3, in_taxi=True, delivered=False)


def test_human_policy_takes_the_shorter_path_through_the_toll(
    world: TaxiWorld, optimal: Policy, human: Policy
) -> None:
    human_actions = rollout(world, human)
    assert human_actions == HUMAN_ACTIONS
    cells = [s.cell for s in trace(world, human_actions)]
    assert cells.count(TOLL) == 2  # through the toll on the way there and on the way back
    assert trace(world, human_actions)[-1].delivered
    assert len(human_actions) < len(rollout(world, optimal))
    moves = [a for a in human_actions if a.startswith("move")]
    assert len(moves) == 8  # 4 + 4: Manhattan distances, the shortest possible


def test_optimal_return_beats_human_return_under_true_rewards(
    world: TaxiWorld, optimal: Policy, human: Policy
) -> None:
    optimal_actions, human_actions = rollout(world, optimal), rollout(world, human)
    true_optimal = discounted_return(world, optimal_actions)
    true_human = discounted_return(world, human_actions)
    assert true_optimal > true_human
    # the human's own model (no toll) prefers the human's path: that is the divergence
    model = world.without_tolls()
    assert discounted_return(model, human_actions) > discounted_return(model, optimal_actions)
    # the value table agrees with the rollout
    assert optimal.value_table[world.start_state()] == pytest.approx(true_optimal, abs=1e-7)
    assert human.value_table[world.start_state()] == pytest.approx(
        discounted_return(model, human_actions), abs=1e-7
    )


def test_policy_is_a_deterministic_mapping(world: TaxiWorld, optimal: Policy) -> None:
    live = [s for s in world.states() if not s.delivered]
    assert set(optimal) == set(live)
    assert len(optimal) == len(live) == 2 * world.width * world.height
    assert all(optimal[s] in ACTIONS for s in optimal)
    assert dict(value_iteration(world)) == dict(optimal)
    with pytest.raises(TypeError):
        optimal[world.start_state()] = "move up"  # type: ignore[index]


def test_ties_break_in_action_order() -> None:
    # two equally short paths from (1, 1) to (2, 2): "move up" comes before "move right"
    open_world = TaxiWorld(width=2, height=2, start=(1, 1), passenger=(2, 2), destination=(2, 2))
    assert rollout(open_world, value_iteration(open_world)) == [U, R, "pick up", "drop off"]


# --- the transition function ------------------------------------------------------------------


def test_walls_and_edges_leave_the_taxi_in_place(world: TaxiWorld) -> None:
    for state, action in [
        (TaxiState(2, 2), R),  # wall between columns 2 and 3
        (TaxiState(3, 3), L),
        (TaxiState(1, 1), L),  # grid edges
        (TaxiState(1, 1), D),
        (TaxiState(3, 4), U),
        (TaxiState(3, 4), R),
    ]:
        assert world.step(state, action) == (state, world.step_cost)
    # bumping into a wall from the toll cell charges no toll again
    assert world.step(TaxiState(2, 3), L) == (TaxiState(2, 3), world.step_cost)


def test_moves_change_row_and_column(world: TaxiWorld) -> None:
    assert world.step(TaxiState(1, 1), U) == (TaxiState(2, 1), -1.0)
    assert world.step(TaxiState(2, 1), D) == (TaxiState(1, 1), -1.0)
    assert world.step(TaxiState(1, 1), R) == (TaxiState(1, 2), -1.0)
    assert world.step(TaxiState(1, 2), L) == (TaxiState(1, 1), -1.0)
    assert world.step(TaxiState(3, 4, in_taxi=True), L) == (TaxiState(3, 3, in_taxi=True), -1.0)


def test_entering_the_toll_costs_the_toll(world: TaxiWorld) -> None:
    assert world.step(TaxiState(1, 3), U) == (TaxiState(2, 3), -1.0 + world.toll_at(TOLL))
    assert world.step(TaxiState(2, 4), L) == (TaxiState(2, 3), -11.0)
    assert world.step(TaxiState(2, 3), U) == (TaxiState(3, 3), -1.0)  # leaving is free


def test_pick_up_and_drop_off(world: TaxiWorld) -> None:
    penalty = world.step_cost + world.illegal_penalty
    waiting, aboard = TaxiState(3, 3), TaxiState(3, 3, in_taxi=True)
    assert world.step(waiting, "pick up") == (aboard, world.step_cost + world.pickup_reward)
    # illegal: no passenger here, passenger already aboard, nobody to drop off, wrong place
    assert world.step(TaxiState(1, 1), "pick up") == (TaxiState(1, 1), penalty)
    assert world.step(aboard, "pick up") == (aboard, penalty)
    assert world.step(waiting, "drop off") == (waiting, penalty)
    assert world.step(TaxiState(1, 1), "drop off") == (TaxiState(1, 1), penalty)
    assert world.step(aboard, "drop off") == (aboard, penalty)
    delivered = TaxiState(1, 1, in_taxi=False, delivered=True)
    assert world.step(TaxiState(1, 1, in_taxi=True), "drop off") == (
        delivered,
        world.step_cost + world.dropoff_reward,
    )
    assert world.is_terminal(delivered)
    for action in ACTIONS:
        assert world.step(delivered, action) == (delivered, 0.0)
    with pytest.raises(ValueError, match="unknown action"):
        world.step(waiting, "teleport")


def test_world_validation() -> None:
    base = {"width": 3, "height": 2, "start": (1, 1), "passenger": (2, 3), "destination": (1, 2)}
    TaxiWorld(**base, walls=frozenset({((1, 2), (1, 1))}), tolls={(2, 2): -5})
    with pytest.raises(ValueError, match="adjacent"):
        TaxiWorld(**base, walls=frozenset({((1, 1), (2, 2))}))
    with pytest.raises(ValueError, match="outside"):
        TaxiWorld(**{**base, "passenger": (3, 1)})
    with pytest.raises(ValueError, match="outside"):
        TaxiWorld(**base, tolls={(0, 1): -5})
    with pytest.raises(ValueError, match="gamma"):
        TaxiWorld(**base, gamma=0.0)
    normalised = TaxiWorld(**base, walls=frozenset({((1, 2), (1, 1))}), tolls={(2, 2): -5})
    assert normalised.walls == frozenset({((1, 1), (1, 2))})
    assert normalised.tolls == (((2, 2), -5.0),)
    assert normalised.blocked((1, 2), (1, 1)) and normalised.blocked((1, 1), (1, 2))


def test_rollout_stops_a_policy_that_never_delivers(world: TaxiWorld) -> None:
    lazy = Policy({s: "move left" for s in world.states() if not s.delivered})
    with pytest.raises(RuntimeError, match="not delivered within 10 steps"):
        rollout(world, lazy, max_steps=10)


# --- tree generation ----------------------------------------------------------------------------


def test_generated_tree_has_the_papers_structure(world: TaxiWorld, optimal: Policy) -> None:
    ours = parse(generate_tree_xml_for(world, optimal))
    assert leaf_ids(ours) == PAPER_ACTIONS
    assert outline(ours) == {
        "goal": "go deliver passenger",
        "subgoals": [
            (
                "go pick up passenger",
                "go pick up passenger",
                [
                    ("step", "navigate to passenger", PAPER_PICK_UP[:-1]),
                    ("action", "pick up passenger", "pick up"),
                ],
            ),
            (
                "go drop off passenger",
                "go drop off passenger",
                [
                    ("step", "navigate to destination", PAPER_DROP_OFF[:-1]),
                    ("action", "drop off passenger", "drop off"),
                ],
            ),
        ],
    }


def test_generated_tree_is_btcpp_v4_with_a_node_model(world: TaxiWorld, optimal: Policy) -> None:
    root = parse(generate_tree_xml_for(world, optimal))
    assert root.tag == "root"
    assert root.get("BTCPP_format") == "4"
    assert root.get("main_tree_to_execute") == "MainTree"
    trees = root.findall("BehaviorTree")
    assert [t.get("ID") for t in trees] == [
        "MainTree",
        "go pick up passenger",
        "go drop off passenger",
    ]
    assert all(len(t) == 1 for t in trees)
    for ref in root.iter("SubTree"):
        assert ref.get("name") == ref.get("ID")
    (model,) = root.findall("TreeNodesModel")
    declared = [a.get("ID") for a in model]
    assert all(a.tag == "Action" and len(a) == 0 for a in model)
    assert sorted(declared) == sorted(set(leaf_ids(root)))
    assert len(declared) == len(set(declared))


def test_generated_xml_is_pretty_printed_with_a_comment() -> None:
    text = generate_tree_xml(PAPER_ACTIONS, comment="made here")
    lines = text.splitlines()
    assert lines[0] == '<?xml version="1.0" encoding="UTF-8"?>'
    assert lines[1] == "<!-- made here -->"
    assert lines[2] == '<root BTCPP_format="4" main_tree_to_execute="MainTree">'
    assert '        <Sequence name="go deliver passenger">' in lines
    assert text.endswith("</root>\n")
    assert "<!--" not in generate_tree_xml(PAPER_ACTIONS)
    with pytest.raises(ValueError):
        generate_tree_xml(PAPER_ACTIONS, comment="no -- allowed")


def test_generator_omits_an_empty_navigate_step() -> None:
    # passenger waiting at the start, destination there too: pick up and drop off, no moves
    here = TaxiWorld(width=2, height=2, start=(1, 2), passenger=(1, 2), destination=(1, 2))
    actions = rollout(here, value_iteration(here))
    assert actions == ["pick up", "drop off"]
    root = parse(generate_tree_xml_for(here, value_iteration(here)))
    assert outline(root)["subgoals"] == [
        (
            "go pick up passenger",
            "go pick up passenger",
            [("action", "pick up passenger", "pick up")],
        ),
        (
            "go drop off passenger",
            "go drop off passenger",
            [("action", "drop off passenger", "drop off")],
        ),
    ]
    assert [a.get("ID") for a in root.find("TreeNodesModel")] == ["pick up", "drop off"]


def test_generator_numbers_repeated_subgoals_and_uses_the_goal() -> None:
    root = parse(generate_tree_xml([U, "pick up", "pick up", D, "drop off"], goal="ride"))
    assert outline(root)["goal"] == "ride"
    assert [s[0] for s in outline(root)["subgoals"]] == [
        "go pick up passenger",
        "go pick up passenger 2",
        "go drop off passenger",
    ]
    assert leaf_ids(root) == [U, "pick up", "pick up", D, "drop off"]


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        ([], "no subgoals"),
        ([R, "pick up", L], "ends with 1 move"),
        ([R, "jump"], "unknown action"),
    ],
)
def test_generator_rejects_bad_sequences(actions: list[str], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        generate_tree_xml(actions)


def test_switch_listener_cuts_at_switches() -> None:
    listener = SwitchListener()
    completed = [listener.observe(a) for a in PAPER_ACTIONS]
    assert [c is not None for c in completed] == [
        a in ("pick up", "drop off") for a in PAPER_ACTIONS
    ]
    first, second = listener.finish()
    assert (first.name, first.step_name, first.moves) == (
        "go pick up passenger",
        "navigate to passenger",
        tuple(PAPER_PICK_UP[:-1]),
    )
    assert (second.action, second.action_name) == ("drop off", "drop off passenger")
    assert listener.pending_moves == ()


def test_human_tree_diverges_only_in_the_navigate_steps(world: TaxiWorld, human: Policy) -> None:
    human_outline = outline(parse(generate_tree_xml_for(world, human)))
    paper_outline = outline(parse(generate_tree_xml_for(world, value_iteration(world))))
    assert human_outline["goal"] == paper_outline["goal"]
    strip = [[(kind, name) for kind, name, _ in s[2]] for s in human_outline["subgoals"]]
    assert strip == [[(kind, name) for kind, name, _ in s[2]] for s in paper_outline["subgoals"]]
    assert human_outline != paper_outline


# --- the tree files -------------------------------------------------------------------------------


@pytest.mark.parametrize(("which", "path"), [("optimal", "taxi.xml"), ("human", "taxi-human.xml")])
def test_tree_files_are_the_generators_current_output(which: str, path: str) -> None:
    text = (ROOT / "trees" / path).read_text(encoding="utf-8")
    assert text == tree_file_text(which)
    assert f"python -m btlog.domains.taxi_world{' human' if which == 'human' else ''} " in text


def test_taxi_xml_is_the_generated_optimal_tree(world: TaxiWorld, optimal: Policy) -> None:
    text = (ROOT / "trees" / "taxi.xml").read_text(encoding="utf-8")
    assert text.startswith('<?xml version="1.0" encoding="UTF-8"?>\n<!-- Generated by: ')
    assert etree.tostring(parse(text)) == etree.tostring(
        parse(generate_tree_xml_for(world, optimal))
    )


def test_running_the_module_prints_the_tree() -> None:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]),
    }
    result = subprocess.run(
        [sys.executable, "-m", "btlog.domains.taxi_world"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
        timeout=60,
    )
    assert result.stdout == (ROOT / "trees" / "taxi.xml").read_text(encoding="utf-8")


# --- random worlds ------------------------------------------------------------------------------


def bfs_steps(world: TaxiWorld, source: tuple[int, int], target: tuple[int, int]) -> int | None:
    """Fewest moves between two cells, written independently of TaxiWorld.step."""
    seen = {source: 0}
    queue = deque([source])
    while queue:
        cell = queue.popleft()
        if cell == target:
            return seen[cell]
        for d_row, d_col in ((1, 0), (-1, 0), (0, -1), (0, 1)):
            nxt = (cell[0] + d_row, cell[1] + d_col)
            inside = 1 <= nxt[0] <= world.height and 1 <= nxt[1] <= world.width
            if inside and nxt not in seen and (min(cell, nxt), max(cell, nxt)) not in world.walls:
                seen[nxt] = seen[cell] + 1
                queue.append(nxt)
    return None


@st.composite
def small_worlds(draw: st.DrawFn) -> TaxiWorld:
    width = draw(st.integers(1, 5))
    height = draw(st.integers(1, 5))
    cell = st.tuples(st.integers(1, height), st.integers(1, width))
    edges = [((r, c), (r, c + 1)) for r in range(1, height + 1) for c in range(1, width)]
    edges += [((r, c), (r + 1, c)) for r in range(1, height) for c in range(1, width + 1)]
    walls = draw(st.sets(st.sampled_from(edges), max_size=6)) if edges else set()
    return TaxiWorld(
        width=width,
        height=height,
        start=draw(cell),
        passenger=draw(cell),
        destination=draw(cell),
        walls=frozenset(walls),
        # undiscounted value iteration only converges if delivery is possible from every state
        gamma=draw(st.sampled_from([0.9, 0.95, 0.99, *([1.0] if not walls else [])])),
    )


@settings(max_examples=150, deadline=None)
@given(small_worlds())
def test_optimal_rollout_delivers_in_the_fewest_steps(world: TaxiWorld) -> None:
    to_passenger = bfs_steps(world, world.start, world.passenger)
    to_destination = bfs_steps(world, world.passenger, world.destination)
    assume(to_passenger is not None and to_destination is not None)
    actions = rollout(world, value_iteration(world))
    assert len(actions) == to_passenger + 1 + to_destination + 1
    assert actions.count("pick up") == actions.count("drop off") == 1
    assert trace(world, actions)[-1].delivered
    # and every such rollout becomes a valid two-subgoal tree
    subgoals = outline(parse(generate_tree_xml(actions)))["subgoals"]
    assert [s[0] for s in subgoals] == ["go pick up passenger", "go drop off passenger"]
    assert leaf_ids(parse(generate_tree_xml(actions))) == actions


@settings(max_examples=100, deadline=None)
@given(small_worlds(), st.lists(st.sampled_from(ACTIONS), max_size=30))
def test_step_keeps_the_taxi_on_the_grid(world: TaxiWorld, actions: list[str]) -> None:
    for before, after in zip(trace(world, actions), trace(world, actions)[1:], strict=False):
        assert world.in_grid(after.cell)
        assert abs(before.row - after.row) + abs(before.col - after.col) <= 1
        assert not (before.delivered and after != before)

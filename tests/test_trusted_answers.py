"""Answers a robotics engineer can trust on trees written without the paper's framing.

The expectations files in ``tests/data/answers`` (``*.answers.yaml``: not ``*.expect.yaml``,
which the pytest plugin checks against a recording beside them; these runs are made by
the test) pin what the real command line answers on
a small fetch tree and on two Nav2 stand-ins (the default NavigateToPose tree, and the
shape Nav2 shipped for several releases whose recoveries sit behind a GoalUpdated check).
The other tests cover each notion as users meet it: the run's story (outcome, runs of the
goal, guards), grounded reasons, descriptions, and questions about nodes a tree lacks.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import ClassVar

import pytest

from btlog.executor.actions import Condition, InputPort, OutputPort, StatefulAction
from btlog.executor.engine import Executor
from btlog.explain.questions import answer
from btlog.explain.story import story
from btlog.explain.words import is_named, restates_structure
from btlog.history import LiveHistory
from btlog.record.recorder import Recorder
from btlog.replay.database import open_runs
from btlog.status import FAILURE, RUNNING, SUCCESS
from btlog.tree.loader import load_tree_text
from btlog.tree.registry import Registry
from tests.cli_support import ROOT, assert_bad_input, btlog

DATA = ROOT / "tests" / "data" / "answers"
NAV2 = ROOT / "trees" / "nav2"
NODES_MODEL = NAV2 / "nodes_model.xml"

#: (tree, outcomes, nodes model or None, expectations), each run and checked as a user would.
EXPECTED = {
    "fetch": (DATA / "fetch-coffee.xml", DATA / "fetch-coffee.yaml", None),
    "nav2": (NAV2 / "navigate_to_pose.xml", NAV2 / "follow-path-fails-once.yaml", NODES_MODEL),
    "nav2-recovery-fallbacks": (
        DATA / "nav2-recovery-fallbacks.xml",
        DATA / "nav2-recovery-fallbacks.yaml",
        NODES_MODEL,
    ),
    "route-and-tour": (DATA / "route-and-tour.xml", DATA / "route-and-tour.yaml", None),
}
EXPECTATIONS = {
    "fetch": DATA / "fetch-coffee.answers.yaml",
    "nav2": DATA / "nav2-navigate-to-pose.answers.yaml",
    "nav2-recovery-fallbacks": DATA / "nav2-recovery-fallbacks.answers.yaml",
    "route-and-tour": DATA / "route-and-tour.answers.yaml",
}


def _run(tmp_path: Path, case: str, *extra: str) -> Path:
    tree, outcomes, model = EXPECTED[case]
    out = tmp_path / f"{case}.mcap"
    args = ["run", str(tree), "--outcomes", str(outcomes), "-o", str(out), "--quiet", *extra]
    if model is not None:
        args += ["--nodes-model", str(model)]
    done = btlog(*args)
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.parametrize("case", sorted(EXPECTED))
def test_answers_meet_their_expectations(tmp_path: Path, case: str) -> None:
    recording = _run(tmp_path, case)
    checked = btlog("check", str(recording), "--expect", str(EXPECTATIONS[case]))
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert ", 0 failed" in checked.stdout


def _story(recording: Path, *options: str) -> list[str]:
    done = btlog("explain", str(recording), *options)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


def test_the_nav2_story_tells_the_one_real_failure(tmp_path: Path) -> None:
    """FollowPath failed once, at 2 s; the replanning checks (IsGoalNearby) that fail by
    design every second are counted apart, never told as failures; the root, a
    RecoveryNode that halts itself before returning SUCCESS, ran once."""
    lines = _story(_run(tmp_path, "nav2"))
    assert lines[0] == (
        "Goal: navigate recovery. Outcome: SUCCESS after 5.500 s, 56 ticks, 163 events."
    )
    assert lines[1:4] == [
        "Failures: 1.",
        "  2.000 s: I could not follow path because follow path failed.",
        "    fell back to clear local costmap context.",
    ]
    assert lines[4] == "  (6 failures by design chose another branch.)"
    assert not any("ran 2 times" in line or "times:" in line for line in lines)
    assert lines[5:] == [
        "Subgoals:",
        "  navigate with replanning: SUCCESS in 5.500 s (0.000 s to 5.500 s)",
        "  recovery fallback: not started",
    ]


def test_an_unnamed_branch_is_never_what_could_not_be_done(tmp_path: Path) -> None:
    """The route's unnamed Sequence failed while Algorithm 7 had nothing to say (its
    fallback's first child failed by design): the episode names what it served."""
    lines = _story(_run(tmp_path, "route-and-tour"))
    assert lines[2:4] == [
        "Failures: 2.",
        "  1.000 s: I could not compute route because append goal pose to goals failed.",
    ]


def test_the_fetch_story_names_what_is_retried(tmp_path: Path) -> None:
    lines = _story(_run(tmp_path, "fetch"))
    assert lines[1:8] == [
        "Failures: 3.",
        "  1.000 s: I could not get to kitchen because go to the kitchen failed.",
        "    fell back to take the stairs.",
        "  2.000 s: I am retrying for attempt 1 to retry grasp because grasp cup failed.",
        "    retried (attempt 1 of 2).",
        "  2.500 s: I am retrying for attempt 2 to retry grasp because grasp cup failed.",
        "    retried (attempt 2 of 2).",
    ]
    assert lines[8:] == [
        "Subgoals:",
        "  get to kitchen: SUCCESS in 1.500 s (0.000 s to 1.500 s)",
        "  grasp cup: SUCCESS, 3 runs (1.500 s to 3.000 s), the last in 0.500 s",
        "  bring coffee: SUCCESS in 0.500 s (3.000 s to 3.500 s)",
    ]


@pytest.mark.parametrize("case", ["fetch", "nav2", "nav2-recovery-fallbacks"])  # they succeed
def test_what_went_wrong_after_the_fact_is_the_storys_last_episode(
    tmp_path: Path, case: str
) -> None:
    """One notion of a failure episode: at the end, "What went wrong?" tells the story's
    last episode, at the time its leaf failed and in the words the story uses."""
    recording = _run(tmp_path, case)
    told = json.loads(btlog("explain", str(recording), "--json").stdout)
    last = told["episodes"][-1]
    said = btlog("ask", str(recording), "--at", "end", "What went wrong?").stdout.strip()
    assert said == f"At {last['last_t_ns'] / 1e9:.3f} s: {last['what_went_wrong']}"


SEARCH = """
<root BTCPP_format="4" main_tree_to_execute="Find">
  <BehaviorTree ID="Find">
    <Sequence name="pick the object">
      <Fallback name="find object">
        <ForceFailure name="look in place 1">
          <Sequence>
            <Action ID="Move" name="move to place 1"/>
            <Action ID="Look" name="look around"/>
          </Sequence>
        </ForceFailure>
        <Action ID="Move" name="move to place 2"/>
      </Fallback>
      <Action ID="Grasp" name="grasp object"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


def test_a_failure_made_from_a_success_is_by_design(tmp_path: Path) -> None:
    """A Fallback whose first alternative is forced to fail after it succeeded (look in
    one place, then go on to the next: kmriiwa's search) chose its next branch by design:
    nothing went wrong, and the story counts it apart."""
    tree = tmp_path / "search.xml"
    tree.write_text(SEARCH, encoding="utf-8")
    out = tmp_path / "search.mcap"
    done = btlog("run", str(tree), "-o", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    for at in ("1.2s", "end"):
        said = btlog("ask", str(out), "--at", at, "What went wrong?").stdout.strip()
        assert said == "Nothing went wrong.", at
    lines = _story(out)
    assert lines[1:3] == ["No failures.", "  (1 failure by design chose another branch.)"]


def test_a_run_stopped_while_running_is_not_finished(tmp_path: Path) -> None:
    recording = _run(tmp_path, "fetch", "--max-ticks", "20")
    told = json.loads(btlog("explain", str(recording), "--json").stdout)
    assert told["outcome"] == "not finished (RUNNING)"
    assert _story(recording)[0].startswith("Goal: fetch coffee. Outcome: not finished (RUNNING)")


LOOP = """
<root BTCPP_format="4" main_tree_to_execute="Patrol">
  <BehaviorTree ID="Patrol">
    <Sequence name="patrol">
      <Action ID="Drive" name="drive to the door"/>
      <Action ID="Look" name="look around"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


class _Steps(StatefulAction):
    """Runs for two ticks, then succeeds."""

    def on_start(self):
        self.left = 2
        return RUNNING

    def on_running(self):
        self.left -= 1
        return RUNNING if self.left else SUCCESS


def _looping_run(path: Path, ticks: int) -> LiveHistory:
    """A BT.CPP program's loop: the tree ticked again after each completion."""
    registry = Registry()
    registry.register_leaf(_Steps, "Drive")
    registry.register_leaf(_Steps, "Look")
    tree = load_tree_text(LOOP, registry)
    executor = Executor(tree, registry)
    recorder = Recorder(path, tree, {"domain": "loop"}, flush_interval=0)
    live = LiveHistory(tree)
    executor.subscribe(recorder)
    executor.subscribe(live)
    for _ in range(ticks):
        executor.tick()
    executor.close()
    return live


def test_a_looping_tree_tells_each_run_of_the_goal(tmp_path: Path) -> None:
    """Re-runs of the root are runs of the goal of their own, not attempts of its
    subgoals; the outcome is the last run's status."""
    path = tmp_path / "loop.mcap"
    live = _looping_run(path, 14)
    told = story(live.tree, live.state, live)
    assert [r.result for r in told.runs] == ["SUCCESS", "SUCCESS", None]
    assert told.outcome == "not finished (RUNNING)"
    lines = _story(path)
    assert lines[1] == "The goal ran 3 times:"
    assert lines[2].startswith("  1. SUCCESS in ")
    assert lines[4].startswith("  3. ")
    assert "Subgoals (in the goal's last run):" in lines
    assert all("attempts" not in line for line in lines)
    asked = btlog("ask", str(path), "--at", "end", "How long did drive to the door take?")
    assert asked.stdout.strip() == "drive to the door took 0.200 s, from 1.000 s to 1.200 s."


def test_a_recovery_node_halting_itself_runs_once(tmp_path: Path) -> None:
    """Nav2's RecoveryNode resets itself before it returns SUCCESS: that result ends its
    activation, so it took the whole navigation, not no time."""
    recording = _run(tmp_path, "nav2")
    asked = btlog("ask", str(recording), "--at", "end", "How long did navigate recovery take?")
    assert asked.stdout.strip() == "navigate recovery took 5.500 s, from 0.000 s to 5.500 s."
    told = json.loads(btlog("explain", str(recording), "--json").stdout)
    assert told["goal_runs"] == [{"start_ns": 0, "end_ns": 5_500_000_000, "result": "SUCCESS"}]


# -- grounded reasons --------------------------------------------------------------------
GROUNDED = """
<root BTCPP_format="4" main_tree_to_execute="Deliver">
  <BehaviorTree ID="Deliver">
    <Sequence name="deliver the parcel">
      <Script name="battery monitor" code="battery_level := 12"/>
      <Fallback name="get the parcel there">
        <Sequence name="drive there">
          <BatteryOK name="battery OK" level="{battery_level}"/>
          <FollowPath name="follow path" error_code_id="{follow_error}"/>
        </Sequence>
        <FollowPath name="take the long way" error_code_id="{long_error}"/>
      </Fallback>
    </Sequence>
  </BehaviorTree>
</root>
"""


class BatteryOK(Condition):
    """Fails below 20 %."""

    ports: ClassVar = {"level": InputPort("int")}

    def check(self):
        return self.get_input("level") >= 20


class FollowPath(StatefulAction):
    """Reports Nav2's error code 106 ("no valid control"), then fails."""

    ports: ClassVar = {"error_code_id": OutputPort()}

    def on_start(self):
        self.set_output("error_code_id", 106)
        return FAILURE


def _grounded_tree(xml: str):
    registry = Registry()
    registry.register_leaf(BatteryOK)
    registry.register_leaf(FollowPath)
    return load_tree_text(xml, registry), registry


def _record_grounded(path: Path, xml: str) -> LiveHistory:
    tree, registry = _grounded_tree(xml)
    executor = Executor(tree, registry)
    recorder = Recorder(path, tree, {"domain": "grounded"}, flush_interval=0)
    live = LiveHistory(tree)
    executor.subscribe(recorder)
    executor.subscribe(live)
    executor.run(10)
    executor.close(teardown=False)
    return live


def _both(path: Path, live: LiveHistory, question: str) -> str:
    """The live answer at the end, checked equal to the answer from the file alone."""
    said = answer(live.tree, live.state, question, live).text
    with open_runs(path, cache=False) as database:
        run = database.run()
        tree, state = run.state_at("end")
        assert answer(tree, state, question, run.history()).text == said
    return said


def test_a_failed_condition_is_grounded_in_what_it_read(tmp_path: Path) -> None:
    path = tmp_path / "grounded.mcap"
    live = _record_grounded(path, GROUNDED)
    assert _both(path, live, "Why did drive there fail?") == (
        "I could not drive there because battery OK failed "
        "(battery_level = 12, written by battery monitor at 0.000 s)."
    )
    assert _both(path, live, "Why did battery OK fail?") == (
        "battery OK failed at 0.000 s (battery_level = 12, written by battery monitor at 0.000 s)."
    )


def test_a_failed_action_is_grounded_in_what_it_reported(tmp_path: Path) -> None:
    path = tmp_path / "grounded.mcap"
    live = _record_grounded(
        path, GROUNDED.replace('code="battery_level := 12"', 'code="battery_level := 80"')
    )
    assert _both(path, live, "What went wrong?") == (
        "I could not get the parcel there because I was unable to drive there as follow path "
        "failed (error_code_id = 106)."
    )
    assert _both(path, live, "Why didn't you follow path?") == (
        "I tried to follow path, but it failed (error_code_id = 106)."
    )
    assert _both(path, live, "Why did get the parcel there fail?") == (
        "I could not get the parcel there because take the long way failed (error_code_id = 106)."
    )


def test_grounds_are_bounded_and_values_are_shown_as_json(tmp_path: Path) -> None:
    long = "x" * 500
    xml = GROUNDED.replace('code="battery_level := 12"', f"code=\"battery_level := '{long}'\"")
    xml = xml.replace('InputPort("int")', 'InputPort("str")')
    path = tmp_path / "grounded.mcap"

    class Picky(BatteryOK):
        ports: ClassVar = {"level": InputPort("str")}

        def check(self):
            return False

    tree, registry = _grounded_tree(xml)
    registry.register_leaf(Picky, "BatteryOK")
    tree = load_tree_text(xml, registry)
    executor = Executor(tree, registry)
    live = LiveHistory(tree)
    executor.subscribe(Recorder(path, tree, {"domain": "grounded"}, flush_interval=0))
    executor.subscribe(live)
    executor.run(5)
    executor.close(teardown=False)
    said = answer(live.tree, live.state, "Why did battery OK fail?", live).text
    assert said.startswith("battery OK failed at 0.000 s (battery_level = xxx")
    assert len(said) < 200 and "…" in said


# -- descriptions ------------------------------------------------------------------------
def test_descriptions_give_answers_their_words_live_and_post_hoc(tmp_path: Path) -> None:
    words = tmp_path / "words.yaml"
    words.write_text(
        "NavigateRecovery: navigate to the goal\n"
        "ClearLocalCostmap-Context: clear the local costmap\n"
        "FollowPath: follow the path\n",
        encoding="utf-8",
    )
    recording = _run(
        tmp_path, "nav2", "--descriptions", str(words), "--ask", "2.2s=What are you doing?"
    )
    asked = btlog("ask", str(recording), "--at", "2.2s", "Why are you doing this?")
    assert asked.stdout.strip() == "I clear the local costmap in order to follow the path."
    goal = btlog("ask", str(recording), "--at", "2.2s", "What is your goal?")
    assert goal.stdout.strip() == "My goal is to navigate to the goal."
    rows = btlog("sql", str(recording), "SELECT metadata FROM runs", "--format", "json")
    metadata = json.loads(json.loads(rows.stdout)[0]["metadata"])
    assert json.loads(metadata["descriptions"])["FollowPath"] == "follow the path"
    # a file given post hoc goes over what was recorded
    other = tmp_path / "other.yaml"
    other.write_text("NavigateRecovery: reach the goal pose\nNoSuchNode: nothing\n")
    again = btlog(
        "ask", str(recording), "--at", "2.2s", "What is your goal?", "--descriptions", str(other)
    )
    assert again.stdout.strip() == "My goal is to reach the goal pose."
    assert "'NoSuchNode' names no node" in again.stderr


def test_a_description_attribute_of_the_xml_is_the_nodes_words(tmp_path: Path) -> None:
    tree = tmp_path / "described.xml"
    tree.write_text(
        (DATA / "fetch-coffee.xml")
        .read_text()
        .replace('name="grasp cup"', 'name="grasp cup" _description="pick the cup up"')
        .replace(
            '<BehaviorTree ID="FetchCoffee">',
            '<BehaviorTree ID="FetchCoffee" _description="bring me a coffee">',
        ),
        encoding="utf-8",
    )
    out = tmp_path / "described.mcap"
    ran = btlog(
        "run", str(tree), "--outcomes", str(DATA / "fetch-coffee.yaml"), "-o", str(out), "--quiet"
    )
    assert ran.returncode == 0, ran.stderr
    assert btlog("ask", str(out), "--at", "2.2s", "What are you doing?").stdout.strip() == (
        "I pick the cup up."
    )
    assert btlog("ask", str(out), "--at", "2.2s", "What is your goal?").stdout.strip() == (
        "My goal is to bring me a coffee."
    )


def test_a_bad_descriptions_file_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("FollowPath:\n  - not a phrase\n", encoding="utf-8")
    tree, outcomes, _ = EXPECTED["fetch"]
    done = btlog(
        "run",
        str(tree),
        "--outcomes",
        str(outcomes),
        "--descriptions",
        str(bad),
        "-o",
        str(tmp_path / "x.mcap"),
    )
    assert_bad_input(done, "bad.yaml:2", "FollowPath")
    assert not (tmp_path / "x.mcap").exists()


# -- nodes a question names --------------------------------------------------------------
def test_a_node_the_tree_lacks_is_bad_input_like_an_unknown_question(tmp_path: Path) -> None:
    recording = _run(tmp_path, "fetch")
    for question in ("Why did teleport fail?", "Can you teleport?"):
        done = btlog("ask", str(recording), "--at", "end", question)
        assert_bad_input(done, 'Sorry. I don\'t know "teleport".')
    unknown = btlog("ask", str(recording), "--at", "end", "Are you a teapot?")
    assert unknown.returncode == 2
    known = btlog("ask", str(recording), "--at", "end", "Can you fetch coffee?")
    assert known.returncode == 0
    assert known.stdout.strip() == 'Sorry. I cannot redo "fetch coffee".'


def test_a_name_an_answer_prints_is_understood_in_a_question(tmp_path: Path) -> None:
    recording = _run(tmp_path, "nav2")
    for name in ("ClearLocalCostmap-Context", "clear local costmap context"):
        done = btlog("ask", str(recording), "--at", "end", f"When did {name} last start?")
        assert done.stdout.strip() == "clear local costmap context last started at 2.000 s."


DOCUMENTED = """
<root BTCPP_format="4" main_tree_to_execute="Tidy Up">
  <BehaviorTree ID="Tidy Up" _description="Returns the arm to its home pose. Then it waits.">
    <Sequence name="TopLevelSequence">
      <SubTree ID="Open Gripper"/>
      <RecoveryNode name="RecoveryFollowPath" number_of_retries="1">
        <Action ID="FollowPath"/>
        <Action ID="Spin" name="SpinRecovery"/>
      </RecoveryNode>
      <Action ID="Wait" name="Drive in a square"/>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Open Gripper" _description="An example showing how to open the gripper.">
    <Action ID="Open"/>
  </BehaviorTree>
</root>
"""


def test_descriptions_are_phrases_and_names_read_as_words(tmp_path: Path) -> None:
    """Descriptions written as documentation (MoveIt Pro's, Groot2's) are spoken as the
    phrase they start with, or not at all; a control's type is dropped from its name, a
    leaf's never; capitals of a name with spaces are lowered."""
    tree_file = tmp_path / "documented.xml"
    tree_file.write_text(DOCUMENTED, encoding="utf-8")
    outcomes = tmp_path / "outcomes.yaml"
    outcomes.write_text("nodes: {FollowPath: [FAILURE, SUCCESS]}\n", encoding="utf-8")
    out = tmp_path / "documented.mcap"
    ran = btlog("run", str(tree_file), "--outcomes", str(outcomes), "-o", str(out), "--quiet")
    assert ran.returncode == 0, ran.stderr
    asked = {
        "What is your goal?": "My goal is to return the arm to its home pose.",
        "Why are you doing this?": "I spin recovery in order to follow path.",
        "What went wrong?": "I could not follow path because follow path failed.",
        "How do you achieve your goal?": 'To achieve the goal "return the arm to its home '
        'pose", I need to do 3 steps. 1. open gripper. 2. follow path. 3. drive in a square.',
    }
    for question, expected in asked.items():
        done = btlog("ask", str(out), "--at", "1.2s", question)
        assert done.stdout.strip() == expected, question


REPEATED = """
<root BTCPP_format="4" main_tree_to_execute="TreeA">
  <BehaviorTree ID="TreeA">
    <Sequence>
      <Action ID="PushIntoVector"/>
      <Action ID="PushIntoVector"/>
      <Action ID="TEST_ACTION_A"/>
      <Action ID="PushIntoVector"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


def test_same_named_leaves_shouted_names_and_a_lone_action_as_the_goal(tmp_path: Path) -> None:
    """Of nodes sharing a name, "Why didn't you X?" is about the one that failed (BT.CPP's
    examples repeat a type unnamed); an identifier all in capitals is words; a tree that
    is one action has that action as its goal, as Q2 says."""
    tree = tmp_path / "repeated.xml"
    tree.write_text(REPEATED, encoding="utf-8")
    outcomes = tmp_path / "outcomes.yaml"
    outcomes.write_text('nodes: {"PushIntoVector::5": FAILURE}\n', encoding="utf-8")
    out = tmp_path / "repeated.mcap"
    ran = btlog("run", str(tree), "--outcomes", str(outcomes), "-o", str(out), "--quiet")
    assert ran.returncode == 0, ran.stderr
    said = btlog("ask", str(out), "Why didn't you push into vector?").stdout.strip()
    assert said == "I tried to push into vector, but it failed."
    said = btlog("ask", str(out), "--at", "1.2s", "What are you doing?").stdout.strip()
    assert said == "I test action a."
    lone = tmp_path / "lone.xml"
    lone.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="BehaviorTree"><Action ID="Arm"/>'
        "</BehaviorTree></root>",
        encoding="utf-8",
    )
    ran = btlog("run", str(lone), "-o", str(tmp_path / "lone.mcap"), "--quiet")
    assert ran.returncode == 0, ran.stderr
    for question, expected in (
        ("What is your goal?", "My goal is to arm."),
        ("Why are you doing this?", "I arm because it is my goal."),
    ):
        said = btlog("ask", str(tmp_path / "lone.mcap"), "--at", "0.2s", question)
        assert said.stdout.strip() == expected


RESTATED = """<root BTCPP_format="4" main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree">
    <Sequence name="root_sequence">
      <Fallback name="get to kitchen">
        <Action ID="GoTo" name="go to the kitchen"/>
        <Action ID="TakeStairs" name="take the stairs"/>
      </Fallback>
      <SubTree ID="Grasping" name="MainTree"/>
      <Sequence name="RootSequence">
        <Action ID="Bring" name="bring coffee"/>
      </Sequence>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Grasping">
    <Sequence name="main_sequence"><Action ID="Grasp" name="grasp cup"/></Sequence>
  </BehaviorTree>
</root>
"""


def test_names_that_restate_a_type_or_a_tree_id_are_no_names(tmp_path: Path) -> None:
    """A Sequence named root_sequence, RootSequence or main_sequence, a SubTree and a tree
    named MainTree say nothing of what the robot does: no answer uses them as a purpose,
    a subgoal or the goal; the answers climb to named nodes, and the goal, with nothing
    above naming it, is what the root holds."""
    tree = tmp_path / "restated.xml"
    tree.write_text(RESTATED, encoding="utf-8")
    outcomes = tmp_path / "outcomes.yaml"
    outcomes.write_text(
        'default: {status: SUCCESS, duration: 0.5}\nnodes: {"go to the kitchen": FAILURE}\n',
        encoding="utf-8",
    )
    out = tmp_path / "restated.mcap"
    ran = btlog("run", str(tree), "--outcomes", str(outcomes), "-o", str(out), "--quiet")
    assert ran.returncode == 0, ran.stderr
    goal = "get to kitchen, grasp cup and bring coffee"
    for at, question, expected in (
        ("0.7s", "What is your goal?", f"My goal is to {goal}."),
        ("1.2s", "Why are you doing this?", "I grasp cup in order to " + goal + "."),
        ("1.2s", "What is your subgoal?", "My subgoal is to grasp cup."),
        ("1.7s", "What is your subgoal?", "My subgoal is to bring coffee."),
        ("1.7s", "Why are you doing this?", "I bring coffee in order to " + goal + "."),
        (
            "1.2s",
            "How do you achieve your goal?",
            f'To achieve the goal "{goal}", I need to do 3 steps. 1. get to kitchen. '
            "2. grasp cup. 3. bring coffee.",
        ),
    ):
        said = btlog("ask", str(out), "--at", at, question)
        assert said.stdout.strip() == expected, (at, question)
    told = _story(out)
    assert told[0].startswith(f"Goal: {goal}. Outcome: SUCCESS")
    subgoals = told[told.index("Subgoals:") + 1 :]
    assert [line.split(":")[0] for line in subgoals] == [
        "  get to kitchen",
        "  grasp cup",
        "  bring coffee",
    ]
    loaded = load_tree_text(RESTATED)
    unnamed = {n.name for n in loaded if not is_named(n)}
    assert {"root_sequence", "RootSequence", "main_sequence", "MainTree"} <= unnamed
    assert is_named(next(n for n in loaded if n.name == "get to kitchen"))


@pytest.mark.parametrize(
    ("name", "type_", "restates"),
    [  # names of controls and trees in public BT.CPP and Nav2 trees
        ("root_sequence", "Sequence", True),
        ("RootSequence", "Sequence", True),
        ("main_sequence", "Sequence", True),
        ("root_selector", "Fallback", True),
        ("MainSequence", "ReactiveSequence", True),
        ("main_seq", "Sequence", True),
        ("SeqNode", "Sequence", True),
        ("Main loop", "Sequence", True),
        ("retry", "RetryUntilSuccessful", True),
        ("MainTree", "SubTree", True),
        ("BehaviorTree", "", True),
        ("Tree1", "", True),
        ("NavigateRecovery", "RecoveryNode", False),
        ("RecoveryFallback", "ReactiveFallback", False),
        ("ClearingActions", "Sequence", False),
        ("search_location", "Sequence", False),
        ("retry grasp", "RetryUntilSuccessful", False),
        ("FetchCoffee", "", False),
    ],
)
def test_a_name_restates_its_type_only_when_it_says_nothing_else(
    name: str, type_: str, restates: bool
) -> None:
    assert restates_structure(name, type_) is restates

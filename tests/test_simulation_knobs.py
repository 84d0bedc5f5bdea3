"""What a simulated run of a real tree needs: the blackboard the host program sets, the
outputs of custom leaves, pass-through for custom decorators and controls, a nodes model
that the XML overrides, and a warning when a leaf is halted over and over."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from btlog.domains.outcomes import Outcomes, OutcomesError
from btlog.runner import RunConfig, prepare
from tests.cli_support import assert_bad_input, btlog

DATA = Path(__file__).resolve().parent / "data" / "trees"
HOST = DATA / "host_blackboard.xml"
HOST_OUTCOMES = DATA / "host_blackboard.outcomes.yaml"


def _writes(recording: Path) -> list[tuple[str, object, str, int | None]]:
    result = btlog(
        "sql",
        recording,
        "SELECT key, value, type, writer_uid FROM blackboard ORDER BY seq",
        "--format",
        "json",
    )
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)
    return [(r["key"], json.loads(r["value"]), r["type"], r["writer_uid"]) for r in rows]


def test_blackboard_and_outputs_drive_the_tree(tmp_path: Path) -> None:
    """The host's entries are written before the first tick (no writer); a custom leaf's
    outputs land on the entries its ports name, typed as its model declares them, and the
    RetryUntilSuccessful reading {num_locs} retries 3 times."""
    recording = tmp_path / "host.mcap"
    result = btlog("run", HOST, "--outcomes", HOST_OUTCOMES, "-o", recording)
    assert result.returncode == 0, result.stderr
    assert "final status: SUCCESS" in result.stdout
    writes = _writes(recording)
    assert writes[:2] == [
        ("goal", {"x": 2.0, "y": 1.0}, "dict", None),
        ("speed", 0.5, "float", None),
    ]
    assert ("num_locs", 3, "int", 4) in writes and ("location", "kitchen", "str", 4) in writes
    rerun = btlog("check", recording, "--rerun")  # the recorded outcomes hold both
    assert rerun.returncode == 0, rerun.stdout + rerun.stderr


def test_without_them_the_refusal_says_what_is_missing(tmp_path: Path) -> None:
    result = btlog("run", HOST, "-o", tmp_path / "x.mcap")
    assert_bad_input(
        result,
        "host_blackboard.xml:8:",
        "port 'input_goal': blackboard entry 'goal' does not exist",
        "give it under 'blackboard:' in an outcomes file",
    )


@pytest.mark.parametrize(
    ("outcomes", "words"),
    [
        (
            "blackboard: {goal: 1, speed: 1, num_locs: many}\n"
            "nodes: {get locations: {outputs: {first: kitchen}}}",
            ["outcomes.yaml:1: blackboard 'num_locs'", "'many' is not a valid int"],
        ),
        (
            "blackboard: {goal: 1, speed: 1}\nnodes:\n  get locations: {outputs: {num_locs: 2.5}}",
            ["outcomes.yaml:3: outputs: 'num_locs'", "2.5 is not a valid int"],
        ),
        (
            "nodes:\n  get locations: {outputs: {count: 2}}",
            ["outcomes.yaml:2: outputs: 'get locations' has no port 'count' in the tree"],
        ),
        (
            "nodes:\n  go to pose: {outputs: {speed: fast}}",
            ["outcomes.yaml:2: outputs: port 'speed' of 'go to pose' is 'slow' in the tree"],
        ),
        ("blackboard: {when: 2024-01-01}", ["outcomes.yaml:1: blackboard['when']"]),
        ("default: {status: SUCCESS, outputs: {a: 1}}", ["outcomes.yaml:1: default"]),
    ],
    ids=["blackboard type", "output type", "no such port", "not a key", "not JSON", "default"],
)
def test_bad_blackboard_and_outputs(tmp_path: Path, outcomes: str, words: list[str]) -> None:
    path = tmp_path / "outcomes.yaml"
    path.write_text(outcomes)
    with pytest.raises(OutcomesError) as caught:
        prepare(RunConfig(tree=str(HOST), outcomes_file=str(path)))
    for word in words:
        assert word in str(caught.value), str(caught.value)


def test_outcomes_keep_blackboard_and_outputs_as_written() -> None:
    outcomes = Outcomes.from_mapping(
        {"blackboard": {"@goal": 1}, "nodes": {"a": [{"status": "SUCCESS", "outputs": {"p": 1}}]}}
    )
    assert outcomes.blackboard == {"goal": 1}
    assert outcomes.source["nodes"]["a"][0]["outputs"] == {"p": 1}


def test_custom_decorators_and_controls_run_as_pass_through(tmp_path: Path) -> None:
    result = btlog("run", DATA / "custom_nodes.xml", "-o", tmp_path / "c.mcap")
    assert result.returncode == 0, result.stderr
    assert "final status: SUCCESS" in result.stdout
    warnings = result.stderr.splitlines()
    assert any(
        "custom_nodes.xml:8: 'WaitForEvent' is a decorator btlog has no code for" in w
        and "its child's result is its own" in w
        for w in warnings
    ), warnings
    assert any("'BestEffort' is a control" in w and "as a Sequence" in w for w in warnings)
    shown = btlog("timeline", tmp_path / "c.mcap", "--node", "go to B")
    assert "SUCCESS" in shown.stdout  # the pass-through control ran both children


def test_an_undeclared_type_with_children_is_refused_naming_what_btcpp_needs(
    tmp_path: Path,
) -> None:
    text = (DATA / "custom_nodes.xml").read_text()
    path = tmp_path / "undeclared.xml"
    path.write_text(text.replace('<Decorator ID="WaitForEvent">', '<Decorator ID="Other">'))
    assert_bad_input(
        btlog("validate", path),
        "undeclared.xml:8: unknown node type 'WaitForEvent' with children",
        "BT.CPP would need the code that registers it (a plugin, or the program's",
        "<TreeNodesModel>",
    )


def test_a_stale_nodes_model_warns_and_the_xml_wins(tmp_path: Path) -> None:
    result = btlog(
        "run",
        DATA / "stale_model.xml",
        "--nodes-model",
        DATA / "stale_nodes_model.xml",
        "-o",
        tmp_path / "s.mcap",
    )
    assert result.returncode == 0, result.stderr
    assert "final status: SUCCESS" in result.stdout
    warnings = result.stderr
    assert "stale_model.xml:8: Spin has no port 'is_recovery' in the nodes model" in warnings
    assert "'fast' is not a valid double" in warnings and "kept as written" in warnings
    assert "declares 'CheckAndRetry' an action, but the XML gives it 1 child" in warnings
    assert warnings.count("Spin has no port") == 1  # once per type and port, not per tick


def test_a_livelock_is_warned_about_with_its_cause(tmp_path: Path) -> None:
    livelock = DATA / "livelock.xml"
    result = btlog("run", livelock, "-o", tmp_path / "l.mcap", "--max-ticks", "1000")
    assert result.returncode == 0, result.stderr
    assert "final status: RUNNING" in result.stdout
    [warning] = [line for line in result.stderr.splitlines() if "' was halted" in line]
    assert "'follow path' was halted 166 times in a row and never finished" in warning
    assert "ReactiveSequence 'guarded motion' ticks 'path is valid', which is RUNNING" in warning
    assert "declare it a condition (--nodes-model)" in warning
    model = DATA / "livelock_nodes_model.xml"
    fixed = btlog("run", livelock, "--nodes-model", model, "-o", tmp_path / "f.mcap")
    assert "final status: SUCCESS" in fixed.stdout and "' was halted" not in fixed.stderr


def test_a_leaf_halted_many_times_before_finishing(tmp_path: Path) -> None:
    """Halted again and again, then it finishes: 'before it finished'."""
    path = tmp_path / "t.xml"
    shutil.copy(DATA / "livelock.xml", path)
    outcomes = tmp_path / "o.yaml"
    # the check takes time for its first 150 activations, then answers at once
    outcomes.write_text(
        "nodes:\n  path is valid: "
        + json.dumps([{"status": "SUCCESS", "ticks": 2}] * 150 + [{"duration": 0}])
    )
    result = btlog("run", path, "--outcomes", outcomes, "-o", tmp_path / "t.mcap")
    assert "final status: SUCCESS" in result.stdout
    assert "'follow path' was halted 149 times before it finished" in result.stderr


def test_a_run_stopped_inside_an_endless_loop_says_what_would_end_it(tmp_path: Path) -> None:
    path = tmp_path / "loop.xml"
    path.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><KeepRunningUntilFailure name="patrol">'
        '<Sequence><Action ID="Patrol"/></Sequence></KeepRunningUntilFailure></BehaviorTree></root>'
    )
    result = btlog("run", path, "--max-ticks", "30", "-o", tmp_path / "loop.mcap")
    assert result.returncode == 0, result.stderr
    assert (
        "KeepRunningUntilFailure 'patrol' was still looping: it ends only when its child "
        "fails (script that result in the outcomes file to end the run)"
    ) in result.stderr
    outcomes = tmp_path / "o.yaml"
    outcomes.write_text("nodes: {Patrol: [SUCCESS, FAILURE]}")
    ended = btlog("run", path, "--outcomes", outcomes, "-o", tmp_path / "ended.mcap")
    assert "final status: FAILURE" in ended.stdout and "looping" not in ended.stderr

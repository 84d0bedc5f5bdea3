"""Bad values are refused with exit 2 and one line naming the option, file or value:
NaN and infinite seconds, outputs that would overwrite inputs, empty SQL, argparse
errors, port values BT.CPP refuses, and crafted recordings whose tree is not a tree."""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import pytest

from btlog.domains.outcomes import Outcomes
from btlog.record import Recorder
from btlog.runner import RunConfig
from btlog.tree.loader import load_tree_text
from btlog.tree.model import Node
from tests.cli_support import assert_bad_input, btlog
from tests.oracle.runner import have_behaviortreepy, run_oracle

SMALL = (
    '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence>'
    '<Action ID="Do" name="a"/><Action ID="Do" name="b"/></Sequence></BehaviorTree></root>'
)


@pytest.fixture
def small(tmp_path: Path) -> Path:
    """A two-action tree in its own folder."""
    path = tmp_path / "small.xml"
    path.write_text(SMALL)
    return path


@pytest.mark.parametrize(
    ("flag", "value"),
    [
        *[("--flush-interval", v) for v in ("nan", "inf", "-inf", "-1", "1e300")],
        *[("--tick-period", v) for v in ("nan", "inf", "-inf", "-1", "0", "1e300")],
    ],
)
def test_seconds_must_be_finite_and_positive(small: Path, flag: str, value: str) -> None:
    result = btlog("run", small.name, f"{flag}={value}", "-o", "r.mcap", cwd=small.parent)
    assert_bad_input(result, flag, "finite number of seconds")
    assert not (small.parent / "r.mcap").exists()


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf", "1.0e+300"])
def test_outcome_durations_must_be_finite(small: Path, value: str) -> None:
    outcomes = small.parent / "outcomes.yaml"
    outcomes.write_text(f"nodes:\n  a: {{status: SUCCESS, duration: {value}}}\n")
    result = btlog("run", small.name, "--outcomes", outcomes.name, cwd=small.parent)
    assert_bad_input(result, "outcomes.yaml:2", "duration", "must be a", "finite")


def test_outputs_never_overwrite_inputs(small: Path) -> None:
    folder = small.parent
    outcomes = folder / "outcomes.yaml"
    outcomes.write_text("default: {status: SUCCESS, duration: 0}\n")
    os.link(small, folder / "alias.xml")
    (folder / "inc.xml").write_text(
        '<root BTCPP_format="4" main_tree_to_execute="Main"><include path="small.xml"/>'
        '<BehaviorTree ID="Main"><SubTree ID="M"/></BehaviorTree></root>'
    )
    for tree, output in [
        ("small.xml", "small.xml"),
        ("small.xml", "./../" + folder.name + "/small.xml"),
        ("small.xml", "alias.xml"),
        ("small.xml", "outcomes.yaml"),
        ("inc.xml", "small.xml"),
    ]:
        args = ["run", tree, "--outcomes", "outcomes.yaml", "-o", output]
        result = btlog(*args, "--max-ticks", "5", cwd=folder)
        assert_bad_input(result, "-o", "that is an input")
    assert small.read_text() == SMALL
    assert btlog("run", "small.xml", "-o", "r.mcap", cwd=folder).returncode == 0
    assert_bad_input(btlog("recover", "r.mcap", "-o", "r.mcap", cwd=folder), "that is an input")
    assert_bad_input(btlog("show", "r.mcap", "--html", "r.mcap", cwd=folder), "--html")
    assert btlog("explain", "r.mcap", "--at", "end", cwd=folder).returncode == 0


@pytest.mark.parametrize("query", ["", "   ", "-- only a comment", ";"])
def test_sql_without_a_statement(small: Path, query: str) -> None:
    assert btlog("run", "small.xml", "-o", "r.mcap", cwd=small.parent).returncode == 0
    assert_bad_input(btlog("sql", "r.mcap", query, cwd=small.parent), "no statement")


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["run"], ["btlog run: error:", "TREE"]),
        (["run", "t.xml", "--max-ticks", "many"], ["--max-ticks", "'many'"]),
        (["frobnicate"], ["btlog: error:", "frobnicate"]),
        (["sql", "--format", "xml", "r.mcap", "q"], ["--format"]),
        (["ask", "r.mcap"], ["QUESTION"]),
    ],
)
def test_argument_errors_are_one_line(tmp_path: Path, args: list[str], words: list[str]) -> None:
    assert_bad_input(btlog(*args, cwd=tmp_path), *words)


BTCPP_REFUSES = [
    '<Delay delay_msec="-1"><AlwaysSuccess/></Delay>',
    '<Delay delay_msec="4294967296"><AlwaysSuccess/></Delay>',
    '<Repeat num_cycles="12345678901234567890123456"><AlwaysSuccess/></Repeat>',
    '<Repeat num_cycles="2147483648"><AlwaysSuccess/></Repeat>',
    '<RetryUntilSuccessful num_attempts="-2147483649"><AlwaysSuccess/></RetryUntilSuccessful>',
    '<Timeout msec="-1"><AlwaysSuccess/></Timeout>',
    '<Sleep msec="-5"/>',
]
BTCPP_ACCEPTS = [
    '<Delay delay_msec="0"><AlwaysSuccess/></Delay>',
    '<Timeout msec="4294967295"><AlwaysSuccess/></Timeout>',
    '<Repeat num_cycles="2147483647"><AlwaysFailure/></Repeat>',
    '<Repeat num_cycles="-2"><AlwaysSuccess/></Repeat>',
]


def _document(body: str) -> str:
    return f'<root BTCPP_format="4"><BehaviorTree ID="M">{body}</BehaviorTree></root>'


@pytest.mark.parametrize("body", BTCPP_REFUSES)
def test_port_values_btcpp_refuses(tmp_path: Path, body: str) -> None:
    (tmp_path / "ports.xml").write_text(_document(body))
    assert_bad_input(btlog("validate", "ports.xml", cwd=tmp_path), "ports.xml:1", "bad value")


@pytest.mark.skipif(not have_behaviortreepy(), reason="behaviortreepy missing")
@pytest.mark.parametrize("body", BTCPP_REFUSES + BTCPP_ACCEPTS)
def test_port_ranges_agree_with_btcpp(tmp_path: Path, body: str) -> None:
    theirs = run_oracle({"xml": _document(body), "max_ticks": 1})
    assert theirs is not None
    (tmp_path / "ports.xml").write_text(_document(body))
    ours = btlog("validate", "ports.xml", cwd=tmp_path)
    assert (theirs["error"] is not None) == (ours.returncode == 2), (theirs, ours.stderr)


def _crafted(folder: Path, case: str, metadata: dict[str, str] | None = None) -> Path:
    """A recording written by the real recorder from a tree changed after loading."""
    (folder / "small.xml").write_text(SMALL)
    tree = load_tree_text(SMALL)
    first, second = tree.root.children
    if case == "duplicate uid":
        second.uid = first.uid
    elif case == "unknown parent":
        second.parent = load_tree_text(SMALL).root.children[0]
        second.parent.uid = 99
    elif case == "deep":
        node = second
        for uid in range(100, 350):
            child = Node(uid=uid, type="Inverter", name="", kind="decorator", parent=node)
            node.children.append(child)
            node = child
    elif case == "two roots":
        second.parent = None  # still described under the root, but recorded parentless
    config = RunConfig(tree=str(folder / "small.xml"))
    recorded = {**config.to_metadata(tree, uuid.uuid4().hex[:12], Outcomes()), **(metadata or {})}
    path = folder / f"{case.replace(' ', '-')}.mcap"
    Recorder(path, tree, recorded).close()
    return path


@pytest.mark.parametrize(
    ("case", "words"),
    [
        ("duplicate uid", ["uid 2 is used by two nodes"]),
        ("unknown parent", ["parent uid 99 is unknown"]),
        ("two roots", ["2 nodes have no parent"]),
    ],
)
def test_crafted_trees_are_refused(tmp_path: Path, case: str, words: list[str]) -> None:
    path = _crafted(tmp_path, case)
    for command in (["explain", "--at", "end"], ["check", "--rerun"]):
        name, *rest = command
        result = btlog(name, path.name, *rest, cwd=tmp_path)
        assert_bad_input(result, path.name, "/btlog/tree", *words)


def test_recorded_nan_tick_period_is_refused_on_rerun(tmp_path: Path) -> None:
    path = _crafted(tmp_path, "sound", {"tick_period": "nan"})
    result = btlog("check", path.name, "--rerun", cwd=tmp_path)
    assert_bad_input(result, "--tick-period", "nan")


def test_crafted_deep_tree_is_refused(tmp_path: Path) -> None:
    path = _crafted(tmp_path, "deep")
    result = btlog("explain", path.name, "--at", "end", cwd=tmp_path)
    assert_bad_input(result, path.name, "/btlog/tree", "deeper than 200 levels")


@pytest.mark.parametrize(
    "when", ["tick:99999999999999999999999", "seq:9223372036854775808", "99999999999999999999s"]
)
def test_moments_past_64_bits_are_refused_before_running(small: Path, when: str) -> None:
    args = ["--ask", f"{when}=What are you doing?", "-o", "r.mcap"]
    result = btlog("run", small.name, *args, cwd=small.parent)
    assert_bad_input(result, when, "out of range")
    assert not (small.parent / "r.mcap").exists()

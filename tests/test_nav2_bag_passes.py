"""``btlog import`` of a Nav2 bag reads it in passes instead of holding its log (#27):
what it imports is what it imported when it held every entry (the figures below were
pinned from that version), and its memory does not grow with the log."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import pytest
from mcap_ros2.writer import Writer

from btlog.record.reader import open_recording
from btlog.runner import RunConfig, execute
from btlog.sinks.nav2_rosbag import LOG_MSGDEF
from btlog.sources.nav2_rosbag import import_bag
from tests.cli_support import btlog
from tests.rosbag2_support import NAV2_LOG
from tests.test_nav2_rosbag import NO_UID_MSGDEF, TREE, nav2_messages, record, write_nav2_bag

OMITTED = (
    "changes the log leaves out were added, each at the time of the entry whose previous "
    "status shows it (resets to IDLE, when Nav2 runs with bt_log_idle_transitions false)"
)
INCOMPLETE = (
    "the bag ends before this goal's result: Nav2 publishes /behavior_tree_log only while "
    "the tree is RUNNING, so the goal's last transitions are missing (not invented)"
)
MID_RUN = (
    "the log begins mid-run (the recorder started after the goal did): the state at its "
    "first entry is inferred (each node's previous status in its first entry, RUNNING for "
    "their other ancestors) and recorded as the first tick"
)
NEVER_NAMED = (
    "'ComputePathToPose': never in the log while nodes under it run, so RUNNING from the "
    "first entry on (the recorder started after it did, or --tree has nodes the run's tree "
    "did not)"
)
#: per way of matching: the warnings, and each goal's transitions and metadata notes
PINNED = {
    True: (
        [
            f"goal 1: {MID_RUN} (3 nodes not IDLE)",
            f"goal 1: 26 {OMITTED}",
            f"goal 2: 2 {OMITTED}",
            f"goal 2: {INCOMPLETE}",
            f"goal 4: 42 {OMITTED}",
            f"goal 4: {INCOMPLETE}",
        ],
        [
            (93, {"mid_run": MID_RUN, "omitted": f"26 {OMITTED}"}),
            (34, {"incomplete": INCOMPLETE, "omitted": f"2 {OMITTED}"}),
            (1, {}),
            (137, {"incomplete": INCOMPLETE, "omitted": f"42 {OMITTED}"}),
        ],
    ),
    False: (
        [
            f"goal 1: {MID_RUN} (3 nodes not IDLE)",
            f"goal 1: 27 {OMITTED}",
            f"goal 2: 2 {OMITTED}",
            f"goal 2: {INCOMPLETE}",
            f"goal 4: {NEVER_NAMED} (1 nodes not IDLE)",
            f"goal 4: 43 {OMITTED}",
            f"goal 4: {INCOMPLETE}",
        ],
        [
            (94, {"mid_run": MID_RUN, "omitted": f"27 {OMITTED}"}),
            (34, {"incomplete": INCOMPLETE, "omitted": f"2 {OMITTED}"}),
            (1, {}),
            (
                139,
                {"incomplete": INCOMPLETE, "mid_run": NEVER_NAMED, "omitted": f"43 {OMITTED}"},
            ),
        ],
    ),
}


def cut_bag(tmp_path: Path, uids: bool) -> Path:
    """Three goals as Nav2 logs them, the recorder started three messages late and
    ``bt_log_idle_transitions`` false (no change to IDLE logged)."""
    runs = [
        record(tmp_path, "a"),
        record(tmp_path, "b", outcomes={"nodes": {"FollowPath": "SUCCESS"}}),
        record(tmp_path, "c"),
    ]
    path = tmp_path / ("uids.mcap" if uids else "names.mcap")
    with open(path, "wb") as stream:
        writer = Writer(stream)
        schema = writer.register_msgdef(NAV2_LOG, LOG_MSGDEF if uids else NO_UID_MSGDEF)
        for topic, _type, sent, message in nav2_messages(runs, uids)[3:]:
            kept = [e for e in message["event_log"] if e["current_status"] != "IDLE"]
            if kept:
                writer.write_message(topic, schema, {**message, "event_log": kept}, sent)
        writer.finish()
    return path


@pytest.mark.parametrize("uids", [True, False], ids=["uids", "shared-names"])
def test_a_multi_goal_bag_imports_as_when_it_was_held(tmp_path: Path, uids: bool) -> None:
    bag = cut_bag(tmp_path, uids)
    out = tmp_path / "g.mcap"
    result = btlog("import", str(bag), "--tree", str(TREE), "-o", str(out))
    assert result.returncode == 0, result.stderr
    warnings, goals = PINNED[uids]
    assert result.stderr.splitlines() == [f"btlog import: warning: {w}" for w in warnings]
    for index, (count, notes) in enumerate(goals, 1):
        recording = open_recording(tmp_path / f"g-goal{index}.mcap")
        assert len(recording.transitions) == count
        kept = ("incomplete", "mid_run", "omitted")
        assert {k: v for k, v in recording.metadata.items() if k in kept} == notes
        source = recording.metadata["source"]
        source = json.loads(source) if isinstance(source, str) else source
        assert (source["messages"], source["goal"], source["goals"]) == (32, index, 4)
        assert source["matched_by"] == ("uid" if uids else "name")
    # one goal alone is the same recording as in the import of all of them
    alone = tmp_path / "alone.mcap"
    result = btlog("import", str(bag), "--tree", str(TREE), "--goal", "2", "-o", str(alone))
    assert result.returncode == 0, result.stderr
    both = open_recording(alone), open_recording(tmp_path / "g-goal2.mcap")
    assert both[0].transitions == both[1].transitions


def long_bag(tmp_path: Path, ticks: int) -> Path:
    """A bag of one long goal: 10 actions under a Parallel, repeated ``ticks`` times."""
    children = "".join(f'<Action ID="Work" name="a{i}"/>' for i in range(10))
    tree = tmp_path / "tree.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="MainTree"><Repeat num_cycles="-1">'
        f'<Parallel success_count="-1" failure_count="1">{children}</Parallel>'
        "</Repeat></BehaviorTree></root>"
    )
    config = RunConfig(
        str(tree), outcomes={"default": {"status": "SUCCESS", "ticks": 1}}, max_ticks=ticks
    )
    run = open_recording(execute(config, tmp_path / f"run{ticks}.mcap").path)
    bag = tmp_path / f"bag{ticks}.mcap"
    write_nav2_bag(bag, [run], chunk_size=1 << 16)  # the chunks read are as large in both
    return bag


def peak_import(bag: Path, out: Path) -> int:
    """The peak of Python's allocations while ``bag`` is imported."""
    tracemalloc.start()
    try:
        (result,) = import_bag(bag, out, bag.parent / "tree.xml")
        _now, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert result.transitions > 0
    return peak


def test_importing_a_longer_bag_takes_no_more_memory(tmp_path: Path) -> None:
    short, long = long_bag(tmp_path, 400), long_bag(tmp_path, 1600)
    peaks = [peak_import(bag, tmp_path / f"out-{bag.stem}.mcap") for bag in (short, long)]
    transitions = [
        len(open_recording(tmp_path / f"out-{b.stem}.mcap").transitions) for b in (short, long)
    ]
    assert transitions[1] > 3.5 * transitions[0]
    # holding the log's ~36,000 more entries took > 3 MB more; reading it in passes, < 0.3 MB
    assert peaks[1] - peaks[0] < 300_000, peaks

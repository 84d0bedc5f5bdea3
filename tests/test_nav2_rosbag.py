"""Nav2 bags in and out: ``btlog import BAG.mcap --tree …`` and ``btlog export --to nav2``.

The bags are real ROS 2 MCAP files written with ``mcap-ros2-support`` the way Nav2's
``RosTopicLogger`` publishes: the status changes of each tick are buffered and flushed
only after a tick that left the tree RUNNING, so a goal's last tick reaches the bag with
the next goal's first message, or never when the bag ends first.
"""

from __future__ import annotations

import json
from pathlib import Path

from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer

from btlog.executor.behavior import NodeExecutionError
from btlog.record.reader import Recording, open_recording
from btlog.record.recorder import start_time_ns
from btlog.runner import RunConfig, execute
from btlog.sinks.nav2_rosbag import LOG_MSGDEF, export_nav2
from btlog.sources.nav2_rosbag import import_bag
from btlog.status import RUNNING
from tests.cli_support import ROOT, assert_bad_input, btlog
from tests.oracle.random_trees import generate
from tests.rosbag2_support import HUMBLE, NAV2_LOG, Message, write_sqlite_bag

NAV2 = ROOT / "trees" / "nav2"
TREE = NAV2 / "navigate_to_pose.xml"
FAILS_ONCE = NAV2 / "follow-path-fails-once.yaml"
#: BehaviorTreeStatusChange before Nav2 added the uid field (Humble, Iron).
NO_UID_MSGDEF = HUMBLE


def record(tmp_path: Path, name: str, tree: Path = TREE, **outcomes: object) -> Recording:
    """A btlog run of ``tree`` with the outcomes file or mapping given."""
    config = RunConfig(str(tree), outcomes_file=str(FAILS_ONCE), **outcomes)  # type: ignore[arg-type]
    return open_recording(execute(config, tmp_path / f"{name}.mcap").path)


def nav2_messages(runs: list[Recording], uids: bool = True) -> list[Message]:
    """What Nav2 would have published for these runs, one goal each, 100 s apart, as
    ``(topic, type, log time, message)``."""
    buffer: list[dict] = []
    messages: list[Message] = []
    for index, run in enumerate(runs):
        start = start_time_ns(run.metadata["started_at"])
        offset = index * 100_000_000_000
        names = {n.uid: n.description for n in run.tree}  # BT.CPP's name()
        by_tick: dict[int, list] = {}
        for change in run.transitions:
            by_tick.setdefault(change.tick, []).append(change)
        for tick in run.ticks:
            for change in by_tick.get(tick.tick, []):
                t = start + offset + change.t_ns
                entry = {
                    "timestamp": {"sec": t // 10**9, "nanosec": t % 10**9},
                    "node_name": names[change.uid],
                    "previous_status": change.prev.name,
                    "current_status": change.status.name,
                }
                if uids:
                    entry["uid"] = change.uid
                buffer.append(entry)
            if tick.root_status is RUNNING and buffer:
                sent = start + offset + tick.end_ns
                message = {"timestamp": {"sec": sent // 10**9, "nanosec": 0}, "event_log": buffer}
                messages.append(("/behavior_tree_log", NAV2_LOG, sent, message))
                buffer = []
    return messages


def write_nav2_bag(
    path: Path, runs: list[Recording], uids: bool = True, chunk_size: int = 1 << 20
) -> None:
    """The MCAP file ``path`` of what Nav2 would have published for these runs."""
    with open(path, "wb") as stream:
        writer = Writer(stream, chunk_size=chunk_size)
        schema = writer.register_msgdef(NAV2_LOG, LOG_MSGDEF if uids else NO_UID_MSGDEF)
        for topic, _type, sent, message in nav2_messages(runs, uids):
            writer.write_message(topic, schema, message, sent)
        writer.finish()


def transitions(recording: Recording) -> list[tuple]:
    """(t_ns, uid, prev, status) of every status change."""
    return [(e.t_ns, e.uid, e.prev, e.status) for e in recording.transitions]


def test_export_decodes_with_mcap_ros2(tmp_path: Path) -> None:
    run = record(tmp_path, "run")
    out = tmp_path / "bag.mcap"
    result = btlog("export", str(run.path), "--to", "nav2", str(out))
    assert result.returncode == 0, result.stderr
    with open(out, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        messages = list(reader.iter_decoded_messages())
    xml = [m for m in messages if m.channel.topic == "/behavior_tree_xml"]
    logs = [m for m in messages if m.channel.topic == "/behavior_tree_log"]
    assert [m.schema.name for m in xml] == ["std_msgs/msg/String"]
    assert 'BTCPP_format="4"' in xml[0].decoded_message.data
    assert '_uid="25"' in xml[0].decoded_message.data
    assert {m.schema.name for m in logs} == {"nav2_msgs/msg/BehaviorTreeLog"}
    assert {m.channel.message_encoding for m in logs} == {"cdr"}
    ticks_with_changes = {e.tick for e in run.transitions}
    assert len(logs) == len(ticks_with_changes)  # one message per tick with status changes
    start = start_time_ns(run.metadata["started_at"])
    decoded = [
        (e.timestamp.sec * 10**9 + e.timestamp.nanosec - start, e.uid, e.node_name)
        for m in logs
        for e in m.decoded_message.event_log
    ]
    names = {n.uid: n.name or n.type for n in run.tree}  # BT.CPP's name(): else the ID
    assert decoded == [(e.t_ns, e.uid, names[e.uid]) for e in run.transitions]
    assert all(m.message.log_time >= start for m in logs)
    first = logs[0].decoded_message.event_log[0]
    assert (first.previous_status, first.current_status) == ("IDLE", "RUNNING")


NAMELESS = """<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence>
  <AlwaysSuccess/><Fallback name="try"><AlwaysFailure/><AlwaysSuccess/></Fallback>
</Sequence></BehaviorTree></root>"""


def test_export_names_nameless_nodes_by_their_id_as_btcpp_does(tmp_path: Path) -> None:
    (tmp_path / "t.xml").write_text(NAMELESS, encoding="utf-8")
    assert btlog("run", "t.xml", "-o", "t.mcap", "--quiet", cwd=tmp_path).returncode == 0
    bag = tmp_path / "bag.mcap"
    assert btlog("export", "t.mcap", "--to", "nav2", str(bag), cwd=tmp_path).returncode == 0
    with open(bag, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        names = {
            (e.uid, e.node_name)
            for m in reader.iter_decoded_messages(topics=["/behavior_tree_log"])
            for e in m.decoded_message.event_log
        }
    assert names == {(1, "Sequence"), (2, "AlwaysSuccess"), (3, "try"), (4, "AlwaysFailure"),
                     (5, "AlwaysSuccess")}  # fmt: skip
    back = btlog("import", str(bag), "--tree", "t.xml", "-o", "back.mcap", cwd=tmp_path)
    assert back.returncode == 0, back.stderr
    assert transitions(open_recording(tmp_path / "back.mcap")) == transitions(
        open_recording(tmp_path / "t.mcap")
    )


def test_export_then_import_gives_the_same_transitions(tmp_path: Path) -> None:
    run = record(tmp_path, "run")
    bag = tmp_path / "bag.mcap"
    assert btlog("export", str(run.path), "--to", "nav2", str(bag)).returncode == 0
    back = tmp_path / "back.mcap"
    result = btlog("import", str(bag), "--tree", str(TREE), "-o", str(back))
    assert result.returncode == 0, result.stderr
    imported = open_recording(back)
    assert transitions(imported) == transitions(run)
    assert imported.metadata["started_at"] == run.metadata["started_at"]
    source = imported.metadata["source"]
    source = json.loads(source) if isinstance(source, str) else source
    assert source["matched_by"] == "uid" and source["format"] == "nav2-rosbag2"


def test_a_nav2_bag_imports_one_recording_per_goal(tmp_path: Path) -> None:
    first = record(tmp_path, "first")
    second = record(tmp_path, "second", outcomes={"nodes": {"FollowPath": "SUCCESS"}})
    bag = tmp_path / "nav2.mcap"
    write_nav2_bag(bag, [first, second])
    out = tmp_path / "goals.mcap"
    result = btlog("import", str(bag), "--tree", str(TREE), "-o", str(out))
    assert result.returncode == 0, result.stderr
    goal1, goal2 = tmp_path / "goals-goal1.mcap", tmp_path / "goals-goal2.mcap"
    # goal 1's last tick came with goal 2's first message: it is complete
    assert transitions(open_recording(goal1)) == transitions(first)
    # goal 2's last tick never reached the bag: imported without it, and said so
    assert "goal 2: the bag ends before this goal's result" in result.stderr
    incomplete = open_recording(goal2)
    assert transitions(incomplete) == transitions(second)[: len(incomplete.transitions)]
    assert len(incomplete.transitions) < len(second.transitions)
    assert "Nav2 publishes /behavior_tree_log only while" in incomplete.metadata["incomplete"]
    assert "incomplete" not in open_recording(goal1).metadata
    explained = btlog("explain", str(goal1), "--at", "2.2s")
    assert "I could not follow path because follow path failed." in explained.stdout
    assert "Note:" not in explained.stdout
    explained = btlog("explain", str(goal2), "--at", "end")
    assert "Note: the bag ends before this goal's result" in explained.stdout


NAMED = (
    '<root BTCPP_format="4"><BehaviorTree ID="Nav">'
    '<RecoveryNode name="navigate" number_of_retries="2">'
    '<PipelineSequence name="plan and follow"><RateController hz="2">'
    '<Action ID="ComputePathToPose" name="plan"/></RateController>'
    '<Action ID="FollowPath" name="follow"/></PipelineSequence>'
    '<Action ID="ClearEntireCostmap" name="clear"/></RecoveryNode>'
    "</BehaviorTree></root>"
)


def test_goal_option_and_name_matching_without_uids(tmp_path: Path) -> None:
    tree = tmp_path / "named.xml"
    tree.write_text(NAMED)
    outcomes = {"nodes": {"follow": [{"status": "FAILURE", "duration": 1}, "SUCCESS"]}}
    runs = [record(tmp_path, f"r{i}", tree, outcomes=outcomes) for i in range(3)]
    bag = tmp_path / "humble.mcap"
    write_nav2_bag(bag, runs, uids=False)
    out = tmp_path / "second.mcap"
    result = btlog("import", str(bag), "--tree", str(tree), "--goal", "2", "-o", str(out))
    assert result.returncode == 0, result.stderr
    imported = open_recording(out)
    assert transitions(imported) == transitions(runs[1])
    source = imported.metadata["source"]
    source = json.loads(source) if isinstance(source, str) else source
    assert (source["matched_by"], source["goal"], source["goals"]) == ("name", 2, 3)
    assert_bad_input(
        btlog("import", str(bag), "--tree", str(tree), "--goal", "4", "-o", str(out)),
        "--goal 4",
        "3 goals",
    )


def test_a_humble_sqlite_bag_imports_as_a_folder_or_a_db3(tmp_path: Path) -> None:
    """ROS 2 Humble's default storage: a folder with metadata.yaml and a .db3 holding no
    message definitions; the .db3 alone is not taken for a BT.CPP SqliteLogger file."""
    tree = tmp_path / "named.xml"
    tree.write_text(NAMED)
    outcomes = {"nodes": {"follow": [{"status": "FAILURE", "duration": 1}, "SUCCESS"]}}
    runs = [record(tmp_path, f"r{i}", tree, outcomes=outcomes) for i in range(2)]
    (db3,) = write_sqlite_bag(tmp_path / "bag", nav2_messages(runs, uids=False), {NAV2_LOG: HUMBLE})
    for bag in (tmp_path / "bag", db3):
        out = tmp_path / f"{bag.name}.mcap"
        result = btlog("import", str(bag), "--tree", str(tree), "-o", str(out))
        assert result.returncode == 0, result.stderr
        first = open_recording(tmp_path / f"{bag.name}-goal1.mcap")
        assert transitions(first) == transitions(runs[0])
        source = first.metadata["source"]
        source = json.loads(source) if isinstance(source, str) else source
        assert source["definition"] == "eloquent-foxy-galactic-humble-iron"
        assert source["matched_by"] == "name"


def test_bad_bags_exit_2_with_one_line(tmp_path: Path) -> None:
    chatter = tmp_path / "chatter.mcap"
    with open(chatter, "wb") as stream:
        writer = Writer(stream)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        writer.write_message("/chatter", schema, {"data": "hi"}, 1)
        writer.write_message("/behavior_tree_xml", schema, {"data": "<root/>"}, 1)
        writer.finish()
    assert_bad_input(btlog("import", str(chatter), "--tree", str(TREE)), "no /behavior_tree_log")
    wrong = tmp_path / "wrong.mcap"
    with open(wrong, "wb") as stream:
        writer = Writer(stream)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data\n")
        writer.write_message("/behavior_tree_log", schema, {"data": "hi"}, 1)
        writer.finish()
    assert_bad_input(
        btlog("import", str(wrong), "--tree", str(TREE)), "std_msgs/msg/String", "expected"
    )
    run = record(tmp_path, "run")
    bag = tmp_path / "nav2.mcap"
    write_nav2_bag(bag, [run])
    other = NAV2 / "navigate_through_poses.xml"
    assert_bad_input(btlog("import", str(bag), "--tree", str(other)), "not the tree that ran")
    assert_bad_input(btlog("import", str(bag)), "holds no tree", "--tree")


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 10_000))
def test_random_trees_round_trip_through_a_nav2_bag(tmp_path_factory, seed: int) -> None:
    """Any run exported as a Nav2 bag imports back (tree from the bag's XML) to the same
    transitions at the same absolute times."""
    case = generate(seed)
    folder = tmp_path_factory.mktemp("roundtrip")
    tree = folder / "tree.xml"
    tree.write_text(case.xml)
    config = RunConfig(str(tree), outcomes=case.outcomes, max_ticks=case.max_ticks)
    try:
        recorded = execute(config, folder / "run.mcap")
    except NodeExecutionError:  # a tree BT.CPP refuses too (e.g. a skipped condition)
        assume(False)
    run = open_recording(recorded.path)
    assume(run.transitions)
    export_nav2(run, folder / "bag.mcap")
    (result,) = import_bag(folder / "bag.mcap", folder / "back.mcap")
    back = open_recording(result.path)

    def absolute(recording: Recording) -> list[tuple]:
        start = start_time_ns(recording.metadata["started_at"])
        return [(start + t, uid, prev, new) for t, uid, prev, new in transitions(recording)]

    assert absolute(back) == absolute(run)
    assert [n.describe()["type"] for n in back.tree] == [n.describe()["type"] for n in run.tree]


def test_a_bag_cut_short_is_read_up_to_the_cut(tmp_path: Path) -> None:
    """A recorder killed mid-run leaves no summary and a torn last chunk: the whole
    messages before the cut are imported, with warnings; a bag cut inside its first
    record is refused."""
    run = record(tmp_path, "run")
    bag = tmp_path / "full.mcap"
    write_nav2_bag(bag, [run], chunk_size=1024)
    data = bag.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 6 // 10])
    out = tmp_path / "out.mcap"
    result = btlog("import", str(cut), "--tree", str(TREE), "-o", str(out))
    assert result.returncode == 0, result.stderr
    assert "the bag ends inside a record" in result.stderr
    imported = transitions(open_recording(out))
    assert 0 < len(imported) < len(run.transitions)
    assert imported == transitions(run)[: len(imported)]
    cut.write_bytes(data[:40])
    assert_bad_input(btlog("import", str(cut), "--tree", str(TREE)), "not a readable")

"""The one reader of ROS 2 bags (``btlog.sources.rosbag2``): MCAP and SQLite storage, a
folder or one file, splits, compression, the definitions of old SQLite bags chosen by
reading the messages exactly, and damage read around with a warning.

The bags are written as ROS 2 writes them (``tests/rosbag2_support.py``)."""

from __future__ import annotations

from pathlib import Path

import pytest
import zstandard

from btlog.sources import detect
from btlog.sources.builder import SourceError
from btlog.sources.rosbag2 import Definition, open_bag, shipped_definitions
from tests.rosbag2_support import HUMBLE, JAZZY, NAV2_LOG, write_mcap_bag, write_sqlite_bag

STRING = "std_msgs/msg/String"
LOG = "/behavior_tree_log"
DEFINITIONS = {NAV2_LOG: HUMBLE, STRING: "string data\n", "acme_msgs/msg/Secret": "string data\n"}
T0 = 1_700_000_000_000_000_000


def log_message(i: int, uid: bool) -> tuple:
    """A ``/behavior_tree_log`` message with one entry (none for i = 0: such a message
    reads the same in every layout)."""
    entry = {
        "timestamp": {"sec": 1_700_000_000 + i, "nanosec": 5},
        "node_name": f"node {i}",
        "previous_status": "IDLE",
        "current_status": "RUNNING",
    }
    if uid:
        entry["uid"] = i
    fields = {"timestamp": {"sec": 1, "nanosec": 2}, "event_log": [entry] if i else []}
    return (LOG, NAV2_LOG, T0 + i, fields)


def names(bag_path: Path | str, topics: set[str] | None = None) -> list[tuple]:
    """(topic, log time, what the message says) of each message, read back."""
    with open_bag(bag_path) as bag:
        return [
            (m.topic, m.log_time_ns, [e.node_name for e in m.decoded.event_log])
            if m.topic == LOG
            else (m.topic, m.log_time_ns, m.decoded.data)
            for m in bag.messages(topics)
        ]


def expected(messages: list[tuple]) -> list[tuple]:
    return [
        (topic, t, [e["node_name"] for e in fields["event_log"]])
        if topic == LOG
        else (topic, t, fields["data"])
        for topic, _type, t, fields in messages
    ]


def test_a_humble_sqlite_bag_decodes_with_the_shipped_definition(tmp_path: Path) -> None:
    messages = [log_message(i, uid=False) for i in range(30)]
    messages.insert(7, ("/chatter", STRING, T0 + 7, {"data": "hello"}))
    secret = ("/secret", "acme_msgs/msg/Secret", T0 + 40, {"data": "x"})
    files = write_sqlite_bag(tmp_path / "humble", [*messages, secret], DEFINITIONS, files=2)
    assert detect(tmp_path / "humble") == "rosbag2" == detect(files[0])
    with open_bag(tmp_path / "humble") as bag:
        assert (bag.storage, bag.files) == ("sqlite3", [str(f) for f in files])
        assert set(bag.topics) == {LOG, "/chatter", "/secret"}
        assert bag.topics[LOG].type == NAV2_LOG
        read = list(bag.messages())
        assert bag.used[LOG].origin == "eloquent-foxy-galactic-humble-iron"
        assert bag.used["/chatter"].origin == "all"
        # a type btlog knows no definition of is skipped, and said so
        (warning,) = bag.warnings
        assert "acme_msgs/msg/Secret (/secret)" in warning and "skipped" in warning
    assert [(m.topic, m.log_time_ns) for m in read] == [(m[0], m[2]) for m in messages]
    assert names(tmp_path / "humble") == expected(messages)
    # the first file alone, a .db3 by itself
    assert names(files[0], {LOG}) == expected([m for m in messages[:16] if m[0] == LOG])
    with pytest.raises(SourceError, match="holds no definition of acme_msgs/msg/Secret"):
        names(tmp_path / "humble", {"/secret"})


def test_the_layout_is_the_one_that_reads_the_messages_exactly(tmp_path: Path) -> None:
    """Nav2 Jazzy logs uids: a SQLite bag without definitions is read with that layout,
    although its messages also decode (into garbage) with Humble's."""
    messages = [log_message(i, uid=True) for i in range(5)]
    write_sqlite_bag(tmp_path / "jazzy-no-defs", messages, {NAV2_LOG: JAZZY})
    with open_bag(tmp_path / "jazzy-no-defs") as bag:
        read = [m.decoded for m in bag.messages({LOG})]
        assert bag.used[LOG].origin == "jazzy-kilted-lyrical-rolling"
    assert [[e.uid for e in m.event_log] for m in read] == [[], [1], [2], [3], [4]]
    assert [e.previous_status for m in read for e in m.event_log] == ["IDLE"] * 4


def test_a_jazzy_sqlite_bag_uses_its_own_definitions(tmp_path: Path) -> None:
    messages = [log_message(i, uid=True) for i in range(5)]
    write_sqlite_bag(tmp_path / "jazzy", messages, {NAV2_LOG: JAZZY}, jazzy=True)
    with open_bag(tmp_path / "jazzy") as bag:
        assert names(tmp_path / "jazzy") == expected(messages)
        list(bag.messages())
        assert bag.used[LOG] == Definition(NAV2_LOG, JAZZY, "bag")


def test_a_definition_of_the_callers_own(tmp_path: Path) -> None:
    write_sqlite_bag(tmp_path / "b", [("/secret", "acme_msgs/msg/Secret", 5, {"data": "x"})],
                     DEFINITIONS)  # fmt: skip
    mine = Definition("acme_msgs/msg/Secret", "string data\n", "acme 1.0")
    with open_bag(tmp_path / "b", extra=[mine]) as bag:
        assert [m.decoded.data for m in bag.messages()] == ["x"]
        assert bag.used["/secret"] == mine


def test_compressed_bags(tmp_path: Path) -> None:
    """rosbag2's compression: each message a zstd frame, or each file a .zstd."""
    messages = [log_message(i, uid=False) for i in range(10)]
    write_sqlite_bag(tmp_path / "per-message", messages, DEFINITIONS, compress_messages=True)
    assert names(tmp_path / "per-message") == expected(messages)
    (db3,) = write_sqlite_bag(tmp_path / "per-file", messages, DEFINITIONS)
    packed = Path(f"{db3}.zstd")
    packed.write_bytes(zstandard.ZstdCompressor().compress(db3.read_bytes()))
    db3.unlink()
    with open_bag(tmp_path / "per-file") as bag:
        assert bag.files == [str(packed)]
        assert len(list(bag.messages())) == 10
        (unpacked,) = bag._temporary.values()
        assert Path(unpacked).exists()
    assert not Path(unpacked).exists()  # closing the bag removes the copy
    bomb = tmp_path / "bomb" / "bomb_0.db3.zstd"
    bomb.parent.mkdir()
    bomb.write_bytes(zstandard.ZstdCompressor().compress(bytes(100 << 20)))
    with open_bag(bomb.parent) as bag, pytest.raises(SourceError, match="decompresses to more"):
        list(bag.messages())
    assert not bag._temporary


def test_mcap_splits_and_a_folder_without_metadata(tmp_path: Path) -> None:
    messages = [log_message(i, uid=True) for i in range(24)]
    files = write_mcap_bag(tmp_path / "mcap", messages, {NAV2_LOG: JAZZY}, files=12)
    assert names(tmp_path / "mcap") == expected(messages)
    # the recorder was killed before writing metadata.yaml: files by split number (_2 < _10)
    (tmp_path / "mcap" / "metadata.yaml").unlink()
    with open_bag(tmp_path / "mcap") as bag:
        assert bag.files == [str(f) for f in files]
    assert names(tmp_path / "mcap") == expected(messages)
    files[3].unlink()
    assert names(tmp_path / "mcap") == expected(messages[:6] + messages[8:])


def test_a_file_the_metadata_lists_but_is_gone(tmp_path: Path) -> None:
    messages = [log_message(i, uid=False) for i in range(1, 9)]
    files = write_sqlite_bag(tmp_path / "b", messages, DEFINITIONS, files=2)
    files[0].unlink()
    with open_bag(tmp_path / "b") as bag:
        assert len(list(bag.messages())) == 4
        (warning,) = bag.warnings
        assert f"the bag's file {files[0]} is missing" in warning
    files[1].unlink()
    with pytest.raises(SourceError, match="none of the bag's files"):
        open_bag(tmp_path / "b")


def test_a_damaged_mcap_chunk_is_skipped_with_its_offset(tmp_path: Path) -> None:
    """Issue #24: one flipped byte in a chunk of a Nav2 bag (zstd-compressed) gave a
    ZstdError and exit 3; the other chunks are read, with a warning naming the offset."""
    messages = [log_message(i, uid=True) for i in range(1, 200)]
    (bag_file,) = write_mcap_bag(tmp_path / "b", messages, {NAV2_LOG: JAZZY}, chunk_size=2048)
    data = bytearray(bag_file.read_bytes())
    middle = len(data) // 2
    data[middle] ^= 0xFF
    bag_file.write_bytes(bytes(data))
    with open_bag(bag_file) as bag:
        read = [(m.log_time_ns, m.decoded.event_log[0].node_name) for m in bag.messages({LOG})]
        (warning,) = bag.warnings
    assert "damaged data at byte" in warning and str(bag_file) in warning
    offset = int(warning.split("at byte ")[1].split()[0])
    assert offset < middle
    originals = {(t, f["event_log"][0]["node_name"]) for _topic, _type, t, f in messages}
    assert 100 < len(read) < len(messages) and set(read) <= originals
    assert read == sorted(read)


def test_what_is_not_a_bag(tmp_path: Path) -> None:
    folder = tmp_path / "empty"
    folder.mkdir()
    with pytest.raises(SourceError, match=r"no metadata\.yaml, \.mcap or \.db3"):
        open_bag(folder)
    info = "rosbag2_bagfile_information: {relative_file_paths: [../x.db3]}"
    (folder / "metadata.yaml").write_text(info)
    with pytest.raises(SourceError, match="outside the bag folder"):
        open_bag(folder)
    (folder / "metadata.yaml").write_text("[1, 2")
    with pytest.raises(SourceError, match=r"metadata\.yaml:1: not valid YAML"):
        open_bag(folder)
    other = tmp_path / "other.db3"
    other.write_bytes(b"SQLite format 3\x00" + bytes(100))
    with pytest.raises(SourceError, match=r"other\.db3"):
        list(open_bag(other).messages())


def test_shipped_definitions_are_those_of_nav2_releases() -> None:
    """btlog's definitions of Nav2's log are Nav2's own .msg files, for each layout."""
    layouts = {d.origin: d.text for d in shipped_definitions(NAV2_LOG)}
    assert set(layouts) == {"jazzy-kilted-lyrical-rolling", "eloquent-foxy-galactic-humble-iron"}
    assert "uint16 uid" in layouts["jazzy-kilted-lyrical-rolling"]
    assert "uid" not in layouts["eloquent-foxy-galactic-humble-iron"]
    assert shipped_definitions("../../etc/passwd") == shipped_definitions("no/msg/Such") == []

"""``btlog recover`` on damage the reader alone cannot get around: the tree's chunk lost
(the tree is rebuilt from its XML attachment), chunks written twice (dropped, and
counted), chunks out of order (saved in seq order), nothing recoverable (exit 2 in one
line). Whatever it writes, ``btlog explain`` reads."""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.errors import EXIT_BAD_INPUT
from btlog.events import EventLog
from btlog.executor.engine import Executor
from btlog.record import Recorder, iter_messages, open_recording
from btlog.record import format as fmt
from btlog.tree.loader import load_tree_text
from tests.cli_support import btlog
from tests.test_chunk_order import reordered, shuffled_order
from tests.test_damage import LOOP, chunks


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, EventLog]:
    """A looping run in many small chunks, its tree file attached as ``btlog run`` does."""
    path = tmp_path_factory.mktemp("recover") / "run.mcap"
    tree = load_tree_text(LOOP)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    log = EventLog()
    recorder = Recorder(
        path,
        tree,
        {"domain": "loop", "tree_file": "trees/loop.xml"},
        [("loop.xml", LOOP.encode())],
        flush_interval=3600,
        chunk_size=1024,
        group_events=50,
    )
    executor.subscribe(log)
    executor.subscribe(recorder)
    executor.run(max_ticks=300)
    executor.close()
    assert len(chunks(path.read_bytes())) >= 10
    return path, log


def recovered(broken: Path, tmp_path: Path) -> tuple[Path, str]:
    fixed = tmp_path / "fixed.mcap"
    done = btlog("recover", broken, "-o", fixed)
    assert done.returncode == 0, done.stderr
    told = btlog("explain", fixed, "--cache-dir", tmp_path / "cache")
    assert told.returncode == 0, told.stderr
    assert "0 events" not in told.stdout
    return fixed, done.stdout


def test_a_lost_tree_chunk_is_rebuilt_from_the_attachment(recording, tmp_path):
    path, log = recording
    data = bytearray(path.read_bytes())
    first, length = chunks(bytes(data))[0]
    data[first + length // 2] ^= 0x5A
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    refused = btlog("explain", broken, "--cache-dir", tmp_path / "cache")
    assert refused.returncode == EXIT_BAD_INPUT and f"byte {first}" in refused.stderr
    fixed, said = recovered(broken, tmp_path)
    assert "the tree rebuilt from the attached loop.xml" in said
    read = open_recording(fixed)
    rebuilt, original = read.tree.describe()["nodes"], open_recording(path).tree.describe()["nodes"]
    assert [(n["uid"], n["type"], n["name"], n["path"]) for n in rebuilt] == [
        (n["uid"], n["type"], n["name"], n["path"]) for n in original
    ]
    kept = [e for e in log.events if e.seq >= read.events[0].seq]
    assert read.events == kept and len(kept) > len(log.events) // 2


def test_a_chunk_written_twice_is_dropped_and_counted(recording, tmp_path):
    path, log = recording
    data = path.read_bytes()
    offset, length = chunks(data)[3]
    broken = tmp_path / "twice.mcap"
    broken.write_bytes(
        data[: offset + length] + data[offset : offset + length] + data[offset + length :]
    )
    fixed, said = recovered(broken, tmp_path)
    assert "duplicated messages dropped" in said
    read = open_recording(fixed)
    assert read.events == log.events


def test_shuffled_chunks_are_saved_in_seq_order(recording, tmp_path):
    path, log = recording
    count = len(chunks(path.read_bytes()))
    moved = reordered(path, tmp_path / "moved.mcap", shuffled_order(count), keep_summary=False)
    fixed, _said = recovered(moved, tmp_path)
    firsts = [
        fmt.parse_events(payload).status[0][0]
        for topic, _time, payload in iter_messages(fixed)
        if topic == fmt.EVENTS_TOPIC and fmt.parse_events(payload).status
    ]
    assert firsts == sorted(firsts) and len(firsts) > 5
    assert open_recording(fixed).events == log.events


def test_a_header_only_file_has_nothing_to_recover(recording, tmp_path):
    path, _log = recording
    data = path.read_bytes()
    header_only = tmp_path / "header.mcap"
    header_only.write_bytes(data[: 8 + 9 + int.from_bytes(data[9:17], "little")])
    done = btlog("recover", header_only, "-o", tmp_path / "out.mcap")
    assert done.returncode == EXIT_BAD_INPUT, done.stderr
    assert done.stderr.count("\n") == 1
    assert str(header_only) in done.stderr and "nothing to recover" in done.stderr
    assert not (tmp_path / "out.mcap").exists()


def _by_topic(path: Path) -> dict[str, list[bytes]]:
    found: dict[str, list[bytes]] = {}
    for topic, _time, payload in iter_messages(path):
        found.setdefault(topic, []).append(payload)
    return found


def test_a_cut_file_in_order_is_copied_as_it_comes_and_a_shuffled_one_saves_the_same(
    recording, tmp_path
):
    """The normal cut file is copied in file order (one chunk at a time); its chunks
    shuffled, the same messages are saved, topic by topic in the same order, and the
    report counts the same."""
    path, log = recording
    count = len(chunks(path.read_bytes()))
    cut = reordered(path, tmp_path / "cut.mcap", list(range(count)), keep_summary=False)
    moved = reordered(path, tmp_path / "moved.mcap", shuffled_order(count, 3), keep_summary=False)
    fixed, said = recovered(cut, tmp_path)
    in_order = _by_topic(fixed)
    topics = [topic for topic, _time, _payload in iter_messages(fixed)]
    assert topics.index(fmt.TICKS_TOPIC) < len(topics) - topics[::-1].index(fmt.EVENTS_TOPIC) - 1
    (tmp_path / "again").mkdir()
    fixed_moved, said_moved = recovered(moved, tmp_path / "again")
    assert _by_topic(fixed_moved) == in_order and len(in_order[fmt.EVENTS_TOPIC]) > 5
    assert (
        said_moved.replace(str(moved), "X").split("->")[1].split(":", 1)[1]
        == (said.split("->")[1].split(":", 1)[1])
    )
    assert open_recording(fixed_moved).events == log.events


def test_a_chunk_repeated_far_from_its_place_is_dropped_and_counted(recording, tmp_path):
    path, log = recording
    data = path.read_bytes()
    found = chunks(data)
    offset, length = found[2]
    end = found[-1][0] + found[-1][1]
    broken = tmp_path / "again.mcap"
    broken.write_bytes(data[:end] + data[offset : offset + length])  # cut, chunk 2 again
    fixed, said = recovered(broken, tmp_path)
    assert "duplicated messages dropped" in said
    assert open_recording(fixed).events == log.events

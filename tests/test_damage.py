"""Damaged recordings are told, never answered silently (CRC checks, framing, recover).

Every hostile file is made here from a real recording: a byte flipped inside a chunk, a
chunk's length damaged, rows that name nodes the tree does not have, seqs written twice.
"""

from __future__ import annotations

import random
import struct
from dataclasses import replace
from pathlib import Path

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import EventLog
from btlog.executor.engine import Executor
from btlog.record import Recorder, RecordingError, iter_messages, open_recording, recover
from btlog.record import format as fmt
from btlog.replay.database import ReplayError, open_runs
from btlog.tree.loader import load_tree_text
from tests.cli_support import btlog
from tests.mcap_support import stored_metadata, write_messages

ROOT = Path(__file__).resolve().parent.parent
LOOP = """<root BTCPP_format="4"><BehaviorTree ID="MainTree">
  <KeepRunningUntilFailure><Sequence name="work">
    <Action ID="Look" name="look"/><Action ID="Grasp" name="grasp"/>
    <Script code="count := 1"/><Action ID="Place" name="place"/>
  </Sequence></KeepRunningUntilFailure>
</BehaviorTree></root>"""


def record(path: Path, ticks: int = 400) -> EventLog:
    """A looping run recorded into many small chunks (events grouped by 50)."""
    tree = load_tree_text(LOOP)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    log = EventLog()
    recorder = Recorder(
        path, tree, {"domain": "loop"}, flush_interval=3600, chunk_size=1024, group_events=50
    )
    executor.subscribe(log)
    executor.subscribe(recorder)
    executor.run(max_ticks=ticks)
    executor.close()
    return log


def chunks(data: bytes) -> list[tuple[int, int]]:
    """(offset, total length) of each top-level chunk record."""
    found, position = [], 8
    while position + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, position)
        if opcode == 0x02:  # footer
            break
        if opcode == 0x06:
            found.append((position, 9 + length))
        position += 9 + length
    return found


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, EventLog]:
    path = tmp_path_factory.mktemp("damage") / "run.mcap"
    log = record(path)
    assert len(chunks(path.read_bytes())) >= 6
    return path, log


def damaged_copy(source: Path, target: Path, offset: int, xor: int = 0x5A) -> Path:
    data = bytearray(source.read_bytes())
    data[offset] ^= xor
    target.write_bytes(bytes(data))
    return target


def test_a_damaged_chunk_is_skipped_with_file_and_offset_and_the_rest_is_read(recording, tmp_path):
    path, log = recording
    offset, length = chunks(path.read_bytes())[3]
    broken = damaged_copy(path, tmp_path / "flip.mcap", offset + length // 2)
    read = open_recording(broken)
    assert any(f"{broken}: damaged data at byte {offset}" in w for w in read.warnings)
    assert any("not 0, 1, 2" in w for w in read.warnings), "the hole in the seqs is told"
    assert read.events and read.events[-1] == log.events[-1], "chunks after the damage are kept"
    assert set(read.events) < set(log.events)
    with open_runs(broken, cache=False) as database:
        run = database.run()
        assert any(f"damaged data at byte {offset}" in w for w in run.info.warnings)
        _c, rows = database.sql("SELECT max(seq) FROM transitions")
        assert rows == [(log.transitions[-1].seq,)]


def test_damaged_framing_is_resynchronised_on_the_next_chunk(recording, tmp_path):
    path, log = recording
    offset, _length = chunks(path.read_bytes())[2]
    broken = damaged_copy(path, tmp_path / "length.mcap", offset + 3)  # the record length
    read = open_recording(broken)
    assert any(f"damaged data at byte {offset}" in w and "framing" in w for w in read.warnings)
    assert read.events[-1] == log.events[-1]


def test_a_message_index_whose_length_lies_is_skipped_not_the_chunk_after_it(recording, tmp_path):
    """No CRC guards the records between chunks: a message index whose length spans the
    next chunk exactly had the walk skip that chunk without a word of it."""
    path, log = recording
    data = bytearray(path.read_bytes())
    (second, second_length), (third, third_length) = chunks(bytes(data))[1:3]
    index = second + second_length  # the message indexes of the second chunk follow it
    assert data[index] == 0x07
    struct.pack_into("<Q", data, index + 1, third + third_length - index - 9)
    broken = tmp_path / "index.mcap"
    broken.write_bytes(bytes(data))
    read = open_recording(broken)
    assert any(f"damaged data at byte {index}" in w for w in read.warnings), read.warnings
    assert read.events == log.events, "every chunk is read"


def test_the_cli_warns_and_answers_from_the_intact_chunks(recording, tmp_path):
    path, _log = recording
    offset, length = chunks(path.read_bytes())[1]
    broken = damaged_copy(path, tmp_path / "cli.mcap", offset + length - 20)
    result = btlog("sql", str(broken), "SELECT count(*) AS n FROM transitions", "--format", "csv")
    assert result.returncode == 0, result.stderr
    assert f"cli.mcap: damaged data at byte {offset}" in result.stderr
    assert "Traceback" not in result.stderr


def test_random_flips_inside_chunks_are_never_silent(recording, tmp_path):
    """A flipped byte anywhere in a chunk either leaves the events as recorded or is
    told (a warning or an error), for the reader and for the read model."""
    path, log = recording
    data = path.read_bytes()
    spans = chunks(data)
    rng = random.Random(14)
    for number in range(12):
        offset, length = rng.choice(spans)
        broken = damaged_copy(path, tmp_path / f"r{number}.mcap", offset + rng.randrange(length))
        try:
            read = open_recording(broken)
        except RecordingError:
            continue
        assert read.events == log.events or read.warnings
        with open_runs(broken, cache=False) as database:
            run = database.run()
            _c, rows = database.sql("SELECT count(*) FROM transitions")
            assert rows == [(len(log.transitions),)] or run.info.warnings


def test_recover_keeps_every_intact_chunk_after_the_damage(recording, tmp_path):
    path, log = recording
    offset, length = chunks(path.read_bytes())[2]
    broken = damaged_copy(path, tmp_path / "broken.mcap", offset + length // 2)
    damaged = open_recording(broken)
    report = recover(broken, tmp_path / "fixed.mcap")
    assert [d.offset for d in report.dropped] == [offset]
    assert report.missing and report.last_seq == log.events[-1].seq
    assert f"dropped 1 damaged part(s): {length} bytes at byte {offset}" in report.summary()
    fixed = open_recording(tmp_path / "fixed.mcap")
    assert fixed.events == damaged.events and len(fixed.events) > len(log.events) // 2
    result = btlog("recover", str(broken), "-o", str(tmp_path / "cli.mcap"))
    assert result.returncode == 0 and "seqs missing" in result.stdout


def rewrite(source: Path, target: Path, change) -> Path:
    """``source`` re-written (valid CRCs) with each events message's status rows passed
    through ``change`` (a list of row lists in, the same out)."""

    def changed(data: bytes) -> bytes:
        events = fmt.parse_events(data)
        rows = change([list(row) for row in events.status])
        return fmt.encode_events(replace(events, status=[tuple(row) for row in rows]))

    messages = (
        (topic, log_time, changed(data)) if topic == fmt.EVENTS_TOPIC else (topic, log_time, data)
        for topic, log_time, data in iter_messages(source)
    )
    return write_messages(target, stored_metadata(source), messages)


@pytest.mark.parametrize("uid", [999, -3, 0])
def test_rows_naming_unknown_nodes_are_refused(recording, tmp_path, uid):
    """Above the tree's uids, below them (the check by range), and 0 (no node's uid)."""
    path, _log = recording

    def stray(rows: list[list]) -> list[list]:
        for row in rows:
            if row[0] == 40:
                row[3] = uid
        return rows

    crafted = rewrite(path, tmp_path / "stray.mcap", stray)
    with pytest.raises(ReplayError, match=rf"stray\.mcap: event seq 40 is about node uid {uid}\b"):
        open_runs(crafted, cache=False)


def test_seqs_written_twice_are_refused(recording, tmp_path):
    path, _log = recording

    def twice(rows: list[list]) -> list[list]:
        for row in rows:
            if row[0] == 41:
                row[0] = 40
        return rows

    crafted = rewrite(path, tmp_path / "twice.mcap", twice)
    with pytest.raises(ReplayError, match=r"twice\.mcap: two events have seq 40"):
        open_runs(crafted, cache=False)

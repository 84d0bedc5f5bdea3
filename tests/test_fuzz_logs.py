"""Fuzzed logs of other tools through ``btlog import``: a BT.CPP 3 ``.fbl``, a Nav2 bag in
MCAP storage and one in SQLite storage (ROS 2 Humble's), damaged byte by byte
(``tests/fuzz_support.py``), end in exit 0 with every intact transition kept, or in exit
2 with one line naming the file; never exit 3 or a traceback.

"Intact" is what lies wholly before the first damaged byte: the ``.fbl``'s whole records
before it, the MCAP bag's chunks that end before it (a damaged chunk is skipped with a
warning, as in btlog's own recordings). A SQLite file has no checksums and no order of
pages in time: its damage must end in exit 0 or 2, and nothing else is promised (a
flipped byte inside a message's timestamp is a different timestamp)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import given
from mcap.opcode import Opcode
from mcap.writer import Writer as McapWriter

from btlog.events import StatusChange
from btlog.record.reader import Recording, open_recording
from btlog.record.walk import HEAD, MAGIC, Walk, chunk_records, inner_records, top_records
from btlog.runner import RunConfig, execute
from btlog.sinks.nav2_rosbag import LOG_MSGDEF
from tests.fbl_support import write_fbl
from tests.fuzz_support import (
    Damage,
    assert_contract,
    assert_prefix_kept,
    damaged,
    fuzz,
    run_cli,
    scratch_folder,
)
from tests.rosbag2_support import HUMBLE, NAV2_LOG, write_sqlite_bag
from tests.test_import_fbl import STAND_IN, UID_BASE, header_of
from tests.test_nav2_rosbag import nav2_messages, write_nav2_bag

_FOLDER = scratch_folder("btlog-fuzz-logs-")
_OUTCOMES = {
    "default": {"status": "SUCCESS", "duration": 0.3},
    "nodes": {"FollowPath": [{"status": "FAILURE", "duration": 1.0}, "SUCCESS"]},
}
RUN = open_recording(
    execute(RunConfig(str(STAND_IN), outcomes=_OUTCOMES), _FOLDER / "run.mcap").path
)
CHANGES = [(e.uid, e.prev, e.status) for e in RUN.transitions]

# the .fbl: header, then 12-byte records from RECORDS_AT
_root, _models = header_of(RUN.tree)
FBL = write_fbl(
    _FOLDER / "run.fbl",
    _root,
    _models,
    [
        (1_700_000_000_000_000 + e.t_ns // 1000, e.uid + UID_BASE, int(e.prev), int(e.status))
        for e in RUN.transitions
    ],
)
RECORDS_AT = 4 + int.from_bytes(FBL[:4], "little")

# the MCAP bag: what Nav2 Jazzy publishes (uids), in small chunks
_BAG = _FOLDER / "run-bag.mcap"
write_nav2_bag(_BAG, [RUN], chunk_size=512)
MCAP = _BAG.read_bytes()
#: what the bags hold: Nav2 publishes while the tree runs, so not the goal's last tick
LOGGED = [
    (entry["uid"], entry["previous_status"], entry["current_status"])
    for message in nav2_messages([RUN])
    for entry in message[3]["event_log"]
]

# the SQLite bag: Humble's, no definitions, names without uids
_SQLITE = write_sqlite_bag(_FOLDER / "humble", nav2_messages([RUN], uids=False), {NAV2_LOG: HUMBLE})
SQLITE = _SQLITE[0].read_bytes()


def _kept(path: Path) -> list[tuple]:
    """The imported changes, without a first tick inferred for a log that seems to begin
    mid-run (a damaged first record of a node changes what the start is inferred to be)."""
    recording: Recording = open_recording(path)
    changes = [e for e in recording.events if isinstance(e, StatusChange)]
    if recording.metadata.get("mid_run"):
        changes = [e for e in changes if e.tick > 1]
    return [(e.uid, e.prev, e.status) for e in changes]


def _import(damage: Damage, name: str, *args: object) -> tuple[Path, object]:
    folder = Path(tempfile.mkdtemp(dir=_FOLDER))
    source, output = folder / name, folder / "out.mcap"
    source.write_bytes(damage.data)
    outcome = run_cli("import", source, "-o", output, *args)
    assert_contract(outcome, str(source))
    return output, outcome


@given(damage=damaged(FBL))
@fuzz(examples=40, seconds=10)
def test_a_damaged_fbl_is_imported_with_its_intact_records_or_refused(damage: Damage) -> None:
    output, outcome = _import(damage, "run.fbl")
    if outcome.code == 0:  # type: ignore[attr-defined]
        whole = max(0, (damage.intact - RECORDS_AT) // 12)
        assert_prefix_kept(CHANGES[:whole], _kept(output))
    else:
        assert not output.exists(), "a refused import leaves no file behind"


@given(damage=damaged(FBL, start=RECORDS_AT))
@fuzz(examples=40, seconds=8)
def test_damaged_fbl_records_keep_every_intact_record(damage: Damage) -> None:
    output, outcome = _import(damage, "run.fbl")
    if outcome.code == 0:  # type: ignore[attr-defined]
        whole = max(0, (damage.intact - RECORDS_AT) // 12)
        assert_prefix_kept(CHANGES[:whole], _kept(output))
    else:
        assert "byte" in outcome.stderr  # type: ignore[attr-defined]


def _chunk_ends(data: bytes) -> list[tuple[int, int]]:
    """``(end offset, log entries so far)`` after each chunk of an undamaged MCAP bag."""
    walk, ends, entries = Walk("bag"), [], 0
    log_channels: set[int] = set()
    for opcode, body, end in top_records(data, len(data), walk):
        if opcode != Opcode.CHUNK:
            continue
        for inner, buffer, start, stop in inner_records(chunk_records(data, body, end)):
            if inner == Opcode.CHANNEL and b"/behavior_tree_log" in buffer[start:stop]:
                log_channels.add(int.from_bytes(buffer[start : start + 2], "little"))
            if inner == Opcode.MESSAGE:
                channel = int.from_bytes(buffer[start : start + 2], "little")
                if channel in log_channels:
                    entries += _entries_in(bytes(buffer[start + 22 : stop]))
        ends.append((end, entries))
    return ends


def _entries_in(cdr: bytes) -> int:
    """The number of status changes in a ``BehaviorTreeLog`` message: the event_log
    length, after the header (4 bytes) and the stamp (8)."""
    return int.from_bytes(cdr[12:16], "little")


CHUNK_ENDS = _chunk_ends(MCAP)
assert len(MAGIC) + HEAD.size < CHUNK_ENDS[0][0] and CHUNK_ENDS[-1][1] == len(LOGGED)


@given(damage=damaged(MCAP))
@fuzz(examples=40, seconds=10)
def test_a_damaged_mcap_bag_is_imported_with_its_intact_chunks_or_refused(damage: Damage) -> None:
    output, outcome = _import(damage, "bag.mcap", "--tree", STAND_IN)
    if outcome.code == 0:  # type: ignore[attr-defined]
        intact = max((n for end, n in CHUNK_ENDS if end <= damage.intact), default=0)
        kept = [(uid, prev.name, new.name) for uid, prev, new in _kept(output)]
        assert_prefix_kept(LOGGED[:intact], kept)


def test_a_definition_the_parser_cannot_read_is_refused_in_one_line() -> None:
    """A bag whose own definition is damaged ('uint32' made 'tint32'), every CRC valid:
    mcap_ros2's parser prints on stderr before it raises; the refusal stays one line
    (found by the fuzz test above, when a damaged summary was still read)."""
    assert b"uint32 nanosec" in LOG_MSGDEF.encode()
    with open(_FOLDER / "bad-definition.mcap", "wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="ros2", library="btlog tests")
        schema = writer.register_schema(
            NAV2_LOG, "ros2msg", LOG_MSGDEF.replace("uint32 nanosec", "tint32 nanosec").encode()
        )
        channel = writer.register_channel("/behavior_tree_log", "cdr", schema)
        writer.add_message(channel, 1, b"\0\1\0\0" + bytes(16), 1)
        writer.finish()
    data = (_FOLDER / "bad-definition.mcap").read_bytes()
    _output, outcome = _import(Damage(data, len(data), "none"), "bag.mcap", "--tree", STAND_IN)
    assert outcome.code == 2  # type: ignore[attr-defined]
    assert "'tint32'" in outcome.stderr  # type: ignore[attr-defined]


@given(damage=damaged(SQLITE))
@fuzz(examples=25, seconds=8)
def test_a_damaged_sqlite_bag_is_imported_or_refused_in_one_line(damage: Damage) -> None:
    output, outcome = _import(damage, "humble_0.db3", "--tree", STAND_IN)
    assert output.exists() == (outcome.code == 0)  # type: ignore[attr-defined]

"""Hostile BT.CPP logs through ``btlog import``: each ends in exit 0 with the right data (and
a warning saying what was wrong) or in exit 2 with one line naming the file and the byte,
session or key; never exit 3."""

from __future__ import annotations

import sqlite3
import struct
from pathlib import Path

import pytest

from btlog.events import StatusChange
from btlog.record.reader import open_recording
from btlog.sinks.btcpp_filelog import export_filelog
from btlog.sources.btcpp_filelog import read_filelog
from btlog.sources.btcpp_records import RECORD_SIZE
from btlog.sources.builder import SourceError
from btlog.status import Status
from tests.cli_support import ROOT
from tests.fuzz_support import Outcome, assert_contract, run_cli

KITTING_RUN = ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"


@pytest.fixture(scope="module")
def btlog_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("faults") / "kitting.btlog"
    export_filelog(open_recording(KITTING_RUN), path)
    return path


def _with_start(source: Path, target: Path, start_us: int) -> Path:
    log = read_filelog(source)
    data = bytearray(source.read_bytes())
    data[log.start_offset : log.start_offset + 8] = struct.pack("<q", start_us)
    target.write_bytes(bytes(data))
    return target


def _transitions(path: Path) -> list[tuple]:
    return [
        (e.t_ns, e.uid, e.status)
        for e in open_recording(path).events
        if isinstance(e, StatusChange)
    ]


@pytest.mark.parametrize("start_us", [-1, -(1 << 63), (1 << 63) - 1])
def test_a_start_time_that_is_no_wall_time_imports_from_the_epoch_with_a_warning(
    btlog_file: Path, tmp_path: Path, start_us: int
) -> None:
    broken = _with_start(btlog_file, tmp_path / "start.btlog", start_us)
    out = tmp_path / "start.mcap"
    result = run_cli("import", broken, "-o", out)
    assert result.code == 0, result.stderr
    offset = read_filelog(btlog_file).start_offset
    assert f"start.btlog (byte {offset}): start time {start_us} µs" in result.stderr
    assert "1970-01-01T00:00:00Z" in result.stderr
    recording = open_recording(out)
    assert recording.metadata["started_at"].startswith("1970-01-01T00:00:00")
    good = tmp_path / "good.mcap"
    assert run_cli("import", btlog_file, "-o", good).code == 0
    assert _transitions(out) == _transitions(good)


def test_a_record_naming_no_node_is_refused_with_its_byte(btlog_file: Path, tmp_path: Path) -> None:
    log = read_filelog(btlog_file)
    data = bytearray(btlog_file.read_bytes())
    at = log.records_offset + 5 * 9
    data[at + 6 : at + 8] = (999).to_bytes(2, "little")
    broken = tmp_path / "uid.btlog"
    broken.write_bytes(bytes(data))
    result = run_cli("import", broken, "-o", tmp_path / "uid.mcap")
    assert_contract(result, "uid.btlog", "node uid 999", f"record 5 (byte {at})", codes=[2])
    assert not (tmp_path / "uid.mcap").exists()


def test_records_are_read_in_blocks_with_the_same_transitions_and_error_places(
    btlog_file: Path, tmp_path: Path
) -> None:
    """The records are read a block at a time (memory bounded whatever the file's size):
    blocks of 7 records give the transitions of one read, a bad status in a later block
    is named by its record and byte, and a file cut while it is read says so."""
    log = read_filelog(btlog_file)
    whole = list(log.transitions())
    assert len(whole) == len(log) > 7 * 3
    assert list(log.transitions(block=7 * RECORD_SIZE)) == whole
    data = bytearray(btlog_file.read_bytes())
    at = log.records_offset + 17 * RECORD_SIZE
    data[at + 8] = 9
    broken = tmp_path / "status.btlog"
    broken.write_bytes(bytes(data))
    seen: list[tuple] = []
    with pytest.raises(SourceError, match=rf"status\.btlog: record 17 \(byte {at}\): status 9"):
        seen.extend(read_filelog(broken).transitions(block=7 * RECORD_SIZE))
    assert seen == whole[:17]
    cut = tmp_path / "cut.btlog"
    cut.write_bytes(btlog_file.read_bytes())
    opened = read_filelog(cut)
    with open(cut, "r+b") as stream:
        stream.truncate(log.records_offset + 10 * RECORD_SIZE)
    cut_at = r"cut\.btlog: the file was cut while read, at record 10 \("
    with pytest.raises(SourceError, match=cut_at):
        list(opened.transitions(block=7 * RECORD_SIZE))


# -- SqliteLogger files ----------------------------------------------------------------------
def sqlite_log(db: Path, xml: bytes | str, rows: list[tuple], old: bool = False) -> Path:
    """A SqliteLogger file of one session holding ``rows`` (timestamp, uid, state, extra),
    with the tables BT.CPP 4.6 and later create, or (``old``) 4.1 to 4.5's: the uid column
    named ``uid``, no ``extra_data``, no ``Nodes``."""
    uid, extra = ("uid", "") if old else ("node_uid", ", extra_data VARCHAR")
    con = sqlite3.connect(db)
    con.executescript(
        f"CREATE TABLE Transitions (timestamp INTEGER PRIMARY KEY NOT NULL, session_id INTEGER "
        f"NOT NULL, {uid} INTEGER NOT NULL, duration INTEGER, state INTEGER NOT NULL{extra});"
        "CREATE TABLE Definitions (session_id INTEGER PRIMARY KEY AUTOINCREMENT, "
        "date TEXT NOT NULL, xml_tree TEXT NOT NULL);"
    )
    con.execute("INSERT INTO Definitions (date, xml_tree) VALUES ('2026-12-01 10:00', ?)", (xml,))
    columns = f"timestamp, session_id, {uid}, state" + ("" if old else ", extra_data")
    marks = ", ".join("?" * len(columns.split(",")))
    con.executemany(
        f"INSERT INTO Transitions ({columns}) VALUES ({marks})",
        [(t, 1, u, s, *([] if old else [x])) for t, u, s, x in rows],
    )
    con.commit()
    con.close()
    return db


@pytest.fixture(scope="module")
def kitting_rows(btlog_file: Path) -> tuple[bytes, list[tuple]]:
    """The kitting run's tree XML and its transitions as SQLite rows (µs since 1970)."""
    log = read_filelog(btlog_file)
    start = 1_780_000_000_000_000
    rows = [(start + t + i, u, int(s), "") for i, (t, u, s) in enumerate(log.transitions())]
    return log.xml, rows


def _expected(rows: list[tuple]) -> list[tuple]:
    """The transitions a recording of ``rows`` holds: (ns since the first, uid, status)."""
    return [((t - rows[0][0]) * 1000, u, Status(s)) for t, u, s, _x in rows]


def _import(db: Path, out: Path) -> Outcome:
    return run_cli("import", db, "-o", out)


def test_a_negative_timestamp_imports_from_the_epoch_with_a_warning(kitting_rows, tmp_path):
    xml, rows = kitting_rows
    shifted = [(t - rows[0][0] - 5_000_000, u, s, x) for t, u, s, x in rows]
    db = sqlite_log(tmp_path / "neg.db3", xml, shifted)
    result = _import(db, tmp_path / "neg.mcap")
    assert result.code == 0, result.stderr
    assert "neg.db3 session 1: start time -5000000 µs" in result.stderr
    assert _transitions(tmp_path / "neg.mcap") == _expected(shifted)


def test_bt_cpp_4_5_files_without_extra_data_nor_nodes_import(kitting_rows, tmp_path):
    xml, rows = kitting_rows
    db = sqlite_log(tmp_path / "old.db3", xml, rows, old=True)
    result = _import(db, tmp_path / "old.mcap")
    assert result.code == 0 and not result.stderr, result.stderr
    assert _transitions(tmp_path / "old.mcap") == _expected(rows)
    con = sqlite3.connect(db)  # node_uid, as 4.6 names it, but no extra_data column
    con.execute("ALTER TABLE Transitions RENAME COLUMN uid TO node_uid")
    con.commit()
    con.close()
    result = _import(db, tmp_path / "mixed.mcap")
    assert result.code == 0 and not result.stderr, result.stderr
    assert _transitions(tmp_path / "mixed.mcap") == _expected(rows)


def test_a_database_damaged_part_way_keeps_the_transitions_before_the_damage(
    kitting_rows, tmp_path
):
    xml, rows = kitting_rows
    many = [(t + 100_000_000 * lap, u, s, x) for lap in range(40) for t, u, s, x in rows]
    db = sqlite_log(tmp_path / "bad.db3", xml, many)
    data = bytearray(db.read_bytes())
    page = 4096
    at = (len(data) // page) * 3 // 4 * page  # a leaf page of Transitions, late in the file
    data[at : at + page] = bytes([0x55]) * page
    db.write_bytes(bytes(data))
    result = _import(db, tmp_path / "bad.mcap")
    assert result.code == 0, result.stderr
    assert "bad.db3 session 1: the database is damaged after the transition at timestamp" in (
        result.stderr
    )
    assert "malformed" in result.stderr
    kept = _transitions(tmp_path / "bad.mcap")
    assert len(rows) < len(kept) < len(many)
    assert kept == _expected(many)[: len(kept)]


def test_an_undecodable_tree_is_refused_naming_the_session(kitting_rows, tmp_path):
    xml, rows = kitting_rows
    db = sqlite_log(tmp_path / "xml.db3", xml, rows)
    con = sqlite3.connect(db)
    broken = xml[:100] + b"\xff\xfe" + xml[100:]
    con.execute("UPDATE Definitions SET xml_tree = CAST(? AS TEXT)", (broken,))
    con.commit()
    con.close()
    result = _import(db, tmp_path / "x.mcap")
    assert_contract(result, "xml.db3 session 1", "not UTF-8", "byte 100", codes=[2])
    assert not (tmp_path / "x.mcap").exists()


@pytest.mark.parametrize(
    ("row", "words"),
    [
        ((5, "x", 1, ""), ["timestamp 5", "node uid 'x' is not an integer"]),
        ((5, 1, 9, ""), ["timestamp 5", "status 9 is not 0-4"]),
        ((5, 4000, 1, ""), ["node uid 4000 is not in the tree", "timestamp 5"]),
    ],
)
def test_bad_values_in_a_row_are_refused_naming_the_timestamp(kitting_rows, tmp_path, row, words):
    xml, _rows = kitting_rows
    db = sqlite_log(tmp_path / "row.db3", xml, [(1, 1, 1, ""), row])
    assert_contract(_import(db, tmp_path / "row.mcap"), "row.db3 session 1", *words, codes=[2])
    assert not (tmp_path / "row.mcap").exists()


def test_a_huge_gap_between_timestamps_is_refused_not_overflowed(kitting_rows, tmp_path):
    xml, _rows = kitting_rows
    db = sqlite_log(tmp_path / "gap.db3", xml, [(1, 1, 1, ""), ((1 << 62), 1, 2, "")])
    result = _import(db, tmp_path / "gap.mcap")
    assert_contract(result, "gap.db3", "past 2262", "timestamp", codes=[2])

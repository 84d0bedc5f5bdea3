"""Hostile BT.CPP logs through ``btlog import``: each ends in exit 0 with the right data (and
a warning saying what was wrong) or in exit 2 with one line naming the file and the byte,
session or key; never exit 3."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from btlog.events import StatusChange
from btlog.record.reader import open_recording
from btlog.sinks.btcpp_filelog import export_filelog
from btlog.sources.btcpp_filelog import read_filelog
from tests.cli_support import ROOT, assert_bad_input, btlog

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
    result = btlog("import", broken, "-o", out)
    assert result.returncode == 0, result.stderr
    offset = read_filelog(btlog_file).start_offset
    assert f"start.btlog (byte {offset}): start time {start_us} µs" in result.stderr
    assert "1970-01-01T00:00:00Z" in result.stderr
    recording = open_recording(out)
    assert recording.metadata["started_at"].startswith("1970-01-01T00:00:00")
    good = tmp_path / "good.mcap"
    assert btlog("import", btlog_file, "-o", good).returncode == 0
    assert _transitions(out) == _transitions(good)


def test_a_record_naming_no_node_is_refused_with_its_byte(btlog_file: Path, tmp_path: Path) -> None:
    log = read_filelog(btlog_file)
    data = bytearray(btlog_file.read_bytes())
    at = log.records_offset + 5 * 9
    data[at + 6 : at + 8] = (999).to_bytes(2, "little")
    broken = tmp_path / "uid.btlog"
    broken.write_bytes(bytes(data))
    result = btlog("import", broken, "-o", tmp_path / "uid.mcap")
    assert_bad_input(result, "uid.btlog", "node uid 999", f"record 5 (byte {at})")
    assert not (tmp_path / "uid.mcap").exists()

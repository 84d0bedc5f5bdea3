"""Fuzzed BT.CPP logs through ``btlog import``: a FileLogger2 ``.btlog`` and a SqliteLogger
file, damaged byte by byte (``tests/fuzz_support.py``), end in exit 0 with every intact
transition kept or in exit 2 with one line naming the file; never exit 3."""

from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import given

from btlog.events import StatusChange
from btlog.record.reader import open_recording
from btlog.sinks.btcpp_filelog import export_filelog
from btlog.sources.btcpp_filelog import read_filelog
from btlog.sources.btcpp_records import RECORD_SIZE
from tests.cli_support import ROOT
from tests.fuzz_support import Damage, assert_contract, assert_prefix_kept, damaged, fuzz, run_cli

KITTING_RUN = ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"
_FOLDER = Path(tempfile.mkdtemp(prefix="btlog-fuzz-imports-"))
BTLOG_FILE = _FOLDER / "kitting.btlog"
export_filelog(open_recording(KITTING_RUN), BTLOG_FILE)
BTLOG = BTLOG_FILE.read_bytes()
LOG = read_filelog(BTLOG_FILE)
RECORDS = [(t_us * 1000, uid, status) for t_us, uid, status in LOG.transitions()]


def _imported(path: Path) -> list[tuple]:
    return [
        (e.t_ns, e.uid, e.status)
        for e in open_recording(path).events
        if isinstance(e, StatusChange)
    ]


def _import(damage: Damage, suffix: str) -> tuple[Path, object]:
    folder = Path(tempfile.mkdtemp(dir=_FOLDER))
    source, output = folder / f"in{suffix}", folder / "out.mcap"
    source.write_bytes(damage.data)
    outcome = run_cli("import", source, "-o", output)
    assert_contract(outcome, str(source))
    return output, outcome


@given(damage=damaged(BTLOG))
@fuzz(examples=40, seconds=12)
def test_a_damaged_btlog_anywhere_is_imported_or_refused_in_one_line(damage: Damage) -> None:
    output, outcome = _import(damage, ".btlog")
    if outcome.code != 0:  # type: ignore[attr-defined]
        assert not output.exists(), "a refused import leaves no file behind"


@given(damage=damaged(BTLOG, start=LOG.start_offset))
@fuzz(examples=60, seconds=15)
def test_damaged_btlog_records_keep_every_intact_record(damage: Damage) -> None:
    output, outcome = _import(damage, ".btlog")
    if outcome.code == 0:  # type: ignore[attr-defined]
        whole = max(0, (damage.intact - LOG.records_offset) // RECORD_SIZE)
        assert_prefix_kept(RECORDS[:whole], _imported(output))
    else:
        assert not output.exists()

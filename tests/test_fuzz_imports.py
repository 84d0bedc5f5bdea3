"""Fuzzed BT.CPP logs through ``btlog import``: a FileLogger2 ``.btlog`` and a SqliteLogger
file, damaged byte by byte (``tests/fuzz_support.py``), and SqliteLogger rows holding any
value SQLite can store, end in exit 0 (every intact ``.btlog`` record kept) or in exit 2
with one line naming the file; never exit 3."""

from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from btlog.events import StatusChange
from btlog.record.reader import open_recording
from btlog.sinks.btcpp_filelog import export_filelog
from btlog.sources.btcpp_filelog import read_filelog
from btlog.sources.btcpp_records import RECORD_SIZE
from tests.cli_support import ROOT
from tests.fuzz_support import (
    Damage,
    assert_contract,
    assert_prefix_kept,
    damaged,
    fuzz,
    run_cli,
    scratch_folder,
)
from tests.test_import_faults import sqlite_log

KITTING_RUN = ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"
_FOLDER = scratch_folder("btlog-fuzz-imports-")
BTLOG_FILE = _FOLDER / "kitting.btlog"
export_filelog(open_recording(KITTING_RUN), BTLOG_FILE)
BTLOG = BTLOG_FILE.read_bytes()
LOG = read_filelog(BTLOG_FILE)
RECORDS = [(t_us * 1000, uid, status) for t_us, uid, status in LOG.transitions()]
SQLITE_ROWS = [
    (1_780_000_000_000_000 + t * 1000 + i, u, int(s), "")
    for i, (t, u, s) in enumerate(LOG.transitions())
]
SQLITE = sqlite_log(_FOLDER / "kitting.db3", LOG.xml, SQLITE_ROWS).read_bytes()


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
@fuzz(examples=25, seconds=8)
def test_a_damaged_btlog_anywhere_is_imported_or_refused_in_one_line(damage: Damage) -> None:
    output, outcome = _import(damage, ".btlog")
    if outcome.code != 0:  # type: ignore[attr-defined]
        assert not output.exists(), "a refused import leaves no file behind"


@given(damage=damaged(BTLOG, start=LOG.start_offset))
@fuzz(examples=40, seconds=10)
def test_damaged_btlog_records_keep_every_intact_record(damage: Damage) -> None:
    output, outcome = _import(damage, ".btlog")
    if outcome.code == 0:  # type: ignore[attr-defined]
        whole = max(0, (damage.intact - LOG.records_offset) // RECORD_SIZE)
        assert_prefix_kept(RECORDS[:whole], _imported(output))
    else:
        assert not output.exists()


@given(damage=damaged(SQLITE))
@fuzz(examples=25, seconds=8)
def test_a_damaged_sqlite_log_is_imported_or_refused_in_one_line(damage: Damage) -> None:
    output, outcome = _import(damage, ".db3")
    assert output.exists() == (outcome.code == 0)  # type: ignore[attr-defined]


#: Any value a SQLite column can hold but NULL (BT.CPP's columns are NOT NULL).
SQL_VALUES = (
    st.integers(-(1 << 63), (1 << 63) - 1)
    | st.integers(-2, 40)
    | st.floats(allow_nan=False)
    | st.text(max_size=8)
    | st.binary(max_size=8)
)


@given(
    rows=st.lists(
        st.tuples(st.integers(-(1 << 62), 1 << 62), SQL_VALUES, SQL_VALUES, SQL_VALUES | st.none()),
        min_size=1,
        max_size=6,
        unique_by=lambda row: row[0],
    )
)
@fuzz(examples=30, seconds=8)
def test_sqlite_rows_of_any_values_are_imported_or_refused_in_one_line(rows: list) -> None:
    folder = Path(tempfile.mkdtemp(dir=_FOLDER))
    db = sqlite_log(folder / "rows.db3", LOG.xml, sorted(rows))
    outcome = run_cli("import", db, "-o", folder / "out.mcap")
    assert_contract(outcome, str(db))
    if outcome.code == 0:
        kept = _imported(folder / "out.mcap")
        assert [(u, int(s)) for _t, u, s in kept] == [(u, s) for _t, u, s, _x in sorted(rows)]

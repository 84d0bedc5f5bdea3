"""The two clocks: simulated time for reproducible runs, the wall clock for ``--realtime``.

Wall-clock assertions here are lower bounds only (a sleep lasts at least as long as
asked) or bounds with seconds of slack, so a loaded machine cannot make them fail.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from btlog.executor.clock import SimClock, WallClock
from btlog.record.reader import open_recording

ROOT = Path(__file__).resolve().parent.parent
PERIOD_NS = 20_000_000  # 0.02 s


def test_sim_clock_puts_tick_k_at_k_minus_one_periods() -> None:
    clock = SimClock(0.02)
    for tick in (1, 2, 7, 1000):
        clock.start_tick(tick)
        assert clock.now_ns() == (tick - 1) * PERIOD_NS


def test_paced_wall_clock_waits_until_the_tick_is_due() -> None:
    clock = WallClock(0.02, paced=True)
    clock.start_tick(1)
    clock.start_tick(4)
    assert clock.now_ns() >= 3 * PERIOD_NS


def test_unpaced_wall_clock_never_waits() -> None:
    clock = WallClock(1.0, paced=False)
    clock.start_tick(50)  # would be due 49 s from now
    assert clock.now_ns() < 5_000_000_000


def test_wall_clock_never_goes_back() -> None:
    clock = WallClock(0.02, paced=False)
    readings = [clock.now_ns() for _ in range(1000)]
    assert readings == sorted(readings)
    assert readings[0] >= 0


def test_realtime_run_paces_its_ticks_and_says_so(tmp_path: Path) -> None:
    out = tmp_path / "realtime.mcap"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "btlog.cli.main",
            "run",
            str(ROOT / "trees" / "kitting.xml"),
            "--domain",
            "kitting",
            "--realtime",
            "--tick-period",
            "0.02",
            "--max-ticks",
            "6",
            "-o",
            str(out),
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT / "src")},
    )
    assert result.returncode == 0, result.stderr
    recording = open_recording(out)
    assert recording.metadata["clock"] == "wall"
    ticks = [record for record in recording.ticks if not record.teardown]
    assert [t.tick for t in ticks] == list(range(1, 7))
    for record in ticks:
        assert record.start_ns >= (record.tick - 1) * PERIOD_NS
        assert record.end_ns >= record.start_ns
    times = [event.t_ns for event in recording.events]
    assert times == sorted(times)

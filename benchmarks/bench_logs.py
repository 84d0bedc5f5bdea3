"""Importing the logs robots already have: seconds against size, for the three formats of
the real logs btlog was measured on (README, "Measured on public trees").

The stand-ins are made as the real ones were written, from one btlog run of the Nav2
stand-in tree (``tests/data/logs/nav2-v3-stand-in.xml``, FollowPath failing once), the
run repeated K times:

1. **.fbl**: a BT.CPP 3 ``FileLogger`` file (``tests/fbl_support.py`` writes it byte for
   byte as BT.CPP 3.8 does), the runs one after the other (one long log);
2. **SQLite bag**: a Nav2 Humble rosbag2 folder (no message definitions, names without
   uids: matched by the tree's structure), one goal per run;
3. **MCAP bag**: a Nav2 Jazzy bag (uids, zstd chunks), one goal per run.

Each is imported as ``btlog import`` does (``import_fbl`` / ``import_bag``), best of
``--repeat``; the figures are the file size, the transitions imported, the seconds and
transitions per second. With ``--real DIR`` the ``.fbl`` files under DIR are timed too.

    python benchmarks/bench_logs.py                  # K = 1, 10, 100
    python benchmarks/bench_logs.py --real DIR       # your own folder of .fbl logs
    python benchmarks/bench_logs.py --smoke          # K = 1, 3, one repeat

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the tests' writers of the formats (never btlog's readers)

from tests.fbl_support import write_fbl  # noqa: E402
from tests.rosbag2_support import HUMBLE, NAV2_LOG, write_sqlite_bag  # noqa: E402
from tests.test_import_fbl import OUTCOMES, STAND_IN, UID_BASE, header_of  # noqa: E402
from tests.test_nav2_rosbag import nav2_messages, write_nav2_bag  # noqa: E402

from btlog.record.reader import Recording, open_recording  # noqa: E402
from btlog.record.recorder import start_time_ns  # noqa: E402
from btlog.runner import RunConfig, execute  # noqa: E402
from btlog.sources.btcpp_fbl import import_fbl  # noqa: E402
from btlog.sources.nav2_rosbag import import_bag  # noqa: E402


def _run(folder: Path) -> Recording:
    config = RunConfig(str(STAND_IN), outcomes=OUTCOMES)
    return open_recording(execute(config, folder / "run.mcap").path)


def make_fbl(run: Recording, times: int, path: Path) -> Path:
    """The run ``times`` over, one after the other, as a BT.CPP 3 FileLogger writes it."""
    start_us = start_time_ns(run.metadata["started_at"]) // 1000
    span = run.transitions[-1].t_ns // 1000 + 100_000
    changes = [
        (start_us + k * span + e.t_ns // 1000, e.uid + UID_BASE, int(e.prev), int(e.status))
        for k in range(times)
        for e in run.transitions
    ]
    root, models = header_of(run.tree)
    write_fbl(path, root, models, changes)
    return path


def _size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*")) if path.is_dir() else path.stat().st_size


def best(repeat: int, job: Callable[[], int]) -> tuple[float, int]:
    """The best wall time of ``repeat`` runs of ``job`` and what it returned."""
    times, value = [], 0
    for _ in range(repeat):
        began = time.perf_counter()
        value = job()
        times.append(time.perf_counter() - began)
    return min(times), value


def _transitions(results: list) -> int:
    return sum(result.transitions for result in results)


def _row(label: str, size: int, seconds: float, transitions: int) -> None:
    rate = transitions / seconds if seconds else 0.0
    print(f"{label:<28} {size / 1e3:>9.1f} kB {transitions:>8} {seconds:>8.3f} s {rate:>9.0f}/s")


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, nargs="+", default=[1, 10, 100], metavar="K")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--real", metavar="DIR", help="also time the .fbl files under DIR")
    parser.add_argument("--smoke", action="store_true", help="K = 1, 3; one repeat")
    args = parser.parse_args()
    if args.smoke:
        args.runs, args.repeat = [1, 3], 1
    with tempfile.TemporaryDirectory(prefix="btlog-logs-") as scratch:
        folder = Path(scratch)
        run = _run(folder)
        print(f"{'log (runs of the stand-in)':<28} {'size':>12} {'changes':>8} {'import':>10}")
        for times in args.runs:
            fbl = make_fbl(run, times, folder / f"run{times}.fbl")
            out = folder / f"fbl{times}.mcap"
            seconds, count = best(args.repeat, lambda: import_fbl(fbl, out).transitions)  # noqa: B023
            _row(f".fbl x{times}", _size(fbl), seconds, count)
            messages = nav2_messages([run] * times, uids=False)
            write_sqlite_bag(folder / f"humble{times}", messages, {NAV2_LOG: HUMBLE})
            bag = folder / f"humble{times}"
            seconds, count = best(
                args.repeat,
                lambda: _transitions(import_bag(bag, folder / "sq.mcap", STAND_IN)),  # noqa: B023
            )
            _row(f"SQLite bag x{times} (names)", _size(bag), seconds, count)
            mcap = folder / f"jazzy{times}.mcap"
            write_nav2_bag(mcap, [run] * times)
            seconds, count = best(
                args.repeat,
                lambda: _transitions(import_bag(mcap, folder / "mc.mcap", STAND_IN)),  # noqa: B023
            )
            _row(f"MCAP bag x{times} (uids)", _size(mcap), seconds, count)
        for real in sorted(Path(args.real).rglob("*.fbl")) if args.real else []:
            out = folder / "real.mcap"
            seconds, count = best(args.repeat, lambda: import_fbl(real, out).transitions)  # noqa: B023
            _row(f"real {real.name}", _size(real), seconds, count)


if __name__ == "__main__":
    main()

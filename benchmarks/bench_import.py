"""BT.CPP FileLogger2 import and export: transitions per second.

A ``.btlog`` of N transitions (default 2,000,000) is made from the kitting run in
``recordings/`` (exported once, its 249 transitions repeated with their times shifted, as a
long run of the same tree would log them). Then, best of ``--repeat``:

1. **parse**: ``read_filelog`` and iterating its records (the floor: reading the file);
2. **import**: ``import_filelog`` into a recording (parse + tick inference + recorder);
3. **export**: ``export_filelog`` of that recording back to a ``.btlog``.

    python benchmarks/bench_import.py            # 2,000,000 transitions
    python benchmarks/bench_import.py --smoke    # 50,000 transitions, one repeat

It prints figures and the import / parse ratio; it asserts nothing.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from btlog.record.reader import open_recording
from btlog.sinks.btcpp_filelog import export_filelog
from btlog.sources.btcpp_filelog import import_filelog, read_filelog
from btlog.sources.btcpp_records import RECORD_SIZE, encode_record

KITTING = Path(__file__).resolve().parent.parent / "recordings" / "kitting-look-at-chuck-fails.mcap"


def make_log(folder: Path, transitions: int) -> Path:
    """A FileLogger2 file of ``transitions`` records: the kitting run, repeated."""
    seed = folder / "seed.btlog"
    export_filelog(open_recording(KITTING), seed)
    log = read_filelog(seed)
    head = seed.read_bytes()[: log.records_offset]
    cycle = list(log.transitions())
    span = cycle[-1][0] + 100_000
    out = bytearray(head)
    for i in range(transitions):
        t_us, uid, status = cycle[i % len(cycle)]
        out += encode_record(t_us + (i // len(cycle)) * span, uid, status)
    path = folder / "long.btlog"
    path.write_bytes(bytes(out))
    return path


def best(repeat: int, job: Callable[[], object]) -> float:
    """The best wall time of ``repeat`` runs of ``job``."""
    times = []
    for _ in range(repeat):
        began = time.perf_counter()
        job()
        times.append(time.perf_counter() - began)
    return min(times)


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--transitions", type=int, default=2_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="50,000 transitions, once")
    args = parser.parse_args()
    n, repeat = (50_000, 1) if args.smoke else (args.transitions, args.repeat)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        log = make_log(folder, n)
        recording, back = folder / "long.mcap", folder / "back.btlog"
        parse = best(repeat, lambda: sum(1 for _ in read_filelog(log).transitions()))
        imported = best(repeat, lambda: import_filelog(log, recording))
        exported = best(repeat, lambda: export_filelog(open_recording(recording), back))
        size = log.stat().st_size
        print(
            f"{n:,} transitions ({size / 1e6:.1f} MB .btlog, {RECORD_SIZE} B each), "
            f"best of {repeat}"
        )
        for label, seconds in (("parse", parse), ("import", imported), ("export", exported)):
            print(f"  {label:8s} {n / seconds:12,.0f} transitions/s   {seconds:7.2f} s")
        print(f"import / parse: {imported / parse:.1f}x the time of reading the file")
        print(f"recording: {recording.stat().st_size / n:.2f} B/transition")


if __name__ == "__main__":
    main()

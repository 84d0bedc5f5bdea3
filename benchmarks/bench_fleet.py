"""A fleet of runs: export N recorded runs to a Parquet lake, then the fleet report.

1. **Runs**: N runs recorded by the same code as ``btlog run``, seeds 1..N,
   ``--failure-rate 0.2``, in ``--jobs`` processes: nine in ten of the kitting domain
   (``trees/kitting.xml``), one in ten of the taxi domain (``trees/taxi.xml``), so the
   lake has two domain partitions.
2. **Export**: ``btlog.fleet.lake.export_runs`` (what ``btlog export --parquet`` runs),
   in the same processes, one file per run and table; runs/s.
3. **The fleet report** (``btlog fleet``'s DuckDB queries) on that lake of one file per
   run and table (once), then **compaction** (what an export does at its end: one file
   per table and partition), then the report again on the compacted lake, best of
   ``--repeat``, and over the taxi domain only (partition pruning); with ``--spark`` also
   the PySpark job in local mode on the same lake, and whether both agree.
   Beside them, the reference: the same aggregate (activations and failures per node)
   computed with the btlog read model by opening every recording with ``open_runs``
   (caches built), which is what a user without a lake would do.

    python benchmarks/bench_fleet.py                 # 10,000 runs
    python benchmarks/bench_fleet.py --runs 2000 --spark
    python benchmarks/bench_fleet.py --smoke         # 40 runs
    python benchmarks/bench_fleet.py --recordings DIR   # reuse (or keep) DIR's recordings

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from btlog.fleet.compact import compact_lake
from btlog.fleet.lake import export_runs
from btlog.fleet.report import duckdb_report
from btlog.runner import RunConfig, execute

ROOT = Path(__file__).resolve().parent.parent
KITTING = str(ROOT / "trees" / "kitting.xml")
TAXI = str(ROOT / "trees" / "taxi.xml")


def _make_and_export(job: tuple[list[int], str, str]) -> tuple[float, float]:
    """Record the runs of ``seeds`` into ``folder`` and export them into ``lake``;
    returns (seconds recording, seconds exporting)."""
    seeds, folder, lake = job
    started = time.perf_counter()
    paths = []
    for seed in seeds:
        path = Path(folder) / f"run-{seed}.mcap"
        if not path.is_file():
            tree, domain = (TAXI, "taxi") if seed % 10 == 0 else (KITTING, "kitting")
            config = RunConfig(tree=tree, domain=domain, seed=seed, failure_rate=0.2)
            execute(config, path)
        paths.append(path)
    recorded = time.perf_counter()
    export_runs(paths, lake, compact=False)  # the processes share the lake: compact once
    return recorded - started, time.perf_counter() - recorded


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--spark", action="store_true", help="also time the PySpark job")
    parser.add_argument("--reference", type=int, default=200, help="runs for the reference")
    parser.add_argument("--smoke", action="store_true", help="40 runs, one repeat")
    parser.add_argument("--keep", metavar="DIR", help="work in DIR and keep the lake")
    parser.add_argument(
        "--recordings", metavar="DIR", help="recordings folder (reused: only missing runs made)"
    )
    args = parser.parse_args()
    if args.smoke:
        args.runs, args.repeat, args.reference = 40, 1, 10
    if args.keep:
        measure(args, Path(args.keep))
    else:  # removed afterwards
        with tempfile.TemporaryDirectory(prefix="btlog-fleet-") as work:
            measure(args, Path(work))


def measure(args: argparse.Namespace, work: Path) -> None:
    """Make the runs and the lake in ``work`` and print the figures."""
    os.environ.setdefault("BTLOG_CACHE_DIR", str(work / "cache"))
    folder, lake = Path(args.recordings) if args.recordings else work / "runs", work / "lake"
    folder.mkdir(parents=True, exist_ok=True)
    if lake.exists():
        raise SystemExit(f"{lake} exists: give a fresh --keep folder")

    seeds = list(range(1, args.runs + 1))
    chunks = [seeds[i :: args.jobs * 8] for i in range(args.jobs * 8)]
    started = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        spent = list(pool.map(_make_and_export, [(c, str(folder), str(lake)) for c in chunks]))
    wall = time.perf_counter() - started
    recording = sum(s[0] for s in spent)
    exporting = sum(s[1] for s in spent)
    print(f"runs: {args.runs} runs (kitting, taxi), {args.jobs} processes, {wall:.1f} s wall")
    # seconds summed over the processes (wall time inside each; recordings found are reused)
    print(f"  recording {recording:.1f} s in the processes")
    per_run = exporting / args.runs * 1e3
    print(f"  export    {exporting:.1f} s in the processes ({per_run:.0f} ms/run)")
    print(f"  lake, one file per run and table: {_files(lake)}")

    loose = _timed(lambda: duckdb_report(str(lake)))
    print(f"fleet report (DuckDB), one file per run and table: {loose:.2f} s")
    merged = _timed(lambda: compact_lake(lake))
    print(f"compaction: {merged:.2f} s; lake: {_files(lake)}")
    best = min(_timed(lambda: duckdb_report(str(lake))) for _ in range(args.repeat))
    report = duckdb_report(str(lake))
    print(
        f"fleet report (DuckDB), compacted, all {report.runs} runs: {best:.2f} s "
        f"(best of {args.repeat}) -> {loose / best:.1f}x faster than one file per run"
    )
    one = min(_timed(lambda: duckdb_report(str(lake), domain="taxi")) for _ in range(args.repeat))
    taxi = duckdb_report(str(lake), domain="taxi").runs
    print(f"fleet report, domain=taxi only ({taxi} runs): {one:.2f} s")

    sample = sorted(folder.glob("run-*.mcap"))[: args.reference]
    if sample:
        ref = _timed(lambda: _reference(sample))
        per_run_lake = best / report.runs
        per_run_ref = ref / len(sample)
        print(
            f"reference: open_runs over {len(sample)} recordings + the same aggregate: "
            f"{ref:.2f} s ({per_run_ref * 1e3:.1f} ms/run) -> lake "
            f"{per_run_ref / per_run_lake:.0f}x faster per run"
        )
    if args.spark:
        from btlog.fleet.spark import spark_report

        spark_started = time.perf_counter()
        theirs = spark_report(str(lake))
        spark_s = time.perf_counter() - spark_started
        agree = theirs.to_json() == report.to_json()
        print(f"fleet report (Spark local): {spark_s:.1f} s; same numbers as DuckDB: {agree}")


def _files(lake: Path) -> str:
    files = list(lake.rglob("*.parquet"))
    size = sum(f.stat().st_size for f in files)
    return f"{len(files)} files, {size / 1e6:.1f} MB"


def _reference(paths: list[Path]) -> int:
    from btlog.replay.database import open_runs

    with open_runs(*paths) as database:
        _, rows = database.sql(
            "SELECT n.path, count(*) FILTER (WHERE t.status = 'FAILURE') FROM transitions t "
            "JOIN nodes n USING (run_id, uid) GROUP BY ALL"
        )
    return len(rows)


def _timed(action) -> float:
    started = time.perf_counter()
    action()
    return time.perf_counter() - started


if __name__ == "__main__":
    main()

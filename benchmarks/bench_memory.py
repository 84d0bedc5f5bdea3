"""Memory of the read model on a run with one large blackboard value (issue 14, item 1).

A Script builds a string of ``--value-mb`` MiB once, then ``Repeat(-1)`` runs a Parallel
of 47 actions (``default: {status: SUCCESS, ticks: 1}``) for ``--ticks`` ticks: about 144
events a tick. The benchmark records it with ``btlog run``, then measures the peak RSS of
the first ``btlog sql`` on it (which builds the cache: tables and snapshots) and of a
second one (cache reused), each in its own process, and the same for a run without the
large value (the reference). It prints the cache's size per event.

    python benchmarks/bench_memory.py                 # 10 MiB value, 7,000 ticks (~1M events)
    python benchmarks/bench_memory.py --smoke         # 1 MiB value, 300 ticks
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ACTIONS = 47


def tree_xml(value_mib: float) -> str:
    """The benchmark tree: a value of ``value_mib`` MiB, then the endless Parallel."""
    doublings = 0
    while 1024 * 2**doublings < value_mib * (1 << 20):
        doublings += 1
    build = "v := &apos;" + "x" * 1024 + "&apos;" + "; v := v..v" * doublings
    actions = "".join(f'<Action ID="Work" name="a{i}"/>' for i in range(ACTIONS))
    script = f'<Script code="{build}"/>' if value_mib > 0 else ""
    return f"""<root BTCPP_format="4"><BehaviorTree ID="MainTree"><Sequence>
  {script}
  <Repeat num_cycles="-1"><Parallel success_count="-1" failure_count="1">{actions}</Parallel>
  </Repeat></Sequence></BehaviorTree></root>"""


def btlog(*args: str, env: dict[str, str]) -> tuple[float, int]:
    """Run ``btlog ARGS`` in a child process; (seconds, its peak RSS in bytes)."""
    started = time.perf_counter()
    child = subprocess.Popen(
        [sys.executable, "-m", "btlog.cli.main", *args],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    _pid, status, usage = os.wait4(child.pid, 0)
    if status != 0:
        raise SystemExit(f"btlog {args[0]} failed: {child.stderr.read().decode()[-500:]}")
    child.stderr.close()
    return time.perf_counter() - started, usage.ru_maxrss * 1024


def measure(folder: Path, value_mib: float, ticks: int, env: dict[str, str]) -> dict:
    """Record one run; measure two ``btlog sql`` on it, then the first ``btlog ask``."""
    tree = folder / f"tree-{value_mib}.xml"
    tree.write_text(tree_xml(value_mib))
    outcomes = folder / "outcomes.yaml"
    outcomes.write_text("default: {status: SUCCESS, ticks: 1}\n")
    recording = folder / f"run-{value_mib}.mcap"
    run_args = ("run", str(tree), "--outcomes", str(outcomes), "--max-ticks", str(ticks))
    run_seconds, run_rss = btlog(*run_args, "-o", str(recording), "--quiet", env=env)
    query = "SELECT count(*) FROM transitions"
    first, first_rss = btlog("sql", str(recording), query, env=env)
    second, second_rss = btlog("sql", str(recording), query, env=env)
    # the first state asked for builds the snapshots (a file beside the cache)
    ask, ask_rss = btlog("ask", str(recording), "--at", "end", "What are you doing?", env=env)
    cache_dir = Path(env["BTLOG_CACHE_DIR"])
    # the snapshots are built a segment at a time: NAME.N.snapshots.duckdb beside NAME.duckdb
    newest = max(
        (p for p in cache_dir.glob("*.duckdb") if not p.name.endswith(".snapshots.duckdb")),
        key=lambda p: p.stat().st_mtime_ns,
    )
    segments = sorted(cache_dir.glob(newest.name.replace(".duckdb", ".*.snapshots.duckdb")))
    assert segments, f"no snapshots beside {newest}"
    # the status changes: NAME.transitions.N.parquet beside NAME.duckdb (none before them)
    parquet = sorted(cache_dir.glob(newest.name.replace(".duckdb", ".transitions.*.parquet")))
    import duckdb

    with duckdb.connect(str(newest), read_only=True) as con:
        (events,) = con.execute("SELECT events FROM _ingest").fetchone()
    state_bytes = 0
    for segment in segments:
        with duckdb.connect(str(segment), read_only=True) as con:
            (size,) = con.execute("SELECT sum(strlen(state::VARCHAR)) FROM _snapshots").fetchone()
            state_bytes += size or 0
    return {
        "events": events,
        "file_mb": recording.stat().st_size / 1e6,
        "run": (run_seconds, run_rss),
        "first": (first, first_rss),
        "second": (second, second_rss),
        "ask": (ask, ask_rss),
        "cache_bytes": sum(p.stat().st_size for p in [newest, *segments, *parquet]),
        "parquet_bytes": sum(p.stat().st_size for p in parquet),
        "state_bytes": state_bytes,
    }


def report(label: str, figures: dict) -> None:
    """Print one run's figures."""
    events = figures["events"]
    print(f"{label}: {events:,} events, recording {figures['file_mb']:.1f} MB")
    name = {
        "run": "btlog run",
        "first": "first btlog sql",
        "second": "second btlog sql",
        "ask": "first btlog ask",
    }
    for key in name:
        seconds, rss = figures[key]
        print(f"  {name[key]:<18} {seconds:6.1f} s   peak RSS {rss / 1e6:8.0f} MB")
    print(
        f"  cache {figures['cache_bytes'] / 1e6:.1f} MB = "
        f"{figures['cache_bytes'] / max(events, 1):.1f} bytes/event (of which transitions "
        f"Parquet {figures['parquet_bytes'] / 1e6:.1f} MB); snapshot states "
        f"{figures['state_bytes'] / 1e6:.2f} MB in all"
    )


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--value-mb", type=float, default=10.0, help="MiB of the large value")
    parser.add_argument("--ticks", type=int, default=7000)
    parser.add_argument("--smoke", action="store_true", help="1 MiB, 300 ticks")
    args = parser.parse_args()
    value, ticks = (1.0, 300) if args.smoke else (args.value_mb, args.ticks)
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory(prefix="bench-memory-") as name:
        folder = Path(name)
        env = {
            **os.environ,
            "PYTHONPATH": str(ROOT / "src"),
            "BTLOG_CACHE_DIR": str(folder / "cache"),
        }
        large = measure(folder, value, ticks, env)
        report(f"{value:g} MiB value", large)
        plain = measure(folder, 0, ticks, env)
        report("no large value (reference)", plain)
        ratio = large["first"][1] / plain["first"][1]
        print(f"first btlog sql peak RSS, large value / reference: {ratio:.2f}x")


if __name__ == "__main__":
    main()

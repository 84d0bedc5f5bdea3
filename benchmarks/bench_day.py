"""A robot's day (issue 27): a ~100M-event run recorded, then its first answers, end to end.

Everything goes through the public command line, each command in its own process, so
each figure is what a user meets: wall seconds and the process's peak resident memory
(``wait4``'s ``ru_maxrss``).

1. **Recording**: ``btlog run`` of a Parallel of ``--actions`` actions (each succeeds
   after one tick) inside ``Repeat``, ticked until about ``--events`` events are written
   (≈ 3 events an action a tick). Its rate and memory show whether recording stays flat.
2. **First answers on the fresh recording** (empty cache): ``btlog ask --at end "What
   are you doing?"`` (builds the cache), then a history question (``When did a7 last
   fail?``: it never did, so the whole history is read), then ``btlog explain`` (the
   story of the whole run), each the first of its kind; then a warm ``ask``; then the
   history question and ``explain`` again, each as the first command on the fresh
   recording (the cache removed before each: it builds the cache). The same
   first ``ask`` on a 10-tick recording of the same tree gives the fixed cost (start-up,
   imports), and the events a second beyond it.
3. **The reference**: DuckDB's own load of the same rows (``transitions``,
   ``blackboard``, ``ticks``, copied from the cache to Parquet beforehand) into a DuckDB
   file (as btlog's cache is), then into memory, each in a process of its own with
   DuckDB's default settings. Each first answer is printed with its ratio to the faster
   of the two.
4. **Sizes**: the recording, the cache (tables and snapshots) and their ratio.
5. **Importing the day** (``--import``): the run exported as BT.CPP's FileLogger2
   (``btlog export --to btlog``), imported back (``btlog import``), and recorded live
   (``btlog attach --poll 0.0001``) from a Groot2 publisher that replays that file as fast
   as it is polled (``groot2_replay.py``, in a process of its own, 999 transitions a
   poll); each with its rate (transitions a second of wall time and of its own CPU time:
   the second depends less on what else the machine runs) and peak RSS, to show whether
   they stay flat.

    python benchmarks/bench_day.py                     # ~100M events (minutes; GBs of disk)
    python benchmarks/bench_day.py --events 10000000 --import
    python benchmarks/bench_day.py --smoke             # ~50k events, seconds (CI; all steps)

It prints figures; it asserts nothing but that every command succeeds.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent.parent
#: Events a tick of the benchmark's tree, per action (IDLE→RUNNING, RUNNING→SUCCESS,
#: SUCCESS→IDLE), near enough to choose the tick count.
EVENTS_PER_ACTION = 3.07
HISTORY_QUESTION = "When did a7 last fail?"
REFERENCE = """
import sys, duckdb
con = duckdb.connect(sys.argv[2])
con.execute("SET enable_progress_bar = false")
for name in sys.argv[3:]:
    con.execute(f"CREATE TABLE {name} AS FROM read_parquet('{sys.argv[1]}.{name}.parquet')")
con.close()
"""
EXPORT = """
import sys, duckdb
con = duckdb.connect(sys.argv[1], read_only=True)
con.execute("SET enable_progress_bar = false")
for name in sys.argv[3:]:
    con.execute(f"COPY {name} TO '{sys.argv[2]}.{name}.parquet' (FORMAT parquet)")
print(sum(con.execute(f"SELECT count(*) FROM {name}").fetchone()[0] for name in sys.argv[3:]))
"""
TABLES = ("transitions", "blackboard", "ticks")
#: ``attach --timeout``: the attach ends this long after the publisher's last reply.
ATTACH_TIMEOUT = 0.5


def tree_xml(actions: int) -> str:
    """The benchmark tree: ``Repeat`` forever over a Parallel of ``actions`` actions."""
    children = "".join(f'<Action ID="Work" name="a{i}"/>' for i in range(actions))
    return (
        '<root BTCPP_format="4"><BehaviorTree ID="MainTree"><Repeat num_cycles="-1">'
        f'<Parallel success_count="-1" failure_count="1">{children}</Parallel>'
        "</Repeat></BehaviorTree></root>"
    )


class Measured(NamedTuple):
    """A child process's wall seconds, peak RSS (bytes), stdout and CPU seconds."""

    seconds: float
    rss: int
    out: str
    cpu: float


def measured(args: list[str], env: dict[str, str]) -> Measured:
    """Run ``args`` in a child process and measure it (exit on failure)."""
    started = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        child = subprocess.Popen(args, env=env, stdout=out, stderr=err)
        _pid, status, usage = os.wait4(child.pid, 0)
        seconds = time.perf_counter() - started
        err.seek(0)
        if status != 0:
            raise SystemExit(f"{' '.join(args[:4])}… failed: {err.read().decode()[-800:]}")
        out.seek(0)
        cpu = usage.ru_utime + usage.ru_stime
        return Measured(seconds, usage.ru_maxrss * 1024, out.read().decode(), cpu)


def btlog(*args: str, env: dict[str, str]) -> Measured:
    """One ``btlog`` command in a child process (see ``measured``)."""
    return measured([sys.executable, "-m", "btlog.cli.main", *args], env)


def record(folder: Path, name: str, actions: int, ticks: int, env: dict[str, str]) -> tuple:
    """``btlog run`` of the benchmark tree for ``ticks`` ticks: (path, seconds, rss, events)."""
    tree = folder / "tree.xml"
    tree.write_text(tree_xml(actions))
    outcomes = folder / "outcomes.yaml"
    outcomes.write_text("default: {status: SUCCESS, ticks: 1}\n")
    path = folder / name
    seconds, rss, out, _cpu = btlog(
        "run", str(tree), "--outcomes", str(outcomes), "--max-ticks", str(ticks),
        "-o", str(path), env=env,
    )  # fmt: skip
    events = next(int(line.split()[1]) for line in out.splitlines() if line.startswith("events:"))
    return path, seconds, rss, events


def cache_files(cache: Path) -> list[Path]:
    """The finished cache files (tables, their transitions files, snapshots) of the
    cache folder."""
    return [
        p for p in (*cache.glob("*.duckdb"), *cache.glob("*.parquet")) if not p.name.startswith(".")
    ]


def reference(cache: Path, folder: Path, env: dict[str, str]) -> list[tuple[str, float, int, int]]:
    """DuckDB loading the run's rows from Parquet into a DuckDB file, then into memory:
    (where, seconds, rss, rows) of each."""
    tables = min(
        (
            p
            for p in cache_files(cache)
            if p.suffix == ".duckdb" and not p.name.endswith(".snapshots.duckdb")
        ),
        key=lambda p: -p.stat().st_mtime_ns,
    )
    target = folder / "reference.duckdb"
    _s, _r, rows, _c = measured(
        [sys.executable, "-c", EXPORT, str(tables), str(target), *TABLES], env
    )
    found = []
    for where in (str(target), ":memory:"):
        seconds, rss, _out, _cpu = measured(
            [sys.executable, "-c", REFERENCE, str(target), where, *TABLES], env
        )
        found.append(("a file" if where != ":memory:" else "memory", seconds, rss, int(rows)))
    for leftover in folder.glob("reference.duckdb*"):
        leftover.unlink()
    return found


def imported(folder: Path, recording: Path, env: dict[str, str]) -> None:
    """Step 5: export the run as a ``.btlog``, import it, attach to a publisher replaying
    it; print each figure, then delete the files."""
    log = folder / "day.btlog"
    back, live = folder / "day.imported.mcap", folder / "day.attached.mcap"
    exported = btlog("export", str(recording), str(log), "--to", "btlog", env=env)
    print(
        f"importing the day (the run as a FileLogger2 .btlog, {log.stat().st_size / 1e6:.0f} MB):"
    )
    line("btlog export --to btlog", exported[0], exported[1])
    took, rss, out, cpu = btlog("import", str(log), "-o", str(back), env=env)
    count = int(re.search(r": (\d+) transitions", out)[1])  # type: ignore[index]
    line(f"btlog import ({count / took / 1e6:.2f}M/s, {count / cpu / 1e6:.2f}M/CPU-s)", took, rss)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    replay = [sys.executable, str(ROOT / "benchmarks" / "groot2_replay.py"), str(log), str(port)]
    publisher = subprocess.Popen(replay, env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert publisher.stdout is not None and publisher.stdout.readline().strip() == "ready"
        took, rss, out, cpu = btlog(
            "attach", f"tcp://127.0.0.1:{port}", "-o", str(live), "--poll", "0.0001",
            "--timeout", str(ATTACH_TIMEOUT), "--reconnect", "0", env=env,
        )  # fmt: skip
    finally:
        publisher.kill()
        publisher.wait()
    live_count = int(re.search(r": (\d+) transitions", out)[1])  # type: ignore[index]
    if live_count != count:
        raise SystemExit(f"attach recorded {live_count:,} transitions of {count:,}")
    rate = count / max(took - ATTACH_TIMEOUT, 1e-9) / 1e6
    line(f"btlog attach ({rate:.2f}M/s, {count / cpu / 1e6:.2f}M/CPU-s)", took, rss)
    for path in (log, back, live):
        path.unlink()


def line(label: str, seconds: float, rss: int, reference_seconds: float | None = None) -> None:
    """Print one figure (and its ratio to the reference load, the faster of the two)."""
    ratio = "" if reference_seconds is None else f"   {seconds / reference_seconds:5.2f}x DuckDB"
    print(f"  {label:<50} {seconds:7.2f} s   peak RSS {rss / 1e6:7.0f} MB{ratio}")


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--events", type=int, default=100_000_000)
    parser.add_argument("--actions", type=int, default=60)
    parser.add_argument(
        "--import",
        dest="imports",
        action="store_true",
        help="also export the run as a FileLogger2 .btlog, import it and attach to it replayed",
    )
    parser.add_argument("--smoke", action="store_true", help="about 50,000 events, every step")
    parser.add_argument("--keep", type=Path, help="keep the recording and caches in this folder")
    parser.add_argument(
        "--reuse", action="store_true", help="with --keep: reuse the recording made before"
    )
    args = parser.parse_args()
    events = 50_000 if args.smoke else args.events
    ticks = max(10, round(events / (args.actions * EVENTS_PER_ACTION)))
    print(
        f"machine: {os.cpu_count()} CPUs, load average "
        f"{', '.join(f'{x:.2f}' for x in os.getloadavg())} (shared with other jobs)"
    )
    with tempfile.TemporaryDirectory(prefix="bench-day-") as name:
        folder = args.keep or Path(name)
        folder.mkdir(parents=True, exist_ok=True)
        cache = folder / "cache"
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "BTLOG_CACHE_DIR": str(cache)}
        small, *_ = record(folder, "small.mcap", args.actions, 10, env)
        fixed, *_ = btlog("ask", str(small), "--at", "end", "What are you doing?", env=env)

        saved = folder / "day.events"
        if args.reuse and saved.is_file():
            path, seconds, rss, events = folder / "day.mcap", 0.0, 0, int(saved.read_text())
        else:
            path, seconds, rss, events = record(folder, "day.mcap", args.actions, ticks, env)
            saved.write_text(str(events))
        size = path.stat().st_size
        print(
            f"recording: {events:,} events ({ticks:,} ticks of a {args.actions}-action "
            f"Parallel), {size / 1e6:.0f} MB = {size / events:.2f} B/event"
        )
        if seconds:
            line(f"btlog run ({events / seconds / 1e6:.2f}M events/s)", seconds, rss)

        for old in cache_files(cache):
            old.unlink()
        ask = ("ask", str(path), "--at", "end", "What are you doing?")
        first = btlog(*ask, env=env)
        references = reference(cache, folder, env)
        print(f"first answers on the fresh recording (fixed cost of a first ask: {fixed:.2f} s):")
        for where, took, memory, rows in references:
            line(f"DuckDB: {rows:,} rows from Parquet into {where}", took, memory)
        ref_seconds = min(took for _where, took, _memory, _rows in references)
        beyond = events / max(first[0] - fixed, 1e-9) / 1e6
        line(f"first ask ({beyond:.1f}M events/s beyond)", first[0], first[1], ref_seconds)
        history = btlog("ask", str(path), "--at", "end", HISTORY_QUESTION, env=env)
        line(f"first history ({HISTORY_QUESTION})", history[0], history[1], ref_seconds)
        story = btlog("explain", str(path), env=env)
        story_lines = len(story[2].splitlines())
        line(f"explain, the story ({story_lines} lines)", story[0], story[1], ref_seconds)
        warm = btlog(*ask, env=env)
        line("warm ask", warm[0], warm[1])
        print("each the first command on the fresh recording (it builds the cache):")
        for old in cache_files(cache):
            old.unlink()
        cold_history = btlog("ask", str(path), "--at", "end", HISTORY_QUESTION, env=env)
        line("first history", cold_history[0], cold_history[1], ref_seconds)
        for old in cache_files(cache):
            old.unlink()
        cold_story = btlog("explain", str(path), env=env)
        line("explain", cold_story[0], cold_story[1], ref_seconds)
        peak = max(rss, first[1], history[1], story[1], warm[1], cold_history[1], cold_story[1])
        print(f"  peak RSS of any btlog command: {peak / 1e6:.0f} MB")
        cached = sum(p.stat().st_size for p in cache_files(cache))
        print(
            f"cache: {cached / 1e6:.0f} MB = {cached / size:.2f}x the recording "
            f"({cached / events:.2f} B/event)"
        )
        print(f"answer: {first[2].strip()[:200]}")
        if args.imports or args.smoke:
            imported(folder, path, env)


if __name__ == "__main__":
    main()

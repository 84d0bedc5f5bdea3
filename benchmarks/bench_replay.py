"""Replay into DuckDB: ingestion speed, snapshot build time, and the state at a moment.

1. **A recording of N events** (default 10M). A workload tree (below) is run once by the
   executor with scripted outcomes until its root completes; that cycle of events —
   status changes of ~30 nodes, blackboard writes by Script nodes, one tick record per
   tick — is then fed to the ``Recorder`` over and over (seq, time and tick shifted)
   until N events are written. The file is exactly what a long run of the tree records.
2. **Ingestion** (``btlog.replay.ingest.load_tables``), best of ``--repeat``: the tables
   into an in-memory database; events/s. Beside it, **DuckDB's own read of the same
   rows** from Parquet: the ingested ``transitions``, ``blackboard`` and ``ticks`` are
   written to Parquet files and ``CREATE TABLE … AS SELECT * FROM read_parquet(…)`` is
   timed; the ratio shows what decoding the MCAP costs on top of DuckDB's own loading.
3. **The first ``btlog sql`` and ``btlog ask``** on the fresh recording, end to end (a
   new process, the cache built, one answer), as a user meets them, the fixed cost of a
   first query (a tiny recording) and a warm ``btlog ask``. **The first open**
   (``open_runs``, cache built): the tables, written to the cache file; the snapshots
   (SQL over the tables, a snapshot every K events), built on the first state asked for;
   and a second open (cache used).
4. **The state at a moment**: ``Run.state_at("seq:N")`` at ``--moments`` random N in the
   first 10% and in the last 10% of the run; median and p90 latency (ms), cold (a fresh
   ``Run`` per figure, so its small block cache starts empty).
5. ``--sweep``: state latency and snapshot build time for several K on the same run,
   the measurement behind ``DEFAULT_SNAPSHOT_EVERY``.

    python benchmarks/bench_replay.py              # 10,000,000 events
    python benchmarks/bench_replay.py --smoke      # 200,000 events, one repeat
    python benchmarks/bench_replay.py --events 2000000 --sweep

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import compileall
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import duckdb

import btlog
from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import EventLog, StatusChange, TickRecord, TreeMutation
from btlog.executor.engine import Executor
from btlog.record.recorder import Recorder
from btlog.replay import ingest
from btlog.replay.database import open_runs
from btlog.replay.tables import create_schema
from btlog.status import FAILURE, SUCCESS
from btlog.tree.loader import load_tree_text

#: A pick-and-place loop: conditions that fail and fall back, a retry, actions that run
#: for a few ticks, and Script nodes writing the blackboard.
WORKLOAD = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence name="kit parts">
      <Script code="cycle := cycle + 1"/>
      <SubTree ID="Fetch" part="{part}" _autoremap="true"/>
      <SubTree ID="Fetch" part="{part}" _autoremap="true"/>
      <Fallback name="inspect">
        <Condition ID="part ok" name="part ok"/>
        <Action ID="rework" name="rework part"/>
      </Fallback>
      <Script code="done := cycle"/>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Fetch">
    <Sequence name="fetch part">
      <Fallback name="find part">
        <Condition ID="part visible" name="part visible"/>
        <Action ID="look around" name="look around"/>
      </Fallback>
      <RetryUntilSuccessful num_attempts="3">
        <Action ID="grasp" name="grasp part"/>
      </RetryUntilSuccessful>
      <Script code="part := 'gear'"/>
      <Action ID="move" name="move to tray"/>
      <Action ID="place" name="place part"/>
    </Sequence>
  </BehaviorTree>
</root>"""
OUTCOMES = {
    "default": {"status": "SUCCESS", "ticks": 1},
    "nodes": {
        "part visible": ["FAILURE", "SUCCESS"],
        "grasp part": [{"status": "FAILURE", "ticks": 2}, "SUCCESS"],
        "move to tray": {"status": "SUCCESS", "ticks": 3},
        "part ok": ["SUCCESS", "SUCCESS", "FAILURE"],
    },
}


def workload_cycle() -> tuple[object, list, list[TickRecord]]:
    """(tree, events, ticks) of one run of the workload tree, root start to completion."""
    tree = load_tree_text(WORKLOAD)
    executor = Executor(
        tree, leaf_factory=scripted_leaf_factory(tree, Outcomes.from_mapping(OUTCOMES))
    )
    executor.root_board.entries["cycle"] = 0
    log = EventLog()
    executor.subscribe(log)
    while executor.tick() not in (SUCCESS, FAILURE):
        pass
    return tree, log.events, log.ticks


def write_recording(path: Path, events: int, run: tuple | None = None) -> tuple[int, int]:
    """Record ``events`` events of the repeated workload (or of ``run``, a
    ``workload_cycle``-like (tree, events, ticks)); returns (events, ticks)."""
    tree, cycle, ticks = run if run is not None else workload_cycle()
    recorder = Recorder(path, tree, {"domain": "benchmark", "seed": 0})
    on_status, on_write, on_tick = recorder.on_status, recorder.on_write, recorder.on_tick
    span = ticks[-1].end_ns + 100_000_000
    written, repetition, last_tick = 0, 0, 0
    while written < events:
        base_seq, base_t, base_tick = (
            repetition * len(cycle),
            repetition * span,
            repetition * len(ticks),
        )
        position = 0
        for record in ticks:
            tick = record.tick
            while position < len(cycle) and cycle[position].tick <= tick:
                event = cycle[position]
                if type(event) is StatusChange:
                    seq, t, _tick, uid, prev, status = event
                    on_status(seq + base_seq, t + base_t, tick + base_tick, uid, prev, status)
                elif not isinstance(event, TreeMutation):
                    seq, t, _tick, scope, key, value, kind, writer = event
                    on_write(
                        seq + base_seq,
                        t + base_t,
                        tick + base_tick,
                        scope,
                        key,
                        value,
                        kind,
                        writer,
                    )
                position += 1
            last_tick = tick + base_tick
            on_tick(
                TickRecord(
                    last_tick, record.start_ns + base_t, record.end_ns + base_t, record.root_status
                )
            )
        written += len(cycle)
        repetition += 1
    recorder.close()
    return written, last_tick


def best(run: Callable[[], object], repeat: int) -> tuple[float, object]:
    """(best wall seconds, the last result) of ``repeat`` runs."""
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return min(times), result


def btlog_seconds(cache_home: Path, *args: str) -> float:
    """Wall seconds of one ``btlog`` command in a new process (caches in ``cache_home``)."""
    env = {**os.environ, "XDG_CACHE_HOME": str(cache_home)}
    start = time.perf_counter()
    command = [sys.executable, "-m", "btlog.cli.main", *args]
    subprocess.run(command, env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def first_answers(path: Path, folder: Path, events: int) -> None:
    """Print the first ``btlog sql`` and ``btlog ask`` on the fresh recording, end to end
    (a new process, the read model built, one answer), then warm, as a user meets them;
    and the fixed cost of a first query (the same on a 1-event-cycle recording).

    btlog's modules are compiled first, as ``pip install`` does: run from a checkout with
    ``PYTHONDONTWRITEBYTECODE`` set, every command would compile them again (~0.15 s).
    """
    compileall.compile_dir(Path(btlog.__file__).parent, quiet=1)
    query = ("sql", str(path), "SELECT count(*) FROM transitions")
    ask = ("ask", str(path), "--at", "end", "What are you doing?")
    sql_first = btlog_seconds(folder / "xdg-sql", *query)
    ask_then = btlog_seconds(folder / "xdg-sql", *ask)
    ask_warm = btlog_seconds(folder / "xdg-sql", *ask)
    ask_first = btlog_seconds(folder / "xdg-ask", *ask)
    small = folder / "small.mcap"
    write_recording(small, 1)
    fixed = btlog_seconds(folder / "xdg-small", "sql", str(small), query[2])
    print(
        f"first `btlog sql` on the fresh recording (end to end, cache built): "
        f"{sql_first:.2f} s = {events / sql_first:,.0f} events/s; fixed cost of a first "
        f"query (a {small.stat().st_size / 1e3:.0f} KB recording) {fixed:.2f} s; beyond it "
        f"{events / max(sql_first - fixed, 1e-9):,.0f} events/s"
    )
    print(
        f"first `btlog ask --at end` on the fresh recording: {ask_first:.2f} s "
        f"({events / max(ask_first - fixed, 1e-9):,.0f} events/s beyond the fixed cost); "
        f"after the first `btlog sql` (snapshots built): {ask_then:.2f} s; warm: {ask_warm:.2f} s"
    )


def ingest_in_memory(path: Path) -> ingest.IngestReport:
    """The tables only (no snapshots), into an in-memory database."""
    con = duckdb.connect()
    create_schema(con)
    try:
        return ingest.load_tables(con, path)
    finally:
        con.close()


def parquet_read(path: Path, folder: Path, repeat: int) -> tuple[float, int]:
    """(best seconds, rows) for DuckDB loading the same rows from Parquet files."""
    con = duckdb.connect()
    create_schema(con)
    ingest.load_tables(con, path)
    files = []
    for table in ("transitions", "blackboard", "ticks"):
        target = folder / f"{table}.parquet"
        con.execute(f"COPY {table} TO '{target}' (FORMAT parquet)")
        files.append((table, target))
    (rows,) = con.execute(
        "SELECT (SELECT count(*) FROM transitions) + "
        "(SELECT count(*) FROM blackboard) + "
        "(SELECT count(*) FROM ticks)"
    ).fetchall()[0]
    con.close()

    def load() -> None:
        fresh = duckdb.connect()
        for table, target in files:
            fresh.execute(
                f"CREATE TABLE {table} AS SELECT * FROM read_parquet($path)", {"path": str(target)}
            )
        fresh.close()

    seconds, _ = best(load, repeat)
    return seconds, rows


def latencies(run, lo: int, hi: int, count: int, seed: int) -> list[float]:
    """Milliseconds of ``state_at("seq:N")`` for ``count`` random N in [lo, hi)."""
    rng = random.Random(seed)
    found = []
    for _ in range(count):
        seq = rng.randrange(lo, hi)
        start = time.perf_counter()
        run.state_at(f"seq:{seq}")
        found.append((time.perf_counter() - start) * 1000)
    return found


def summary(values: list[float]) -> str:
    values = sorted(values)
    p90 = values[min(len(values) - 1, int(len(values) * 0.9))]
    return f"median {statistics.median(values):6.2f} ms   p90 {p90:6.2f} ms"


def state_figures(path: Path, cache: Path, moments: int, every: int) -> tuple[float, float]:
    """Print early/late latency for snapshot interval ``every``; returns the medians."""
    with open_runs(path, snapshot_every=every, cache_dir=cache) as database:
        run = database.run()
        events = run.info.events
        tenth = max(1, events // 10)
        early = latencies(run, 0, tenth, moments, 1)
    with open_runs(path, snapshot_every=every, cache_dir=cache) as database:
        late = latencies(database.run(), events - tenth, events, moments, 2)
    print(f"    early (first 10%): {summary(early)}")
    print(f"    late  (last 10%):  {summary(late)}")
    return statistics.median(early), statistics.median(late)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=10_000_000)
    parser.add_argument("--smoke", action="store_true", help="200,000 events, one repeat")
    parser.add_argument("--repeat", type=int, default=3, help="runs per timing; best shown")
    parser.add_argument("--moments", type=int, default=200)
    parser.add_argument("--snapshot-every", type=int, default=ingest.DEFAULT_SNAPSHOT_EVERY)
    parser.add_argument(
        "--sweep", action="store_true", help="also measure K = 256 … 4096 (snapshot interval)"
    )
    args = parser.parse_args()
    events = 200_000 if args.smoke else args.events
    repeat = 1 if args.smoke else args.repeat
    print(
        f"machine: {os.cpu_count()} CPUs, load average "
        f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}; duckdb {duckdb.__version__}"
    )
    with tempfile.TemporaryDirectory(prefix="bench-replay-") as name:
        folder = Path(name)
        path = folder / "bench.mcap"
        start = time.perf_counter()
        written, ticks = write_recording(path, events)
        print(
            f"recording: {written:,} events, {ticks:,} ticks, "
            f"{path.stat().st_size / 1e6:.1f} MB, written in "
            f"{time.perf_counter() - start:.1f} s"
        )

        first_answers(path, folder, written)
        seconds, report = best(lambda: ingest_in_memory(path), repeat)
        print(
            f"ingestion, tables in memory (best of {repeat}): {seconds:.2f} s = "
            f"{report.events / seconds:,.0f} events/s  ({report.transitions:,} transitions, "
            f"{report.writes:,} writes, {report.ticks:,} ticks)"
        )
        parquet_seconds, rows = parquet_read(path, folder, repeat)
        print(
            f"DuckDB reading the same {rows:,} rows from Parquet: {parquet_seconds:.2f} s = "
            f"{rows / parquet_seconds:,.0f} rows/s; ingestion takes "
            f"{seconds / parquet_seconds:.1f}x as long"
        )

        cache = folder / "cache"
        start = time.perf_counter()
        with open_runs(path, snapshot_every=args.snapshot_every, cache_dir=cache) as database:
            built = database.ingested[0]
            total = time.perf_counter() - start
            start = time.perf_counter()
            database.run().snapshots_table()
            snapshots = time.perf_counter() - start
        rest = total - built.ingest_seconds
        size = sum(f.stat().st_size for f in cache.iterdir()) / 1e6
        print(
            f"open_runs, first open (cache built): {total:.2f} s = tables "
            f"{built.ingest_seconds:.2f} s (into the cache file) + the rest {rest:.2f} s; then the "
            f"snapshots, on the first state asked for: {snapshots:.2f} s (K = "
            f"{args.snapshot_every}); caches {size:.0f} MB"
        )
        start = time.perf_counter()
        with open_runs(path, snapshot_every=args.snapshot_every, cache_dir=cache) as database:
            assert not database.ingested
        reopen = (time.perf_counter() - start) * 1000
        print(f"open_runs, second open (cache reused): {reopen:.1f} ms")
        print(f"state at a moment, {args.moments} random moments each, K = {args.snapshot_every}:")
        early, late = state_figures(path, cache, args.moments, args.snapshot_every)
        print(f"    late / early: {late / early:.2f}")
        if args.sweep:
            for every in (256, 512, 1024, 2048, 4096):
                sweep_cache = folder / f"cache-{every}"
                with open_runs(path, snapshot_every=every, cache_dir=sweep_cache) as database:
                    start = time.perf_counter()
                    table = database.run().snapshots_table()
                    seconds = time.perf_counter() - start
                    (rows,) = database.con.execute(f"SELECT count(*) FROM {table}").fetchone()
                print(f"  K = {every}: snapshots {seconds:.2f} s, {rows:,} rows")
                state_figures(path, sweep_cache, args.moments, every)


if __name__ == "__main__":
    main()

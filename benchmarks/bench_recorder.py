"""Recorder throughput: how many events per second ``Recorder`` takes, and the file size.

The recorder is fed directly, as the executor with a simulated clock feeds it, with
synthetic ticks of ``--per-tick`` status changes (uids spread over a 200-node tree,
statuses cycling through IDLE→RUNNING→SUCCESS→IDLE) and one tick record per tick: a
batch of packed changes a tick (``on_status_batch``; ``on_status`` per change with
``--max-tick-events``, which turns batches off) + ``on_tick`` + encoding + compression +
writing, and nothing of a tree's execution. The loop that makes
the calls costs something too; it is timed alone with a no-op subscriber, and the
"recorder-only" figure subtracts it. Each chunk compression is measured in turn (lz4 only
when the ``lz4`` package is installed).

    python benchmarks/bench_recorder.py            # 2,000,000 events per compression
    python benchmarks/bench_recorder.py --smoke    # a tiny run, to check the script works

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from mcap.writer import CompressionType

from btlog.events import CHANGE, Subscriber, TickRecord
from btlog.record.recorder import Recorder
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS
from btlog.tree.model import ACTION, CONTROL, Node, Tree

CYCLE = ((IDLE, RUNNING), (RUNNING, SUCCESS), (SUCCESS, IDLE), (RUNNING, FAILURE))


def synthetic_tree(leaves: int = 200) -> Tree:
    """A Sequence root with ``leaves`` action children (uids 1..leaves+1)."""
    root = Node(uid=1, type="Sequence", name="root", kind=CONTROL, path="root")
    for uid in range(2, leaves + 2):
        child = Node(uid=uid, type="Act", name=f"a{uid}", kind=ACTION, parent=root, path=f"a{uid}")
        root.children.append(child)
    return Tree(root)


def compressions() -> list[CompressionType]:
    """The chunk compressions the installed mcap package can write."""
    found = [CompressionType.ZSTD, CompressionType.NONE]
    try:
        import lz4.frame  # noqa: F401
    except ImportError:
        return found
    return [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE]


def tick_patterns(per_tick: int, count: int = 8) -> list[list[tuple]]:
    """``count`` different ticks, each ``per_tick`` (uid, prev, status) changes."""
    return [
        [(2 + (i * 7 + k) % 200, *CYCLE[(i + k) & 3]) for i in range(per_tick)]
        for k in range(count)
    ]


def feed(subscriber: Subscriber, events: int, per_tick: int, tick_ns: int = 0) -> None:
    """Deliver ``events`` status changes in ticks of ``per_tick`` (1 µs apart in sim time,
    or ticks ``tick_ns`` apart, as a robot's 10 Hz tree with ``tick_ns`` 100 ms) as the
    executor does: a batch a tick when the subscriber takes batches, else one
    ``on_status`` a change; then ``on_tick``."""
    on_status, on_tick = subscriber.on_status, subscriber.on_tick
    patterns = tick_patterns(per_tick)
    batches = [[CHANGE.pack(*change) for change in pattern] for pattern in patterns]
    on_batch = subscriber.on_status_batch if subscriber.takes_status_batches() else None
    seq, tick = 0, 0
    while seq < events:
        tick += 1
        start = tick * tick_ns if tick_ns else seq * 1000
        if on_batch is not None:
            batch = batches[tick % len(batches)]
            on_batch(seq, tick, start, batch, None)
            seq += len(batch)
        else:
            for uid, prev, new in patterns[tick % len(patterns)]:
                on_status(seq, start if tick_ns else seq * 1000, tick, uid, prev, new)
                seq += 1
        on_tick(TickRecord(tick, start, start if tick_ns else seq * 1000, RUNNING))


class NoOp(Subscriber):
    """Takes batches and does nothing: what the loop of ``feed`` costs alone."""

    def takes_status_batches(self) -> bool:
        return True

    def on_status_batch(self, *batch: object) -> None:
        pass


def best_time(run, repeat: int) -> tuple[float, float]:
    """The fastest of ``repeat`` runs of ``run()``: (wall seconds, CPU seconds of this
    process). On a shared machine the CPU time is the steadier figure."""
    wall = cpu = float("inf")
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        run()
        wall = min(wall, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    return wall, cpu


def measure(
    path: Path,
    compression: CompressionType,
    events: int,
    per_tick: int,
    flush_interval: float,
    repeat: int,
    max_tick_events: int | None = None,
    tick_ns: int = 0,
) -> tuple[float, float, int]:
    """(best wall seconds, best CPU seconds, file bytes) for recordings of ``events``
    synthetic events."""
    tree = synthetic_tree()

    def run() -> None:
        recorder = Recorder(
            path,
            tree,
            {"domain": "benchmark"},
            flush_interval=flush_interval,
            compression=compression,
            max_tick_events=max_tick_events,
        )
        feed(recorder, events, per_tick, tick_ns)
        recorder.close()

    return *best_time(run, repeat), path.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=2_000_000)
    parser.add_argument("--per-tick", type=int, default=50)
    parser.add_argument("--flush-interval", type=float, default=1.0)
    parser.add_argument("--repeat", type=int, default=3, help="runs per figure; best is shown")
    parser.add_argument(
        "--max-tick-events",
        type=int,
        default=None,
        help="the Recorder's per-tick buffer bound (default: none)",
    )
    parser.add_argument(
        "--tick-ms",
        type=float,
        default=0.0,
        help="run time between ticks (default: 1 µs an event; 100 = a 10 Hz robot, whose "
        "events messages are then cut by the run's clock)",
    )
    parser.add_argument("--smoke", action="store_true", help="a tiny run (10,000 events)")
    args = parser.parse_args()
    events = 10_000 if args.smoke else args.events
    repeat = 1 if args.smoke else args.repeat
    tick_ns = round(args.tick_ms * 1e6)
    print(
        f"{events:,} events in ticks of {args.per_tick}"
        + (f" {args.tick_ms:g} ms apart" if tick_ns else "")
        + f", flush interval "
        f"{args.flush_interval} s, max_tick_events {args.max_tick_events}, "
        f"best of {repeat}"
    )
    driver = NoOp() if args.max_tick_events is None else Subscriber()
    driver_wall, driver_cpu = best_time(
        lambda: feed(driver, events, args.per_tick, tick_ns), repeat
    )
    print(
        f"  driver alone (no-op subscriber): {events / driver_wall:,.0f} calls/s wall, "
        f"{events / driver_cpu:,.0f} calls/s CPU"
    )
    print("  compression   events/s wall   events/s CPU   recorder-only CPU   MB     B/event")
    with tempfile.TemporaryDirectory() as folder:
        for compression in compressions():
            path = Path(folder) / f"bench-{compression.name.lower()}.mcap"
            wall, cpu, size = measure(
                path,
                compression,
                events,
                args.per_tick,
                args.flush_interval,
                repeat,
                args.max_tick_events,
                tick_ns,
            )
            own = cpu - driver_cpu
            print(
                f"  {compression.name:<11} {events / wall:>13,.0f}   {events / cpu:>12,.0f}   "
                f"{events / own if own > 0 else float('inf'):>17,.0f}   "
                f"{size / 1e6:6.2f}   {size / events:7.2f}"
            )
            os.remove(path)


if __name__ == "__main__":
    main()

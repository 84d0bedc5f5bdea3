"""The cost of recording a py_trees run: py_trees ticking alone vs ticking while
``btlog.sources.py_trees.record`` records it, in the same run.

The tree is the 50-node benchmark tree of ``bench_tick.py`` (a Sequence of 7 Selectors,
``memory=False``, each five Failure then one Success), ticked with
``BehaviourTree.tick()``. Its root completes every tick, so py_trees resets every node to
INVALID at the next one and the recording holds about 100 status changes a tick, the
most this tree makes. Three contenders: py_trees alone, recorded (``answers=False``: the
file only) and recorded as ``record`` does by default (``answers=True``: the events are
also kept for the live history ``recorder.answer`` builds when asked). They are
interleaved in many short rounds and each one's best round is kept, so a burst of load on
a shared machine spoils a round, not a contender; both the wall time and the process's
CPU time are measured, of the ticking thread (what a tick costs the program) and of every
thread (the recorder encodes and compresses on a thread of its own, on another core
when there is one). The ratio recorded / alone of the ticking thread's CPU time a tick
is the figure of the goal (at most 1.15); the wall time's ratio equals it on an idle
machine and is printed too.

    python benchmarks/bench_py_trees.py               # 12 rounds of 0.5 s each
    python benchmarks/bench_py_trees.py --smoke       # 2 rounds of 0.1 s (CI)
"""

from __future__ import annotations

import argparse
import gc
import sys
import tempfile
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from bench_tick import make_py_trees_tree
from btlog.sources.py_trees import record

#: The recording may add at most this much to py_trees' own tick.
GOAL = 1.15


def measure(tick: Callable[[], Any], seconds: float) -> tuple[float, float, float]:
    """Tick for about ``seconds``; the wall time, the ticking thread's CPU time and the
    process's (every thread's) CPU time of one tick, in µs."""
    gc.collect()
    count = 0
    wall, thread, cpu = time.perf_counter(), time.thread_time(), time.process_time()
    deadline = wall + seconds
    while True:
        for _ in range(16):
            tick()
        count += 16
        now = time.perf_counter()
        if now >= deadline:
            break
    return (
        (now - wall) / count * 1e6,
        (time.thread_time() - thread) / count * 1e6,
        (time.process_time() - cpu) / count * 1e6,
    )


def main(argv: list[str] | None = None) -> int:
    """Measure and print the figures and the ratios."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.5, help="per round")
    parser.add_argument("--rounds", type=int, default=12, help="interleaved rounds")
    parser.add_argument("--smoke", action="store_true", help="2 rounds of 0.1 s")
    args = parser.parse_args(argv)
    seconds, rounds = (0.1, 2) if args.smoke else (args.seconds, args.rounds)
    names = ("py_trees alone", "recorded", "recorded, answers kept")
    best = {name: [float("inf")] * 3 for name in names}
    with tempfile.TemporaryDirectory() as tmp, ExitStack() as stack:
        trees = {name: make_py_trees_tree() for name in names}
        recorders = {
            name: stack.enter_context(
                record(trees[name], Path(tmp) / f"{index}.mcap", answers=index == 2)
            )
            for index, name in enumerate(names)
            if index
        }
        for tree in trees.values():
            measure(tree.tick, seconds / 5)  # warm-up
        for _ in range(rounds):
            for name in names:
                measured = measure(trees[name].tick, seconds)
                best[name] = [min(old, new) for old, new in zip(best[name], measured, strict=True)]
        recorder = recorders["recorded"]
        per_tick = recorder.builder.seq / max(recorder.ticks, 1)
    print("  µs a tick (best round)     wall   ticking thread CPU   all threads CPU")
    for name in names:
        wall, thread, cpu = best[name]
        print(f"  {name:<24} {wall:>8.1f} {thread:>20.1f} {cpu:>17.1f}")
    print(f"  status changes recorded a tick: {per_tick:.0f}")
    alone = best["py_trees alone"]
    for name in names[1:]:
        wall, thread, cpu = (best[name][i] / alone[i] for i in range(3))
        verdict = "met" if thread <= GOAL else "NOT met"
        print(
            f"{name} / alone: {thread:.3f}x the ticking thread's CPU (goal <= {GOAL}: "
            f"{verdict}); {cpu:.3f}x all threads' CPU; {wall:.3f}x wall"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

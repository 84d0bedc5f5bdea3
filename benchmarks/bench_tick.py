"""Tick throughput of one 50-node tree in btlog, py_trees 2.6 and BehaviorTree.CPP.

The tree is a Sequence of 7 Fallbacks, each with five AlwaysFailure and then one
AlwaysSuccess (1 + 7 × 7 = 50 nodes): every tick runs every node once and the root
succeeds, so each tick of btlog also logs 99 status changes (50 to a result, 49 resets)
when something records them. The same shape is built

- in btlog, from XML, with no subscriber (nothing recorded);
- in py_trees 2.6, with ``composites.Sequence``/``Selector`` (``memory=False``) and
  ``behaviours.Failure``/``Success``; ``root.tick_once()`` (a ``BehaviourTree.tick()`` adds
  visitors and handlers and is timed as well);
- in BT.CPP 4.8.2 through ``behaviortreepy`` (if it imports), ``tree.tick_once()`` in a
  Python loop (so one Python→C++ call per tick is included).

All of them are timed in the same run, interleaved: ``--rounds`` rounds (default 3)
each tick every contender for its share of ``--seconds`` after a warm-up, and each
contender's best round is reported (the machine is shared: a burst of load then spoils one
round, not one contender). Ticks/s and the ratios btlog/py_trees (plain and with full
recording, against their targets) and btlog/BT.CPP are printed. ``--profile`` adds a
cProfile of btlog's tick.

    python benchmarks/bench_tick.py                # 3 s per measurement
    python benchmarks/bench_tick.py --smoke        # 0.2 s per measurement
    python benchmarks/bench_tick.py --profile      # and where btlog's tick spends its time

``make_btlog_tree()`` and ``time_ticks(tick_fn, seconds)`` are meant to be reused, e.g. to
time btlog with a recorder subscribed::

    executor = make_btlog_tree()
    executor.subscribe(recorder)
    rate = time_ticks(executor.tick, 3.0)

With full recording it also prints the CPU time a tick of the run's thread and of the
recorder's own thread (which packs, compresses and writes), over all rounds.

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import io
import pstats
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from btlog.executor.clock import SimClock
from btlog.executor.engine import Executor
from btlog.record.recorder import Recorder
from btlog.status import SUCCESS
from btlog.tree.loader import load_tree_text

FALLBACKS = 7
FAILURES_PER_FALLBACK = 5
TARGET_RATIO = 5.0
#: btlog executing and recording (issue 16), against py_trees' plain tick
RECORDING_TARGET_RATIO = 6.0


def tree_xml() -> str:
    """The BT.CPP v4 XML of the 50-node tree (unique names; BT.CPP accepts it as is)."""
    fallbacks = []
    for f in range(FALLBACKS):
        leaves = "".join(
            f'<AlwaysFailure name="fail_{f}_{k}"/>' for k in range(FAILURES_PER_FALLBACK)
        )
        fallbacks.append(
            f'<Fallback name="fallback_{f}">{leaves}<AlwaysSuccess name="ok_{f}"/></Fallback>'
        )
    return (
        '<root BTCPP_format="4" main_tree_to_execute="Main">'
        '<BehaviorTree ID="Main"><Sequence name="root">'
        + "".join(fallbacks)
        + "</Sequence></BehaviorTree></root>"
    )


def make_btlog_tree() -> Executor:
    """The 50-node tree as a btlog ``Executor`` (simulated clock, no subscriber).

    Subscribe a recorder (``executor.subscribe(...)``) to time ticking with recording;
    ``executor.tick`` is the function to time.
    """
    tree = load_tree_text(tree_xml())
    assert len(tree) == 1 + FALLBACKS * (FAILURES_PER_FALLBACK + 2)
    return Executor(tree, clock=SimClock(0.001))


def make_py_trees_tree() -> Any:
    """The same shape in py_trees 2.6: Sequence/Selector with ``memory=False``."""
    import py_trees

    fallbacks = []
    for f in range(FALLBACKS):
        children = [
            py_trees.behaviours.Failure(name=f"fail_{f}_{k}") for k in range(FAILURES_PER_FALLBACK)
        ]
        children.append(py_trees.behaviours.Success(name=f"ok_{f}"))
        fallbacks.append(
            py_trees.composites.Selector(name=f"fallback_{f}", memory=False, children=children)
        )
    root = py_trees.composites.Sequence(name="root", memory=False, children=fallbacks)
    return py_trees.trees.BehaviourTree(root)


def make_btcpp_tree() -> tuple[Any, Any] | None:
    """The same XML in BT.CPP through behaviortreepy as ``(factory, tree)`` (keep the
    factory alive as long as the tree), or None if behaviortreepy does not import."""
    try:
        import behaviortreepy
    except ImportError:
        return None
    factory = behaviortreepy.BehaviorTreeFactory()
    return factory, factory.create_tree_from_text(tree_xml())


def time_ticks(tick_fn: Callable[[], Any], seconds: float, warmup: float = 0.1) -> float:
    """Call ``tick_fn`` repeatedly for about ``seconds`` (after a warm-up of ``warmup`` of
    that time) and return the rate in calls per second. Calls are made in batches, so
    the clock is read rarely; garbage is collected before timing starts."""

    def batches(duration: float) -> tuple[int, float]:
        count, batch = 0, 1
        start = time.perf_counter()
        deadline = start + duration
        while True:
            for _ in range(batch):
                tick_fn()
            count += batch
            now = time.perf_counter()
            if now >= deadline:
                return count, now - start
            batch = min(batch * 2, 4096)

    batches(seconds * warmup)
    gc.collect()
    count, elapsed = batches(seconds)
    return count / elapsed


def check_results(executor: Executor, py_tree: Any, btcpp: tuple[Any, Any] | None) -> None:
    """Every implementation must succeed on every tick (a sanity check of the shapes)."""
    import py_trees

    assert executor.tick() is SUCCESS
    py_tree.root.tick_once()
    assert py_tree.root.status == py_trees.common.Status.SUCCESS
    if btcpp is not None:
        assert btcpp[1].tick_once().name == "SUCCESS"


def profile_btlog(seconds: float, top: int = 18) -> str:
    """A cProfile of btlog's tick, sorted by own time."""
    executor = make_btlog_tree()
    tick = executor.tick
    profiler = cProfile.Profile()
    deadline = time.perf_counter() + seconds
    ticks = 0
    profiler.enable()
    while time.perf_counter() < deadline:
        for _ in range(200):
            tick()
        ticks += 200
    profiler.disable()
    out = io.StringIO()
    stats = pstats.Stats(profiler, stream=out)
    stats.sort_stats("tottime").print_stats(top)
    return (
        f"cProfile of {ticks} btlog ticks (times are inflated by the profiler):\n" + out.getvalue()
    )


def main(argv: list[str] | None = None) -> int:
    """Run the measurements and print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--seconds", type=float, default=3.0, help="ticking time per measurement (default 3)"
    )
    parser.add_argument(
        "--rounds", type=int, default=3, help="interleaved rounds, best reported (default 3)"
    )
    parser.add_argument("--smoke", action="store_true", help="0.2 s per measurement")
    parser.add_argument("--profile", action="store_true", help="also profile btlog's tick")
    args = parser.parse_args(argv)
    seconds = 0.2 if args.smoke else args.seconds
    rounds = max(args.rounds, 1)

    executor = make_btlog_tree()
    py_tree = make_py_trees_tree()
    btcpp = make_btcpp_tree()
    check_results(executor, py_tree, btcpp)

    nodes = len(executor.tree)
    print(
        f"tree: Sequence of {FALLBACKS} Fallbacks x ({FAILURES_PER_FALLBACK} AlwaysFailure + "
        f"1 AlwaysSuccess) = {nodes} nodes; {seconds:g} s per measurement "
        f"in {rounds} interleaved rounds, best round reported"
    )
    with tempfile.TemporaryDirectory() as folder:
        recorded = make_btlog_tree()
        recorder = Recorder(Path(folder) / "bench.mcap", recorded.tree, {"domain": "bench"})
        recorded.subscribe(recorder)
        contenders: dict[str, Callable[[], Any]] = {
            "btlog": executor.tick,
            "btlog + full recording": recorded.tick,
            "py_trees": py_tree.root.tick_once,
            "py_trees BehaviourTree.tick()": py_tree.tick,
        }
        if btcpp is not None:
            contenders["BT.CPP (behaviortreepy)"] = btcpp[1].tick_once
        rates = dict.fromkeys(contenders, 0.0)
        run_cpu = 0.0  # the run's thread, while the recorded tree ticks
        for _ in range(rounds):
            for name, tick in contenders.items():
                started = time.thread_time()
                rates[name] = max(rates[name], time_ticks(tick, seconds / rounds))
                if name == "btlog + full recording":
                    run_cpu += time.thread_time() - started
        recorded_ticks = max(recorded.runtime.tick, 1)
        writer_cpu = recorder.writer_cpu_seconds
        recorder.close()
        events_per_tick = recorded.seq / recorded_ticks

    width = max(len(name) for name in rates)
    for name, rate in rates.items():
        print(
            f"  {name:<{width}}  {rate:>11,.0f} ticks/s  {1e6 / rate:8.2f} µs/tick  "
            f"{rate * nodes / 1e6:6.2f} M node-ticks/s"
        )
    ratio = rates["btlog"] / rates["py_trees"]
    print(
        f"btlog / py_trees: {ratio:.2f}x  (target >= {TARGET_RATIO:g}x: "
        f"{'met' if ratio >= TARGET_RATIO else 'NOT met'})"
    )
    print(
        f"btlog / py_trees BehaviourTree.tick(): "
        f"{rates['btlog'] / rates['py_trees BehaviourTree.tick()']:.2f}x"
    )
    recording_ratio = rates["btlog + full recording"] / rates["py_trees"]
    print(
        f"btlog with full recording / py_trees: {recording_ratio:.2f}x  "
        f"(target >= {RECORDING_TARGET_RATIO:g}x: "
        f"{'met' if recording_ratio >= RECORDING_TARGET_RATIO else 'NOT met'}; "
        f"{events_per_tick:.0f} events/tick, "
        f"{rates['btlog + full recording'] * events_per_tick:,.0f} events/s recorded)"
    )
    writer = "n/a" if writer_cpu is None else f"{writer_cpu / recorded_ticks * 1e6:.1f} µs"
    print(
        f"btlog with full recording, CPU a tick (all rounds): run's thread "
        f"{run_cpu / recorded_ticks * 1e6:.1f} µs, recorder's thread {writer}"
    )
    if btcpp is not None:
        print(f"btlog / BT.CPP: {rates['btlog'] / rates['BT.CPP (behaviortreepy)']:.3f}x")
    else:
        print("btlog / BT.CPP: n/a (behaviortreepy does not import)")

    if args.profile:
        print()
        print(profile_btlog(seconds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

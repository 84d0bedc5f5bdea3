"""Nav2 bags: export (``btlog export --to nav2``) and import (``btlog import BAG.mcap``).

A long navigation is recorded once: ``trees/nav2/navigate_to_pose.xml`` with FollowPath
running for ``--seconds`` simulated seconds while the RateController replans at 1 Hz
(about 20 status changes a second). It is then exported as a ROS 2 bag and imported
back, best of ``--repeat``; beside each, in the same run, the BT.CPP FileLogger2 export
and import of the same recording (the ratio shows what CDR via mcap-ros2-support costs
against FileLogger2's fixed 9-byte records).

    python benchmarks/bench_nav2.py              # 3600 s of navigation
    python benchmarks/bench_nav2.py --smoke      # 60 s, one repeat

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from btlog.record.reader import open_recording
from btlog.runner import RunConfig, execute
from btlog.sinks.btcpp_filelog import export_filelog
from btlog.sinks.nav2_rosbag import export_nav2
from btlog.sources.btcpp_filelog import import_filelog
from btlog.sources.nav2_rosbag import import_bag

ROOT = Path(__file__).resolve().parent.parent
TREE = ROOT / "trees" / "nav2" / "navigate_to_pose.xml"


def best(repeat: int, work: Callable[[], object]) -> float:
    """The shortest wall time of ``repeat`` runs of ``work``."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3600.0, help="simulated navigation")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="60 s, one repeat")
    args = parser.parse_args()
    if args.smoke:
        args.seconds, args.repeat = 60.0, 1
    outcomes = {
        "default": {"status": "SUCCESS", "duration": 0},
        "nodes": {
            "GlobalUpdatedGoal": "FAILURE",
            "GoalUpdated": "FAILURE",
            "IsGoalNearby": "FAILURE",
            "FollowPath": {"status": "SUCCESS", "duration": args.seconds},
        },
    }
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        config = RunConfig(str(TREE), outcomes=outcomes, max_ticks=10**7)
        start = time.perf_counter()
        result = execute(config, out / "run.mcap")
        recorded = time.perf_counter() - start
        recording = open_recording(result.path)
        changes = len(recording.transitions)
        print(
            f"run: {args.seconds:.0f} s navigation, {result.ticks:,} ticks, "
            f"{changes:,} transitions, recorded in {recorded:.2f} s"
        )
        bag, log = out / "bag.mcap", out / "run.btlog"
        figures = {
            "export --to nav2": best(args.repeat, lambda: export_nav2(recording, bag)),
            "export --to btlog": best(args.repeat, lambda: export_filelog(recording, log)),
            "import Nav2 bag": best(args.repeat, lambda: import_bag(bag, out / "a.mcap")),
            "import FileLogger2": best(args.repeat, lambda: import_filelog(log, out / "b.mcap")),
        }
        print(f"  {'':22} {'seconds':>9} {'transitions/s':>15}")
        for name, seconds in figures.items():
            print(f"  {name:22} {seconds:9.3f} {changes / seconds:15,.0f}")
        print(f"  bag size {bag.stat().st_size:,} B, FileLogger2 {log.stat().st_size:,} B")
        export = figures["export --to btlog"] / figures["export --to nav2"]
        imported = figures["import FileLogger2"] / figures["import Nav2 bag"]
        print(f"nav2 / FileLogger2 speed: export {export:.2f}x, import {imported:.2f}x")


if __name__ == "__main__":
    main()

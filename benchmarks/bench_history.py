"""Questions over a long run's history: each answer from the read model, never a replay.

1. **A recording of N events** (default 10M): the workload of ``bench_replay.py`` (a
   pick-and-place loop whose conditions fail and fall back, with a retry) recorded over
   and over, so failures are spread over the whole run.
2. **The read model** is built once (``open_runs``, cache beside the recording), then
   opened again: every figure below is *warm* (the cache exists).
3. **Every question** — the paper's Q1–Q6 (Q6 over the history), What will you do
   next?, and each question about a node X (why did X fail, why didn't you X, when did X
   last fail/succeed/start, how long did X take) — at three moments (10 %, 50 %, the end),
   in process with the SQL history: the latency of ``answer`` (state + history queries).
4. **``btlog ask`` warm**: the whole command in a subprocess (interpreter start, opening
   the cached read model, the answer) for each question at the end; the target is < 1 s.
5. **The story** (``btlog explain REC``) in process.
6. The same-run reference: folding the first 1M events from the start with
   ``StateProjection`` (what answering by replay would cost), scaled to N.

    python benchmarks/bench_history.py              # 10,000,000 events
    python benchmarks/bench_history.py --smoke      # 300,000 events, no subprocesses

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_replay import write_recording
from btlog.explain.questions import QUESTIONS, answer
from btlog.explain.story import story
from btlog.replay.database import open_runs
from btlog.replay.sql_history import SqlHistory
from btlog.state import StateProjection

#: Nodes of the workload asked about: a leaf under a retry, a fallback, a subtree's
#: sequence, the root.
ABOUT = ["grasp part", "find part", "fetch part", "kit parts"]


def questions() -> list[str]:
    """Every question, those about X asked about each node of ``ABOUT``."""
    plain = [q for intent, q in QUESTIONS.items() if "X" not in q]
    about = [q.replace("X", name) for q in QUESTIONS.values() if "X" in q for name in ABOUT]
    return plain + [q for q in about if not q.startswith("Can you")] + ["Can you grasp part?"]


def in_process(path: Path, asked: list[str]) -> dict[str, list[float]]:
    """Latency (ms) of each question at 10 %, 50 % and the end, warm, SQL history."""
    times: dict[str, list[float]] = {}
    with open_runs(path) as database:
        run = database.run(str(path))
        history = SqlHistory(run, in_memory=False)
        events = run.extent.events
        for count in (events // 10, events // 2, events):
            for question in asked:
                started = time.perf_counter()
                tree, state = run.state_after(count)
                answer(tree, state, question, history)
                times.setdefault(question, []).append((time.perf_counter() - started) * 1e3)
    return times


def command_line(path: Path, asked: list[str]) -> dict[str, float]:
    """Wall time (s) of ``btlog ask REC --at end QUESTION``, warm."""
    times = {}
    for question in asked:
        started = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "btlog.cli.main", "ask", str(path), "--at", "end", question],
            check=True,
            capture_output=True,
        )
        times[question] = time.perf_counter() - started
    return times


def story_time(path: Path) -> tuple[float, int]:
    """Seconds to tell the story at the end (warm), and its line count."""
    with open_runs(path) as database:
        run = database.run(str(path))
        started = time.perf_counter()
        tree, state = run.state_at("end")
        told = story(tree, state, SqlHistory(run, in_memory=False))
        return time.perf_counter() - started, len(told.lines())


def replay_time(path: Path, events: int) -> float:
    """Seconds to fold the first ``events`` events from the start (the replay answer)."""
    with open_runs(path) as database:
        run = database.run(str(path))
        started = time.perf_counter()
        tree, _ = run.state_after(0)
        projection = StateProjection(tree)
        every = run.snapshot_every
        for index in range(0, events // every):
            _, batch = run._block(index)
            batch.fold(projection, index * every, (index + 1) * every)
        return time.perf_counter() - started


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=10_000_000)
    parser.add_argument("--smoke", action="store_true", help="300,000 events, in process only")
    parser.add_argument("--recording", type=Path, help="reuse (or write) this recording")
    args = parser.parse_args()
    events = 300_000 if args.smoke else args.events
    with tempfile.TemporaryDirectory() as folder:
        path = args.recording or Path(folder) / "history.mcap"
        if not path.exists():
            started = time.perf_counter()
            written, ticks = write_recording(path, events)
            took = time.perf_counter() - started
            print(f"recording: {written:,} events, {ticks:,} ticks ({took:.1f} s)")
        started = time.perf_counter()
        with open_runs(path) as database:
            events = database.run(str(path)).extent.events
        print(f"read model (first open builds the cache): {time.perf_counter() - started:.1f} s")
        asked = questions()
        times = in_process(path, asked)
        print(f"{len(asked)} questions at 10 %, 50 % and the end of {events:,} events, warm, ms:")
        for question, values in times.items():
            print(f"  {max(values):8.1f} max {statistics.median(values):8.1f} median  {question}")
        worst = max(max(v) for v in times.values())
        print(f"slowest answer in process: {worst:.1f} ms")
        seconds, lines = story_time(path)
        print(f"story at the end: {seconds * 1e3:.1f} ms, {lines} lines")
        sample = min(events, 1_000_000)
        fold = replay_time(path, sample) * events / sample
        print(
            f"a replay from the start (folding {events:,} events, scaled from {sample:,}): "
            f"{fold:.1f} s"
        )
        print(f"replay / slowest answer: {fold / (worst / 1e3):.0f}x")
        if not args.smoke:
            wall = command_line(path, asked)
            for question, value in wall.items():
                print(f"  {value:6.2f} s  btlog ask --at end {question!r}")
            print(
                f"btlog ask, warm, wall: max {max(wall.values()):.2f} s, "
                f"median {statistics.median(wall.values()):.2f} s (target < 1 s)"
            )
            base = wall["What is your goal?"]  # no history read: start-up and opening only
            print(
                f"same run, 'What is your goal?' (no history): {base:.2f} s; the slowest "
                f"question costs {max(wall.values()) / base:.2f}x that"
            )


if __name__ == "__main__":
    main()

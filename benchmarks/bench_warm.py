"""Warm answers end to end: ``btlog ask`` on a cached recording, as a user's second question.

1. btlog's modules are compiled first, as ``pip install`` does (run from a checkout with
   ``PYTHONDONTWRITEBYTECODE`` set, every command would compile them again, ~0.15 s).
2. A first ``btlog ask`` builds the recording's cache (tables and snapshots); then
   ``--repeat`` warm ``btlog ask --at 12s "What are you doing?"`` (and as many warm
   ``btlog explain``), each a new process, wall time from start to exit: median, min, max.
   Beside them, in the same run, the floor no command goes under: a bare interpreter, and
   one that imports DuckDB (the read model's engine).
3. Where a warm ``ask``'s time goes: ``python -X importtime``'s total and its biggest
   imports (cumulative, top-level as the command imports them).

    python benchmarks/bench_warm.py              # 15 runs each
    python benchmarks/bench_warm.py --smoke      # 3 runs each

It prints figures and the target (issue 27: a warm answer in at most 0.3 s); it asserts
nothing.
"""

from __future__ import annotations

import argparse
import compileall
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import btlog

ROOT = Path(__file__).resolve().parent.parent
RECORDING = ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"
#: Issue 27's bound on a warm answer, end to end.
TARGET_SECONDS = 0.3


def seconds(command: list[str], env: dict[str, str]) -> float:
    """Wall seconds of one command in a new process (its output discarded)."""
    start = time.perf_counter()
    subprocess.run(command, env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def spread(times: list[float]) -> str:
    """``median … ms (min …, max …)``."""
    ms = [t * 1000 for t in times]
    return f"median {statistics.median(ms):.0f} ms (min {min(ms):.0f}, max {max(ms):.0f})"


def import_figures(command: list[str], env: dict[str, str], top: int) -> None:
    """Print the total of ``-X importtime`` and the ``top`` biggest imports: the command's
    own top-level ones, and the biggest packages wherever they are imported."""
    result = subprocess.run(
        [sys.executable, "-X", "importtime", *command[1:]],
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    rows = []
    for line in result.stderr.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        _self, cumulative, name = line.removeprefix("import time:").split("|")
        depth = (len(name) - len(name.lstrip(" ")) - 1) // 2
        rows.append((depth, int(cumulative), name.strip()))
    total = sum(us for depth, us, _name in rows if depth == 0)
    print(f"  imports (-X importtime, one run): {total / 1000:.0f} ms in all; biggest:")
    for _depth, us, name in sorted((r for r in rows if r[0] == 0), key=lambda r: -r[1])[:top]:
        print(f"    {us / 1000:7.1f} ms  {name}")
    biggest: dict[str, int] = {}
    for _depth, us, name in rows:
        package = name.split(".")[0]
        if package not in sys.stdlib_module_names and package != "btlog":
            biggest[package] = max(biggest.get(package, 0), us)
    ranked = [(p, us) for p, us in sorted(biggest.items(), key=lambda i: -i[1]) if us >= 1000]
    ranked = ranked[:top]
    print("  biggest libraries: " + ", ".join(f"{p} {us / 1000:.0f} ms" for p, us in ranked))


def main() -> None:
    """Measure and print (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15, help="runs of each command")
    parser.add_argument("--smoke", action="store_true", help="3 runs of each command")
    parser.add_argument("--recording", type=Path, default=RECORDING)
    args = parser.parse_args()
    repeat = 3 if args.smoke else args.repeat
    compileall.compile_dir(Path(btlog.__file__).parent, quiet=1)
    print(
        f"machine: {os.cpu_count()} CPUs, load average "
        f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}; {args.recording.name} "
        f"({args.recording.stat().st_size / 1e3:.0f} KB)"
    )
    with tempfile.TemporaryDirectory(prefix="bench-warm-") as folder:
        env = {**os.environ, "XDG_CACHE_HOME": folder, "NO_COLOR": "1"}
        env.pop("BTLOG_CACHE_DIR", None)
        btlog_command = [sys.executable, "-m", "btlog.cli.main"]
        ask = [*btlog_command, "ask", str(args.recording), "--at", "12s", "What are you doing?"]
        explain = [*btlog_command, "explain", str(args.recording)]
        first = seconds(ask, env)
        print(f"first `btlog ask` (cache built): {first * 1000:.0f} ms")
        contenders = {
            "warm `btlog ask --at 12s`": ask,
            "warm `btlog explain` (the story)": explain,
            "python -c pass": [sys.executable, "-c", "pass"],
            "python -c 'import duckdb'": [sys.executable, "-c", "import duckdb"],
        }
        times: dict[str, list[float]] = {name: [] for name in contenders}
        for _ in range(repeat):  # interleaved: a burst of load spoils a round, not a figure
            for name, command in contenders.items():
                times[name].append(seconds(command, env))
        for name, measured in times.items():
            print(f"{name + ':':36} {spread(measured)}")
        median = statistics.median(times["warm `btlog ask --at 12s`"])
        floor = statistics.median(times["python -c 'import duckdb'"])
        met = "met" if median <= TARGET_SECONDS else "NOT met"
        print(
            f"warm ask, median of {repeat}: {median:.3f} s (target <= {TARGET_SECONDS} s: "
            f"{met}); {median / floor:.2f}x an interpreter importing DuckDB in the same run"
        )
        import_figures(ask, env, top=8)


if __name__ == "__main__":
    main()

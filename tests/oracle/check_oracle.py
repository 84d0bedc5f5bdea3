"""Run random cases through the BT.CPP oracle and print statistics (not a pytest module).

Usage, from the project root::

    python -m tests.oracle.check_oracle [--seeds 200] [--start 0] [--jobs N] [--show-errors]

It shows how many cases ran cleanly, how many BT.CPP refused or threw on (and why), how many
crashed or timed out, and the distribution of tree sizes, ticks and transitions, so that one
can see the generator produces valid and interesting trees.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import statistics
import sys
import time
import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor
from typing import Any

if __package__:
    from .random_trees import Case, generate
    from .runner import run_oracle
else:  # run as a script
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    from tests.oracle.random_trees import Case, generate
    from tests.oracle.runner import run_oracle


_SIZE_BINS = [(1, 4), (5, 9), (10, 19), (20, 29), (30, 40), (41, 60)]
_TICK_BINS = [(1, 1), (2, 2), (3, 5), (6, 10), (11, 20), (21, 30)]


def _describe(values: list[int]) -> str:
    if not values:
        return "n/a"
    ordered = sorted(values)
    pct = [ordered[min(len(ordered) - 1, int(q * len(ordered)))] for q in (0.1, 0.5, 0.9)]
    return (
        f"min {ordered[0]}, p10 {pct[0]}, median {pct[1]}, p90 {pct[2]}, "
        f"max {ordered[-1]}, mean {statistics.mean(ordered):.1f}"
    )


def _histogram(values: list[int], bins: list[tuple[int, int]]) -> str:
    counts: collections.Counter = collections.Counter()
    for value in values:
        label = f">{bins[-1][1]}"
        for low, high in bins:
            if low <= value <= high:
                label = f"{low}" if low == high else f"{low}-{high}"
                break
        counts[label] += 1
    labels = [f"{low}" if low == high else f"{low}-{high}" for low, high in bins]
    labels.append(f">{bins[-1][1]}")
    return "  ".join(f"{label}: {counts[label]}" for label in labels if counts[label])


def _tags(case: Case) -> collections.Counter:
    root = ET.fromstring(case.xml)
    tags: collections.Counter = collections.Counter()
    for elem in root.iter():
        if elem.tag in ("root", "BehaviorTree"):
            continue
        tags[elem.tag] += 1
        for attr in elem.attrib:
            if attr.startswith("_"):
                tags[attr] += 1
    return tags


_HALTING_PARENTS = (
    "ReactiveSequence",
    "ReactiveFallback",
    "Parallel",
    "ParallelAll",
    "WhileDoElse",
    "Switch2",
    "Switch3",
)


def _structure(case: Case) -> tuple[dict[str, str], dict[str, ET.Element]]:
    """Map each node name to its parent's name, and each name to its element."""
    root = ET.fromstring(case.xml)
    parent: dict[str, str] = {}
    elems: dict[str, ET.Element] = {}
    for elem in root.iter():
        name = elem.get("name")
        if name is None or elem.tag in ("root", "BehaviorTree"):
            continue
        elems[name] = elem
        for child in elem:
            if child.get("name") is not None:
                parent[child.get("name")] = name
    for elem in elems.values():  # a subtree's body hangs under its SubTree node
        if elem.tag == "SubTree":
            for tree in root.iter("BehaviorTree"):
                if tree.get("ID") == elem.get("ID") and len(tree) and tree[0].get("name"):
                    parent[tree[0].get("name")] = elem.get("name")
    return parent, elems


def _features(case: Case, result: dict[str, Any]) -> set[str]:
    """Name the interesting behaviours visible in one run's transitions."""
    parent, elems = _structure(case)
    transitions = result["transitions"]
    last = result["ticks"] if result["halted"] else None  # skip the final halt_tree
    halted = {
        name
        for tick, name, prev, new in transitions
        if prev == "RUNNING" and new == "IDLE" and tick != last
    }
    starts: collections.Counter = collections.Counter()
    logged: set[str] = set()
    for _, name, prev, _ in transitions:
        logged.add(name)
        if prev == "IDLE":
            starts[name] += 1
    found: set[str] = set()
    for name, elem in elems.items():
        kids = [p for p, q in parent.items() if q == name]
        if elem.tag == "RetryUntilSuccessful" and any(starts[k] >= 2 for k in kids):
            found.add("RetryUntilSuccessful made 2+ attempts")
        if elem.tag == "Repeat" and any(starts[k] >= 2 for k in kids):
            found.add("Repeat ran its child 2+ times")
        if elem.tag == "KeepRunningUntilFailure" and any(starts[k] >= 2 for k in kids):
            found.add("KeepRunningUntilFailure ran its child 2+ times")
        skippable = "_skipIf" in elem.attrib or "_while" in elem.attrib
        if skippable and name not in logged and parent.get(name) in logged:
            found.add("node with _skipIf/_while silent while its parent ran (likely skipped)")
        if elem.tag == "SubTree" and name in logged:
            found.add("SubTree ran")
        reactive = elem.tag in _HALTING_PARENTS and starts[name] > 0
        if reactive and any(kid in halted for kid in kids):
            found.add(f"{elem.tag} halted a running child")
    return found


def _error_kind(message: str) -> str:
    message = re.sub(r"\s+", " ", message)
    return re.sub(r"\d+", "N", message)[:110]


def main(argv: list[str] | None = None) -> int:
    """Run the statistics; return 0 if most cases ran without a BT.CPP error."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--start", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=max(1, os.cpu_count() or 1))
    parser.add_argument("--timeout", type=float, default=20)
    parser.add_argument("--show-errors", action="store_true")
    parser.add_argument("--max-depth", type=int, default=4)
    parser.add_argument("--max-children", type=int, default=4)
    args = parser.parse_args(argv)

    seeds = list(range(args.start, args.start + args.seeds))
    cases = {seed: generate(seed, args.max_depth, args.max_children) for seed in seeds}
    started = time.monotonic()
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        results = dict(
            zip(
                seeds,
                pool.map(lambda s: run_oracle(cases[s], timeout=args.timeout), seeds),
                strict=True,
            )
        )
    elapsed = time.monotonic() - started

    crashed = [s for s in seeds if results[s] is None]
    errored = [s for s in seeds if results[s] is not None and results[s]["error"]]
    clean = [s for s in seeds if results[s] is not None and not results[s]["error"]]
    error_kinds = collections.Counter(_error_kind(results[s]["error"]) for s in errored)

    sizes = [cases[s].node_count for s in seeds]
    ticks = [results[s]["ticks"] for s in clean]
    n_trans = [len(results[s]["transitions"]) for s in clean]
    final = collections.Counter(
        "halted at max_ticks" if results[s]["halted"] else results[s]["root"][-1] for s in clean
    )
    kinds: collections.Counter = collections.Counter()
    runs_with: collections.Counter = collections.Counter()
    coverage: collections.Counter = collections.Counter()
    for s in clean:
        result = results[s]
        seen: set[str] = set()
        started_in_tick: collections.Counter = collections.Counter()
        for tick, name, prev, new in result["transitions"]:
            if prev == "RUNNING" and new == "IDLE":
                kinds["halts (RUNNING->IDLE)"] += 1
                seen.add("halt")
            elif new == "IDLE":
                kinds["resets (SUCCESS/FAILURE->IDLE)"] += 1
            elif prev == "IDLE":
                kinds["activations (IDLE->*)"] += 1
                started_in_tick[(tick, name)] += 1
            else:
                kinds["completions (RUNNING->*)"] += 1
        if any(count > 1 for count in started_in_tick.values()):
            seen.add("node re-activated within one tick (retry/repeat/reactive/wake-up)")
        if result["halted"]:
            seen.add("final halt_tree")
        seen |= _features(cases[s], result)
        names_logged = {name for _, name, _, _ in result["transitions"]}
        silent = [n for n in cases[s].names if n not in names_logged]
        if silent:
            seen.add("some node never changed status (not reached or skipped)")
        for item in seen:
            runs_with[item] += 1
        coverage.update(_tags(cases[s]))

    print(f"seeds {seeds[0]}..{seeds[-1]}: {len(seeds)} cases in {elapsed:.1f}s")
    print(f"  ran cleanly:            {len(clean)}")
    print(f"  BT.CPP raised an error: {len(errored)}")
    print(f"  crashed / timed out:    {len(crashed)}  {crashed if crashed else ''}")
    for kind, count in error_kinds.most_common():
        print(f"    {count:4d} x {kind}")
    if args.show_errors:
        for s in errored:
            print(f"    seed {s}: {results[s]['error']!r}")
    print(f"tree size (nodes):   {_describe(sizes)}")
    print(f"                     {_histogram(sizes, _SIZE_BINS)}")
    print(f"ticks run:           {_describe(ticks)}")
    print(f"                     {_histogram(ticks, _TICK_BINS)}")
    print(f"transitions per run: {_describe(n_trans)}")
    print(f"final root status:   {dict(final)}")
    print("transition kinds (all clean runs):")
    for kind, count in kinds.most_common():
        print(f"  {count:6d} {kind}")
    print("clean runs that show:")
    for item, count in runs_with.most_common():
        print(f"  {count:4d} {item}")
    print("node types / attributes generated (clean runs):")
    print("  " + ", ".join(f"{tag} {count}" for tag, count in coverage.most_common()))
    other = sum(1 for s in seeds if results[s] and results[s].get("other_output"))
    if other:
        print(f"runs with extra stdout lines from BT.CPP: {other}")
    return 0 if len(clean) >= 0.8 * len(seeds) else 1


if __name__ == "__main__":
    sys.exit(main())

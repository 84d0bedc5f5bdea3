"""The viewer on a large run: time to first paint and to a scrub step, in chromium.

1. **A recording** of a generated 1,000-node tree (40 tasks of 25 nodes: a Fallback with
   a condition, a retried grasp, actions that run for a tick or more) with N events
   (default 1,000,000): one run of the tree, repeated with seq, time and tick shifted
   (``bench_replay.write_recording``).
2. **The first open** of ``btlog view`` (the read model's cache built) and a second one
   (cache used): seconds until it prints its URL.
3. **In chromium** (Playwright, Debian's ``/usr/bin/chromium``): time to first paint
   (``goto`` until the tree is drawn with the statuses of the deep-linked moment) and
   until the Gantt is drawn; then the median and p90 of a step: ArrowRight (one event),
   Shift+ArrowRight (one tick) and a click on the timeline (a scrub to a new time), each
   until the page shows the new moment.

    python benchmarks/bench_view.py              # 1,000,000 events
    python benchmarks/bench_view.py --smoke      # 20,000 events

It prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_replay import write_recording
from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import EventLog
from btlog.executor.engine import Executor
from btlog.status import FAILURE, SUCCESS
from btlog.tree.loader import load_tree_text

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"]
ARGS += ["--disable-component-update", "--disable-sync", "--no-first-run"]
TASKS = 40


def big_tree_xml(tasks: int = TASKS) -> str:
    """A tree of 1 + tasks * 25 nodes."""
    parts = []
    for i in range(tasks):
        steps = "".join(f'<Action ID="step" name="step {i}.{k}"/>' for k in range(19))
        parts.append(
            f'<Sequence name="task {i}"><Fallback name="ready {i}">'
            f'<Condition ID="ok" name="part ok {i}"/><Action ID="fix" name="fix part {i}"/>'
            f'</Fallback><RetryUntilSuccessful num_attempts="3">'
            f'<Action ID="grasp" name="grasp {i}"/></RetryUntilSuccessful>{steps}</Sequence>'
        )
    return (
        '<root BTCPP_format="4" main_tree_to_execute="Main"><BehaviorTree ID="Main">'
        f'<Sequence name="mission">{"".join(parts)}</Sequence></BehaviorTree></root>'
    )


def big_cycle() -> tuple:
    """(tree, events, ticks) of one run of the big tree."""
    tree = load_tree_text(big_tree_xml())
    outcomes = {
        "default": {"status": "SUCCESS", "ticks": 1},
        "nodes": {
            **{f"part ok {i}": ["FAILURE", "SUCCESS"] for i in range(TASKS)},
            **{f"grasp {i}": ["FAILURE", "SUCCESS"] for i in range(TASKS)},
        },
    }
    executor = Executor(
        tree, leaf_factory=scripted_leaf_factory(tree, Outcomes.from_mapping(outcomes))
    )
    log = EventLog()
    executor.subscribe(log)
    while executor.tick() not in (SUCCESS, FAILURE):
        pass
    return tree, log.events, log.ticks


def start_viewer(path: Path) -> tuple[subprocess.Popen, str, float]:
    """``btlog view PATH --no-browser``: (process, URL, seconds until the URL)."""
    began = time.perf_counter()
    process = subprocess.Popen(
        [sys.executable, "-m", "btlog.cli.main", "view", str(path), "--no-browser"],
        stdout=subprocess.PIPE,
        text=True,
    )
    line = process.stdout.readline() if process.stdout else ""
    return process, line.split()[2], time.perf_counter() - began


def stop(process: subprocess.Popen) -> None:
    """Stop a viewer this benchmark started."""
    process.terminate()
    process.wait(timeout=10)
    if process.stdout:
        process.stdout.close()


def timed_steps(page, action, count: int) -> list[float]:
    """Milliseconds from ``action()`` until the pane shows another moment, ``count`` times."""
    figures = []
    for _ in range(count):
        before = page.locator(".pane").get_attribute("data-count")
        began = time.perf_counter()
        action()
        page.wait_for_function(
            "before => { const p = document.querySelector('.pane');"
            " return p.dataset.count !== before && !window.btlogViewer.focused.busy; }",
            arg=before,
        )
        figures.append((time.perf_counter() - began) * 1000)
    return figures


def summary(figures: list[float]) -> str:
    """Median and p90 in ms."""
    ordered = sorted(figures)
    p90 = ordered[min(len(ordered) - 1, int(0.9 * len(ordered)))]
    return f"median {statistics.median(ordered):7.1f} ms   p90 {p90:7.1f} ms"


def browse(url: str, events: int, steps: int) -> None:
    """Time the first paint and the steps in chromium."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_page(viewport={"width": 1500, "height": 900})
        middle = events // 2
        began = time.perf_counter()
        page.goto(f"{url}#seq={middle}")
        page.wait_for_selector(f'.pane[data-count="{middle + 1}"]', timeout=120_000)
        painted = time.perf_counter() - began
        page.wait_for_function(
            "() => window.btlogViewer.panes[0].timeline.segments !== null", timeout=300_000
        )
        gantt = time.perf_counter() - began
        nodes = page.locator("g.node").count()
        print(f"first paint: {painted * 1000:8.0f} ms   ({nodes} node elements)")
        print(f"gantt drawn: {gantt * 1000:8.0f} ms")
        right = timed_steps(page, lambda: page.keyboard.press("ArrowRight"), steps)
        print(f"step, one event (ArrowRight):       {summary(right)}")
        ticks = timed_steps(page, lambda: page.keyboard.press("Shift+ArrowRight"), steps)
        print(f"step, one tick (Shift+ArrowRight):  {summary(ticks)}")
        box = page.locator(".timelinebox canvas").bounding_box()
        rng = random.Random(1)

        def click() -> None:
            x = box["x"] + 160 + rng.random() * (box["width"] - 180)
            page.mouse.click(x, box["y"] + 40)

        scrubs = timed_steps(page, click, steps)
        print(f"scrub, a click on the timeline:     {summary(scrubs)}")
        browser.close()


def main() -> None:
    """Parse the options, record, open, browse, print."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=1_000_000)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--smoke", action="store_true", help="20,000 events, 5 steps")
    args = parser.parse_args()
    if args.smoke:
        args.events, args.steps = 20_000, 5
    with tempfile.TemporaryDirectory(prefix="btlog-bench-view-") as folder:
        path = Path(folder) / "big.mcap"
        began = time.perf_counter()
        events, ticks = write_recording(path, args.events, big_cycle())
        print(
            f"recording: {events} events, {ticks} ticks, {1 + 25 * TASKS} nodes, "
            f"{path.stat().st_size / 1e6:.1f} MB, written in {time.perf_counter() - began:.1f} s"
        )
        process, url, first = start_viewer(path)
        stop(process)
        process, url, second = start_viewer(path)
        print(f"btlog view ready: first open {first:.2f} s (cache built), then {second:.2f} s")
        try:
            if Path(CHROMIUM).exists():
                browse(url, events, args.steps)
            else:
                print("chromium is not installed: no browser figures")
        finally:
            stop(process)


if __name__ == "__main__":
    main()

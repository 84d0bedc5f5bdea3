"""What a killed recorder leaves: at most ``flush_interval`` of wall time lost, ticks in
step with events. The "kill" is reading the file as it is on disk while the run goes on."""

from __future__ import annotations

import shutil
from pathlib import Path

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.executor.clock import WallClock
from btlog.executor.engine import Executor
from btlog.record import Recorder, open_recording
from btlog.tree.loader import load_tree_text

LOOP = """<root BTCPP_format="4"><BehaviorTree ID="MainTree">
  <KeepRunningUntilFailure><Sequence name="work">
    <Action ID="Look" name="look"/><Action ID="Grasp" name="grasp"/>
    <Action ID="Place" name="place"/>
  </Sequence></KeepRunningUntilFailure>
</BehaviorTree></root>"""


def executor(clock: WallClock | None = None) -> Executor:
    tree = load_tree_text(LOOP)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
    return Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes), clock=clock)


def snapshot(path: Path, folder: Path, number: int):
    """The recording as a kill at this instant would leave it."""
    copy = folder / f"kill-{number}.mcap"
    shutil.copyfile(path, copy)
    return open_recording(copy)


def test_paced_ticks_lose_at_most_the_flush_interval(tmp_path: Path) -> None:
    period, interval = 0.05, 0.25
    ex = executor(WallClock(tick_period=period))
    path = tmp_path / "paced.mcap"
    recorder = Recorder(path, ex.tree, {"domain": "loop"}, flush_interval=interval)
    ex.subscribe(recorder)
    worst: list[float] = []

    def before_tick(ex: Executor) -> None:
        if ex.runtime.tick < 2:
            return
        kept = snapshot(path, tmp_path, ex.runtime.tick)
        last = kept.events[-1].t_ns if kept.events else 0
        next_tick_at = ex.runtime.tick * round(period * 1e9)  # a kill just before it
        worst.append((next_tick_at - last) / 1e9)

    ex.run(max_ticks=24, before_tick=before_tick)
    ex.close()
    assert max(worst) <= interval, worst


def test_ticks_are_written_with_their_events(tmp_path: Path) -> None:
    ex = executor()
    path = tmp_path / "ticks.mcap"
    recorder = Recorder(
        path, ex.tree, {"domain": "loop"}, flush_interval=3600, chunk_size=512, group_events=20
    )
    ex.subscribe(recorder)
    lags = []

    def before_tick(ex: Executor) -> None:
        if ex.runtime.tick % 25 == 0:
            kept = snapshot(path, tmp_path, ex.runtime.tick)
            if kept.events:
                last_tick = kept.ticks[-1].tick if kept.ticks else 0
                lags.append(kept.events[-1].tick - last_tick)

    ex.run(max_ticks=300, before_tick=before_tick)
    ex.close()
    assert lags and max(lags) <= 1, lags

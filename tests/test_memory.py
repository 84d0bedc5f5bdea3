"""Large blackboard values are stored and loaded once, not once per snapshot (issue 14)."""

from __future__ import annotations

from pathlib import Path

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.executor.engine import Executor
from btlog.record import Recorder, open_recording
from btlog.replay.database import open_runs
from btlog.state import StateProjection
from btlog.tree.loader import load_tree_text

BIG = "v := &apos;" + "x" * 1024 + "&apos;" + "; v := v..v" * 6  # 64 KiB
WORK = '<Repeat num_cycles="20"><Parallel success_count="-1" failure_count="1">{}</Parallel>'
WORK = WORK.format("".join(f'<Action ID="Work" name="a{i}"/>' for i in range(6))) + "</Repeat>"
TREE = f"""<root BTCPP_format="4"><BehaviorTree ID="MainTree"><Sequence>
  <Script code="{BIG}"/>{WORK}
  <Script code="w := v"/>{WORK}
  <Script code="v := &apos;small&apos;"/>{WORK}
  <UnsetBlackboard key="w"/>{WORK}
</Sequence></BehaviorTree></root>"""


def test_large_values_are_not_copied_into_every_snapshot(tmp_path: Path) -> None:
    path = tmp_path / "big.mcap"
    tree = load_tree_text(TREE)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    executor.subscribe(Recorder(path, tree, {"domain": "big"}))
    executor.run(max_ticks=500)
    executor.close()
    recording = open_recording(path)
    with open_runs(path, cache=False, snapshot_every=16) as database:
        run = database.run()
        _c, [(snapshots, stored)] = database.sql(
            f"SELECT count(*), sum(strlen(state::VARCHAR)) FROM {run.snapshots_table()}"
        )
        assert snapshots > 40
        assert stored < 64 * 1024, "no snapshot holds a copy of the 64 KiB value"
        projection = StateProjection(recording.tree)
        events = recording.events
        for count in range(len(events) + 1):
            if count % 7 == 0 or count == len(events):
                _tree, state = run.state_after(count)
                assert state.blackboard == projection.state.blackboard, count
                assert state.seq == projection.state.seq
            if count < len(events):
                projection.apply(events[count])
        final = projection.state.blackboard[""]
        assert final["v"] == "small" and "w" not in final

"""BehaviorTree.CPP's teardown: a destroyed tree is halted, and btlog records it.

When a BT.CPP tree is destroyed, ``haltTree`` halts what still runs and resets every node
left non-IDLE (a SequenceWithMemory's completed children, a run stopped by --max-ticks);
loggers see those transitions after the run's last tick. btlog records them as the run's
last events, in a tick of their own marked ``teardown`` in ``ticks`` (the differential
test compares the complete streams with BT.CPP's). Answers at ``end`` are those of the
state after the teardown, and equal the answers right after the last real tick.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.explain.questions import explain
from btlog.replay.database import open_runs
from btlog.runner import RunConfig, execute
from tests.cli_support import btlog

ROOT = Path(__file__).resolve().parent.parent
MEMORY_TREE = """<root BTCPP_format="4"><BehaviorTree ID="Main">
<SequenceWithMemory name="assemble"><Action ID="fetch" name="fetch"/>
<Action ID="mount" name="mount"/></SequenceWithMemory></BehaviorTree></root>"""


def test_teardown_is_the_recordings_last_tick(tmp_path: Path) -> None:
    """mount fails, the run ends FAILURE with fetch still SUCCESS (memory); the teardown
    tick resets it, as BT.CPP's StdCoutLogger shows after the run ended."""
    (tmp_path / "memory.xml").write_text(MEMORY_TREE, encoding="utf-8")
    (tmp_path / "outcomes.yaml").write_text(
        "default: {status: SUCCESS, duration: 0.2}\nnodes: {mount: [FAILURE]}\n", encoding="utf-8"
    )
    run = btlog("run", "memory.xml", "--outcomes", "outcomes.yaml", "-o", "m.mcap", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "ticks: 5  final status: FAILURE" in run.stdout
    ticks = btlog(
        "sql", "m.mcap", "SELECT tick, root_status, teardown FROM ticks ORDER BY tick",
        "--format", "csv", cwd=tmp_path,
    )  # fmt: skip
    assert ticks.stdout.splitlines()[-2:] == ["5,FAILURE,False", "6,IDLE,True"]
    last = btlog(
        "sql", "m.mcap",
        "SELECT n.name, t.prev_status, t.status FROM transitions t JOIN nodes n USING (uid) "
        "WHERE t.tick = 6 ORDER BY t.seq", "--format", "csv", cwd=tmp_path,
    )  # fmt: skip
    assert last.stdout.splitlines()[1:] == ["fetch,SUCCESS,IDLE"]
    final = btlog("sql", "m.mcap", "SELECT final_status FROM runs", "--format", "csv", cwd=tmp_path)
    assert final.stdout.split() == ["final_status", "FAILURE"]
    shown = btlog("show", "m.mcap", "--at", "end", "--plain", cwd=tmp_path)
    assert "SUCCESS" not in shown.stdout and shown.stdout.count("IDLE") == 3
    before = btlog("show", "m.mcap", "--at", "tick:5", "--plain", cwd=tmp_path)
    assert "fetch  #2  SUCCESS" in before.stdout


@pytest.mark.parametrize(
    ("tree", "domain", "options"),
    [
        ("trees/kitting.xml", "kitting", {"fail": ["look at chuck"]}),
        ("trees/kitting.xml", "kitting", {"max_ticks": 300}),
        ("trees/kitting.xml", "kitting", {"failure_rate": 0.3, "seed": 4}),
        ("trees/taxi.xml", "taxi", {"fail": ["pick up passenger"]}),
    ],
    ids=["retried-failure", "max-ticks", "failure-rate", "taxi-fails"],
)
def test_answers_at_end_are_those_after_the_last_tick(
    tree: str, domain: str, options: dict, tmp_path: Path
) -> None:
    """The teardown changes statuses, never the answers: ``end`` answers as the moment
    right after the last real tick (where, for a stopped run, the old recording halted)."""
    result = execute(
        RunConfig(tree=str(ROOT / tree), domain=domain, **options), tmp_path / "r.mcap"
    )
    with open_runs(tmp_path / "r.mcap", cache=False) as database:
        run = database.run()
        at_end = explain(*run.state_at("end"))
        last_tick = explain(*run.state_at(f"tick:{result.ticks}"))
        _, [(teardown_tick,)] = database.sql("SELECT tick FROM ticks WHERE teardown")
    assert [a.text for a in at_end] == [a.text for a in last_tick]
    assert teardown_tick == result.ticks + 1


def test_live_answer_at_end_is_the_post_hoc_one(tmp_path: Path) -> None:
    """Asked live at ``end``, the answer comes after the teardown, as ``ask --at end``."""
    live = btlog(
        "run", str(ROOT / "trees/kitting.xml"), "--domain", "kitting", "--max-ticks", "300",
        "--ask", "end=What are you doing?", "-o", "k.mcap", cwd=tmp_path,
    )  # fmt: skip
    assert live.returncode == 0, live.stderr
    post = btlog("ask", "k.mcap", "--at", "end", "What are you doing?", cwd=tmp_path)
    assert post.returncode == 0, post.stderr
    assert live.stdout.splitlines()[1].strip() == post.stdout.strip() != ""

"""The snapshots built as SQL over the tables equal the ``StateProjection`` fold (issue 16).

The projection is the single definition of the state: for random outcomes (failures,
retries, blackboard writes, a tree mutation at a random tick) and a random snapshot
interval K, every stored snapshot — the state before event b, b a multiple of K — read
back as a ``State`` equals the live projection's state after b events, derived state
(activations, last failures, retry attempts, the last leaf) included.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from btlog.replay import snapshots
from btlog.replay.blocks import EventBatch
from btlog.replay.database import open_runs
from btlog.replay.snapshots import load_snapshot, snapshot_rows
from btlog.state import State
from tests.test_replay import DEFAULT, KITTING, PROPERTY, canonical, record, scripts_for


def assert_snapshots_equal_the_fold(path: Path, states: list[dict], every: int) -> list[dict]:
    """Every snapshot of ``path`` at interval ``every`` equals the live state after as
    many events; returns the snapshots' states."""
    with open_runs(path, cache=False, snapshot_every=every) as database:
        run = database.run()
        rows = database.con.execute(f"SELECT seq, state FROM {run.snapshots_table()} ORDER BY seq")
        found = []
        for seq, text in rows.fetchall():
            state = canonical(
                State.from_json(load_snapshot(database.con, run.stored_id, text, "run0."))
            )
            expected = canonical(State()) if seq == 0 else states[seq - 1]
            assert state == expected, f"snapshot before event {seq}"
            found.append(state)
    assert len(found) == len(states) // every + 1
    return found


@PROPERTY
@given(
    scripts=scripts_for(KITTING),
    every=st.integers(1, 9),
    mutate_at=st.one_of(st.none(), st.integers(2, 40)),
)
def test_sql_snapshots_equal_the_projection_fold(
    tmp_path_factory, scripts: dict, every: int, mutate_at: int | None
) -> None:
    path: Path = tmp_path_factory.mktemp("snap") / "run.mcap"
    outcomes = {"default": {"status": "SUCCESS", "ticks": 1}, "nodes": scripts}
    live = record(path, KITTING, outcomes, max_ticks=60, mutate_at=mutate_at)
    assert_snapshots_equal_the_fold(path, live.states, every)


NAV2 = Path(__file__).resolve().parent.parent / "trees" / "nav2" / "navigate_to_pose.xml"


@PROPERTY
@given(scripts=scripts_for(NAV2), every=st.integers(1, 9))
def test_sql_snapshots_equal_the_fold_where_nodes_halt_before_returning(
    tmp_path_factory, scripts: dict, every: int
) -> None:
    """Nav2's RecoveryNode halts itself, then returns its result: the result ends the
    activation the halt interrupted (``btlog.history.resumes``), also when a snapshot
    boundary falls between the two changes."""
    path: Path = tmp_path_factory.mktemp("nav2") / "run.mcap"
    outcomes = {"default": {"status": "SUCCESS", "ticks": 1}, "nodes": scripts}
    live = record(path, NAV2, outcomes, max_ticks=60)
    assert_snapshots_equal_the_fold(path, live.states, every)


def test_sql_snapshots_hold_retry_attempts_and_failures(tmp_path: Path) -> None:
    path = tmp_path / "retry.mcap"
    scripts = {"trial and error insert": ["FAILURE", "FAILURE", "SUCCESS"]}
    live = record(path, KITTING, {"default": DEFAULT, "nodes": scripts}, max_ticks=40)
    found = assert_snapshots_equal_the_fold(path, live.states, 1)
    assert any(state["retry_attempts"] for state in found)
    assert any(state["last_failure"] for state in found)


def test_event_blocks_hold_status_changes_in_seq_order_whatever_the_row_order(
    tmp_path: Path,
) -> None:
    """A snapshot's block of events is cut from ``transitions`` in seq order, also when
    the table's rows are not stored in that order."""
    path = tmp_path / "run.mcap"
    record(path, KITTING, {"default": DEFAULT}, max_ticks=20)
    with open_runs(path, cache=False, snapshot_every=8) as database:
        run = database.run()
        con, params = database.con, {"run_id": run.stored_id}
        con.execute("USE run0")
        stored = snapshot_rows(con, run.stored_id, run.tree, run.info.events, 8)
        con.execute("CREATE TABLE shuffled AS FROM transitions ORDER BY seq DESC")
        con.execute("DELETE FROM transitions WHERE run_id = $run_id", params)
        con.execute("INSERT INTO transitions FROM shuffled")
        reversed_rows = snapshot_rows(con, run.stored_id, run.tree, run.info.events, 8)
        con.execute("USE memory")
    blocks = [EventBatch.from_block(b, []) for b in stored["events"].to_pylist()]
    assert [b.seq for b in blocks] == [
        EventBatch.from_block(b, []).seq for b in reversed_rows["events"].to_pylist()
    ]
    seqs = [seq for block in blocks for seq in block.seq]
    assert seqs == sorted(seqs) and len(seqs) > 16
    assert all(seq // 8 == i for i, block in enumerate(blocks) for seq in block.seq)


@PROPERTY
@given(
    scripts=scripts_for(KITTING),
    every=st.integers(1, 5),
    blocks=st.integers(1, 7),
    mutate_at=st.one_of(st.none(), st.integers(2, 40)),
)
def test_snapshots_built_a_segment_at_a_time_equal_the_fold(
    tmp_path_factory, scripts: dict, every: int, blocks: int, mutate_at: int | None
) -> None:
    """Segments of a few snapshots each (issue 27): what holds at a segment's first
    boundary comes from the events before it, blackboard entries and retry counts too."""
    path: Path = tmp_path_factory.mktemp("seg") / "run.mcap"
    outcomes = {"default": {"status": "SUCCESS", "ticks": 1}, "nodes": scripts}
    live = record(path, KITTING, outcomes, max_ticks=60, mutate_at=mutate_at)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(snapshots, "SEGMENT_BLOCKS", blocks)
        assert_snapshots_equal_the_fold(path, live.states, every)


def test_a_first_answer_early_builds_only_the_snapshots_it_needs(tmp_path: Path) -> None:
    """A state at an early moment builds the snapshots of its segment only (one file
    beside the cache); a later moment builds its own; the states equal those of a run
    read into memory (all snapshots), for moments given as seqs, times and ticks."""
    path = tmp_path / "run.mcap"
    scripts = {"trial and error insert": ["FAILURE", "FAILURE", "SUCCESS"]}
    live = record(path, KITTING, {"default": DEFAULT, "nodes": scripts}, max_ticks=60)
    cache_dir = tmp_path / "cache"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(snapshots, "SEGMENT_BLOCKS", 4)
        with open_runs(path, cache_dir=cache_dir, snapshot_every=4) as database:
            run = database.run()
            assert not list(cache_dir.glob("*.snapshots.duckdb"))
            assert canonical(run.state_at("seq:3")[1]) == live.states[3]
            built = sorted(p.name for p in cache_dir.glob("*.snapshots.duckdb"))
            assert len(built) == 1 and built[0].endswith(".0.snapshots.duckdb")
            last = len(live.states)
            assert canonical(run.state_at("end")[1]) == live.states[last - 1]
            assert len(list(cache_dir.glob("*.snapshots.duckdb"))) == 2
            segments = snapshots.segments(last, 4)
            assert segments > 2  # the segments between were never built
            moments = ["0.35s", "2.05s", "tick:7", "tick:31", "seq:40", "-1s"]
            cached = [canonical(run.state_at(m)[1]) for m in moments]
            keys = [run.resolve(m).to_json() for m in moments]
        with open_runs(path, cache=False, snapshot_every=4) as database:
            run = database.run()
            assert [canonical(run.state_at(m)[1]) for m in moments] == cached
            assert [run.resolve(m).to_json() for m in moments] == keys

"""A long recording read in parts, each in a process of its own, gives the same read model.

``btlog.replay.parts`` cuts a finished recording at chunk boundaries and scans each part
in a process; the status changes of each part go to a Parquet file of their own. Here a
run recorded into many small chunks is read whole and in parts (``BTLOG_PART_BYTES``
makes its parts small): every table, row for row, and the states and answers at several
moments must be the same; a damaged chunk in a later part is told the same way; a cut
file (no summary) is read in one part.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.executor.engine import Executor
from btlog.record import Recorder
from btlog.replay import cache, parts
from btlog.replay.database import open_runs
from btlog.tree.loader import load_tree_text
from tests.cli_support import btlog

LOOP = """<root BTCPP_format="4"><BehaviorTree ID="MainTree">
  <KeepRunningUntilFailure><Sequence name="work">
    <Action ID="Look" name="look"/><Fallback name="get">
      <Action ID="Grasp" name="grasp"/><Action ID="Regrasp" name="regrasp"/></Fallback>
    <Script code="count := 1"/><Action ID="Place" name="place"/>
  </Sequence></KeepRunningUntilFailure>
</BehaviorTree></root>"""
OUTCOMES = {
    "default": {"status": "SUCCESS", "ticks": 2},
    "nodes": {"grasp": ["FAILURE", "SUCCESS", "SUCCESS"] * 400},
}
TABLES = ("runs", "nodes", "transitions", "blackboard", "ticks", "mutations")
PART_BYTES = 4096


def record(path: Path, ticks: int = 3000) -> Path:
    """A looping run (failures, blackboard writes) recorded into many small chunks."""
    tree = load_tree_text(LOOP)
    executor = Executor(
        tree, leaf_factory=scripted_leaf_factory(tree, Outcomes.from_mapping(OUTCOMES))
    )
    recorder = Recorder(
        path, tree, {"domain": "loop"}, flush_interval=3600, chunk_size=2048, group_events=40
    )
    executor.subscribe(recorder)
    executor.run(max_ticks=ticks)
    executor.close()
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    return record(tmp_path_factory.mktemp("parts") / "loop.mcap")


def read_model(path: Path, cache_dir: Path | None) -> dict[str, list[tuple]]:
    """Every public table's rows, their column types, and the states at a few moments
    (``cache_dir`` None: read into memory, with ``transitions`` a DuckDB table)."""
    with open_runs(path, cache=cache_dir is not None, cache_dir=cache_dir) as db:
        tables = {table: db.sql(f"SELECT * FROM {table} ORDER BY ALL")[1] for table in TABLES}
        tables["types"] = db.sql(
            "SELECT typeof(prev_status), typeof(status), typeof(seq), typeof(uid) "
            "FROM transitions LIMIT 1"
        )[1]
        run = db.run()
        tables["states"] = [
            (sorted(state.status.items()), str(state.blackboard))
            for moment in ("0.5s", "tick:100", "tick:1501", "end")
            for _tree, state in [run.state_at(moment)]
        ]
    return tables


def test_a_recording_read_in_parts_gives_the_read_model_of_one_read(
    recording, tmp_path, monkeypatch
):
    whole = read_model(recording, tmp_path / "whole")
    assert whole == read_model(recording, None)  # the Parquet view gives the table's rows
    assert whole["types"][0][0].startswith("ENUM(")
    assert len(cache.transitions_paths(cache.entries(tmp_path / "whole")[0].path)) == 1
    monkeypatch.setenv("BTLOG_PART_BYTES", str(PART_BYTES))
    planned = parts.plan(str(recording))
    if min(os.cpu_count() or 1, len(os.sched_getaffinity(0))) < 2:
        assert len(planned) == 1
    else:
        assert len(planned) == min(len(os.sched_getaffinity(0)), parts.MAX_PARTS)
        assert planned[0].start == 8 and planned[-1].stop is None
        assert [part.stop for part in planned[:-1]] == [part.start for part in planned[1:]]
    in_parts = read_model(recording, tmp_path / "parts")
    files = [
        file
        for entry in cache.entries(tmp_path / "parts")
        for file in cache.transitions_paths(entry.path)
    ]
    assert len(files) == len(planned)
    assert whole["transitions"] and whole["blackboard"] and whole["ticks"]
    for table in whole:
        assert in_parts[table] == whole[table], table


def test_answers_from_a_cache_read_in_parts_are_the_same(recording, tmp_path):
    question = ["ask", str(recording), "--at", "tick:1500", "What went wrong?"]
    whole = btlog(*question, "--cache-dir", str(tmp_path / "whole"))
    in_parts = btlog(
        *question,
        "--cache-dir",
        str(tmp_path / "parts"),
        env={"BTLOG_PART_BYTES": str(PART_BYTES)},
    )
    assert whole.returncode == 0, whole.stderr
    assert in_parts.stdout == whole.stdout and "grasp" in whole.stdout
    sql = btlog(
        "sql",
        str(recording),
        "SELECT status, count(*) FROM transitions GROUP BY ALL ORDER BY ALL",
        "--cache-dir",
        str(tmp_path / "parts"),
    )
    assert sql.returncode == 0 and "FAILURE" in sql.stdout, sql.stderr


def test_users_sql_reads_the_transitions_files_and_no_other_file(recording, tmp_path):
    other = tmp_path / "other.parquet"
    btlog("sql", str(recording), "SELECT 1", "--cache-dir", str(tmp_path / "c"))
    (entry,) = [e for e in cache.entries(tmp_path / "c") if "snapshots" not in e.path.name]
    (file,) = cache.transitions_paths(entry.path)
    other.write_bytes(file.read_bytes())
    refused = btlog(
        "sql",
        str(recording),
        f"SELECT count(*) FROM read_parquet('{other}')",
        "--cache-dir",
        str(tmp_path / "c"),
    )
    assert refused.returncode != 0 and "Traceback" not in refused.stderr


def test_a_cut_recording_is_read_in_one_part(recording, tmp_path, monkeypatch):
    cut = tmp_path / "cut.mcap"
    data = recording.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    monkeypatch.setenv("BTLOG_PART_BYTES", str(PART_BYTES))
    assert parts.plan(str(cut)) == [parts.Part(8, None)]


def test_clearing_and_evicting_a_cache_removes_its_transitions_files(recording, tmp_path):
    root = tmp_path / "c"
    btlog("sql", str(recording), "SELECT 1", "--cache-dir", str(root))
    assert list(root.glob("*.parquet"))
    (entry,) = [e for e in cache.entries(root) if "snapshots" not in e.path.name]
    assert entry.size > entry.path.stat().st_size  # its transitions file is counted
    assert cache.evict(root, 0, set()) == [entry.path]
    assert not list(root.glob("*.parquet"))
    btlog("sql", str(recording), "SELECT 1", "--cache-dir", str(root))
    removed, freed = cache.clear(root)
    assert removed == 1 and freed > 0 and not list(root.glob("*.parquet"))


def test_a_cache_whose_transitions_file_is_gone_is_built_again(recording, tmp_path):
    root = tmp_path / "c"
    question = ["ask", str(recording), "--at", "end", "What are you doing?"]
    first = btlog(*question, "--cache-dir", str(root))
    for file in root.glob("*.parquet"):
        file.unlink()
    again = btlog(*question, "--cache-dir", str(root))
    assert again.returncode == 0 and again.stdout == first.stdout, again.stderr
    assert list(root.glob("*.parquet"))


def test_the_summary_counts_the_messages_that_decide_the_parts(recording, tmp_path):
    from mcap.reader import make_reader

    from btlog.record.walk import mapped, summary_message_count

    with open(recording, "rb") as file:
        messages = sum(1 for _ in make_reader(file).iter_messages())
    with mapped(recording) as (data, size):
        assert summary_message_count(data, size) == messages > 1000
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[:-100])
    with mapped(cut) as (data, size):
        assert summary_message_count(data, size) is None  # no sound summary: no hint

"""A fleet of runs: export to a Parquet lake, the fleet report, SQL over the lake, Spark."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from btlog.fleet.compact import compact_lake
from btlog.fleet.lake import LAKE_TABLES, export_runs, open_lake
from btlog.fleet.lock import lake_lock
from btlog.fleet.report import duckdb_report
from btlog.replay.database import open_runs
from btlog.runner import RunConfig, execute
from tests.cli_support import assert_bad_input, btlog, btlog_command, btlog_environment

ROOT = Path(__file__).resolve().parent.parent
KITTING = str(ROOT / "trees" / "kitting.xml")
TAXI = str(ROOT / "trees" / "taxi.xml")


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> list[Path]:
    """Six kitting runs with random failures and two taxi runs, one of them failing."""
    folder = tmp_path_factory.mktemp("fleet-runs")
    made = []
    for seed in range(1, 7):
        config = RunConfig(tree=KITTING, domain="kitting", seed=seed, failure_rate=0.3)
        made.append(execute(config, folder / f"kitting-{seed}.mcap").path)
    made.append(execute(RunConfig(tree=TAXI, domain="taxi"), folder / "taxi-ok.mcap").path)
    failing = RunConfig(tree=TAXI, domain="taxi", fail=["pick up passenger"])
    made.append(execute(failing, folder / "taxi-fail.mcap").path)
    return [Path(p) for p in made]


@pytest.fixture(scope="module")
def lake(runs, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("fleet") / "lake"
    done = btlog("export", *map(str, runs), "--parquet", str(folder))
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"{len(runs)} runs")
    assert done.stdout.rstrip().endswith("(2 partitions)")
    return folder


def test_layout_is_hive_partitioned_by_domain_and_date_one_file_each(lake, runs):
    """After an export, each table has one file per domain=/date= partition, run_id a
    column of it."""
    for table in LAKE_TABLES:
        files = sorted(lake.glob(f"{table}/*/*/*.parquet"))
        assert {f.parts[-3] for f in files} == {"domain=kitting", "domain=taxi"}, table
        assert all(f.parts[-2].startswith("date=") for f in files)
        assert all(f.name.startswith("part-") for f in files)
        partitions = {f.parent for f in files}
        assert len(files) == len(partitions), table
    con = open_lake(lake)
    assert con.execute("SELECT count(DISTINCT run_id) FROM transitions").fetchone() == (len(runs),)


def test_lake_tables_hold_the_read_models_rows(lake, runs):
    """Every table of every run, row for row, as the read model has it."""
    con = open_lake(lake)
    with open_runs(*runs, cache=False) as database:
        for table, key in (("transitions", "seq"), ("blackboard", "seq"), ("nodes", "uid")):
            ours = database.sql(f"SELECT count(*), sum({key}) FROM {table}")[1]
            theirs = con.execute(f"SELECT count(*), sum({key}) FROM {table}").fetchall()
            assert ours == theirs, table
        finals = sorted(r[0] for r in database.sql("SELECT final_status FROM runs")[1])
    assert sorted(r[0] for r in con.execute("SELECT final_status FROM runs").fetchall()) == finals


def test_fleet_report_counts_match_the_runs(lake, runs):
    report = duckdb_report(str(lake))
    assert report.runs == len(runs)
    with open_runs(*runs, cache=False) as database:
        expected = dict(database.sql("SELECT final_status, count(*) FROM runs GROUP BY ALL")[1])
        starts = database.sql(
            "SELECT n.path, n.uid, count(*) FROM transitions t JOIN nodes n USING (run_id, uid) "
            "WHERE t.prev_status = 'IDLE' AND t.status <> 'IDLE' GROUP BY ALL"
        )[1]
        failures = database.sql(
            "SELECT n.path, n.uid, count(*) FROM transitions t JOIN nodes n USING (run_id, uid) "
            "WHERE t.status = 'FAILURE' GROUP BY ALL"
        )[1]
    assert {r["final_status"]: r["runs"] for r in report.outcomes} == {
        str(k): v for k, v in expected.items()
    }
    activations = {(r["path"], r["uid"]): r["activations"] for r in report.nodes}
    assert activations == {(p, u): n for p, u, n in starts}
    failed = {(r["path"], r["uid"]): r["failed"] for r in report.nodes if r["failed"]}
    assert failed == {(p, u): n for p, u, n in failures}
    for row in report.nodes:
        if row["completed"]:
            assert row["failure_rate"] == pytest.approx(row["failed"] / row["completed"], abs=1e-6)
            assert 0 <= row["p50_s"] <= row["p90_s"] <= row["p99_s"]


#: The per-node report as it was computed before the lake had an ``activations`` table:
#: straight from every transition (the oracle for the table written at export).
NODES_FROM_TRANSITIONS = """
WITH numbered AS (
  SELECT t.run_id, t.uid, t.t_ns, CAST(t.status AS VARCHAR) AS status,
         sum(CASE WHEN CAST(t.prev_status AS VARCHAR) = 'IDLE'
                   AND CAST(t.status AS VARCHAR) <> 'IDLE' THEN 1 ELSE 0 END)
           OVER (PARTITION BY t.run_id, t.uid ORDER BY t.seq) AS activation
  FROM transitions t
), activations AS (
  SELECT run_id, uid, activation, min(t_ns) AS start_ns,
         max(CASE WHEN status IN ('SUCCESS', 'FAILURE') THEN t_ns END) AS end_ns,
         max(CASE WHEN status = 'FAILURE' THEN 1 ELSE 0 END) AS failed,
         max(CASE WHEN status IN ('SUCCESS', 'FAILURE') THEN 1 ELSE 0 END) AS completed
  FROM numbered WHERE activation > 0 AND status <> 'IDLE' GROUP BY ALL
)
SELECT n.path, n.uid, count(*), sum(completed), sum(failed),
       quantile_cont(CASE WHEN completed = 1 THEN (end_ns - start_ns) / 1e9 END, 0.5),
       quantile_cont(CASE WHEN completed = 1 THEN (end_ns - start_ns) / 1e9 END, 0.9),
       quantile_cont(CASE WHEN completed = 1 THEN (end_ns - start_ns) / 1e9 END, 0.99)
FROM activations a JOIN nodes n USING (run_id, uid) GROUP BY n.path, n.uid
"""


def test_node_rows_equal_the_aggregate_over_every_transition(lake, runs):
    """The report reads the activations table; its numbers are those of the same
    aggregate over every transition of the read model."""
    with open_runs(*runs, cache=False) as database:
        expected = {
            (row[0], row[1]): [None if v is None else round(float(v), 6) for v in row[2:]]
            for row in database.sql(NODES_FROM_TRANSITIONS)[1]
        }
    got = {
        (r["path"], r["uid"]): [
            r[k] for k in ("activations", "completed", "failed", "p50_s", "p90_s", "p99_s")
        ]
        for r in duckdb_report(str(lake)).nodes
    }
    assert got == expected


def test_causes_follow_the_causal_chain(lake):
    """The failed taxi run: its root failed because pick up passenger failed."""
    report = duckdb_report(str(lake), domain="taxi")
    assert report.runs == 2
    causes = {(r["failed_node"], r["cause"], r["verb"]) for r in report.causes}
    assert ("go deliver passenger", "pick up passenger", "failed") in causes


def test_failures_by_design_are_no_causes(lake):
    """The kitting tree's clean-up "reset arm" (a ForceFailure over "retreat arm") fails
    by design after every failed insertion: when "retreat arm" succeeded, that failure
    caused nothing to go wrong, and the lake's causes leave it out (a failing "retreat
    arm" is a real cause and stays)."""
    made = btlog(
        "sql",
        "--lake",
        str(lake),
        "--format",
        "csv",
        "SELECT count(*) FROM transitions t JOIN nodes n USING (run_id, uid) "
        "WHERE n.name = 'reset arm' AND t.status = 'FAILURE'",
    )
    assert made.returncode == 0, made.stderr
    assert int(made.stdout.split()[-1]) > 0  # the clean-up ran and failed in these runs
    report = duckdb_report(str(lake), domain="kitting")
    assert report.causes
    assert all(r["verb"] == "failed" for r in report.causes)
    assert ("reset arm", "retreat arm", "succeeded") not in {
        (r["failed_node"], r["cause"], r["verb"]) for r in report.causes
    }


def test_fleet_command_prints_the_report_and_json(lake, runs):
    shown = btlog("fleet", str(lake))
    assert shown.returncode == 0, shown.stderr
    assert f"{len(runs)} runs:" in shown.stdout
    taxi = btlog("fleet", str(lake), "--domain", "taxi")
    assert "2 runs: 1 FAILURE, 1 SUCCESS" in taxi.stdout
    assert "pick up passenger" in taxi.stdout
    as_json = btlog("fleet", str(lake), "--domain", "kitting", "--json")
    assert as_json.returncode == 0
    assert json.loads(as_json.stdout)["runs"] == 6


def test_a_partition_filter_reads_only_its_partitions(lake, tmp_path):
    """With the taxi files made unreadable garbage, a kitting query still answers (it
    never opened them) while an unfiltered one fails."""
    copy = tmp_path / "lake"
    shutil.copytree(lake, copy)
    for file in copy.glob("*/domain=taxi/*/*.parquet"):
        file.write_bytes(b"not parquet at all")
    only = btlog(
        "sql", "--lake", str(copy), "SELECT count(*) FROM transitions WHERE domain = 'kitting'"
    )
    assert only.returncode == 0, only.stderr
    every = btlog("sql", "--lake", str(copy), "SELECT count(*) FROM transitions")
    assert every.returncode == 2
    assert every.stderr.count("\n") == 1
    report = btlog("fleet", str(copy), "--domain", "kitting", "--json")
    assert report.returncode == 0, report.stderr
    assert btlog("fleet", str(copy)).returncode == 2


def test_lake_sql_is_read_only(lake):
    for query in (
        f"COPY runs TO '{lake}/../leak.csv'",
        "SELECT * FROM read_csv('/etc/passwd')",
        "ATTACH 'x.duckdb' AS x",
    ):
        done = btlog("sql", "--lake", str(lake), query)
        assert done.returncode == 2, query
        assert "Traceback" not in done.stderr
    assert not (lake.parent / "leak.csv").exists()


@pytest.mark.parametrize("query", ["", "  ", "-- a comment", ";"])
def test_lake_sql_without_a_statement_is_bad_input(lake, query):
    assert_bad_input(btlog("sql", "--lake", str(lake), query), "no statement")


def test_reexport_replaces_a_runs_rows(lake, runs, tmp_path):
    copy = tmp_path / "lake"
    shutil.copytree(lake, copy)
    export_runs([runs[0], runs[-1]], copy)
    assert duckdb_report(str(copy)).to_json() == duckdb_report(str(lake)).to_json()
    assert len(list(copy.glob("transitions/*/*/*.parquet"))) == 2


def _loose_copy(lake: Path, runs: list[Path], folder: Path) -> Path:
    """``lake`` copied to ``folder`` with ``runs`` exported again without compaction."""
    copy = folder / "lake"
    shutil.copytree(lake, copy)
    export_runs(runs, copy, compact=False)
    return copy


def test_an_uncompacted_lake_reads_the_same_and_compacts(lake, runs, tmp_path):
    """Per-run files of re-exported runs beside the merged file: the newest rows win."""
    copy = _loose_copy(lake, runs[:3], tmp_path)
    files = list(copy.glob("transitions/domain=kitting/*/*.parquet"))
    assert sorted(f.name.split("-")[0] for f in files) == ["part", "run", "run", "run"]
    assert compact_lake(copy) == 1
    assert duckdb_report(str(copy)).to_json() == duckdb_report(str(lake)).to_json()
    assert compact_lake(copy) == 0  # nothing left to merge


def test_a_run_whose_export_stopped_before_its_runs_file_is_left_out(lake, runs, tmp_path):
    """An export that stopped after some tables: those files are ignored at compaction."""
    fresh = tmp_path / "fresh"
    export_runs(runs[:1], fresh, compact=False)
    (loose,) = fresh.glob("runs/*/*/run-*.parquet")
    loose.unlink()
    partial = tmp_path / "lake"
    shutil.copytree(lake, partial)
    for file in fresh.glob("*/*/*/run-*.parquet"):
        target = partial / file.relative_to(fresh)
        target.unlink(missing_ok=True)
        shutil.copy(file, target)
    (partial / "runs/domain=kitting").mkdir(exist_ok=True)
    done = btlog("fleet", str(partial), "--compact", "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == duckdb_report(str(lake)).to_json()
    assert not list(partial.glob("*/*/*/run-*.parquet"))


def test_a_compaction_interrupted_before_removing_its_inputs_loses_nothing(lake, runs, tmp_path):
    """Merged file renamed into place, inputs still there (a crash between the two):
    the lake reads (some runs twice) and the next compaction restores it exactly; a
    temporary file left behind is never read and is removed."""
    copy = _loose_copy(lake, runs[:2], tmp_path)
    inputs = tmp_path / "inputs"
    shutil.copytree(copy, inputs)
    compact_lake(copy)
    for file in inputs.glob("*/*/*/*.parquet"):
        shutil.copy(file, copy / file.relative_to(inputs))
    (temporary,) = copy.glob("runs/domain=kitting/*/")
    (temporary / ".part-1.parquet.tmp").write_bytes(b"half a file")
    con = open_lake(copy)
    distinct, rows = con.execute("SELECT count(DISTINCT run_id), count(*) FROM runs").fetchone()
    assert distinct == len(runs) and rows > len(runs)  # kitting runs twice, until compacted
    con.close()
    assert compact_lake(copy) == 1  # the kitting partition; taxi's was one file already
    assert duckdb_report(str(copy)).to_json() == duckdb_report(str(lake)).to_json()
    assert not list(copy.glob("**/.*.tmp"))


@pytest.mark.parametrize(
    "args",
    [
        ("fleet", "/nonexistent-lake"),
        ("fleet", "{tmp}", "--date", "yesterday"),
        ("export", "{tmp}/missing.mcap", "--parquet", "{tmp}/lake"),
        ("sql", "--lake", "{tmp}", "SELECT 1"),
    ],
)
def test_bad_input_is_one_line(args, tmp_path):
    done = btlog(*(a.format(tmp=tmp_path) for a in args))
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr


def _spark_ready() -> str | None:
    try:
        import pyspark  # noqa: F401
    except ImportError:
        return "pyspark is not installed (pip install '.[spark]')"
    if shutil.which("java") is None and not os.environ.get("JAVA_HOME"):
        return "no Java runtime (apt-get install default-jre-headless)"
    return None


@pytest.mark.skipif(_spark_ready() is not None, reason=str(_spark_ready()))
def test_spark_job_gives_the_same_report_as_duckdb(lake):
    """The PySpark job, in Spark's local mode, on the same lake: the same numbers."""
    done = subprocess.run(
        [sys.executable, "-m", "btlog.fleet.spark", str(lake), "--master", "local[1]"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout) == duckdb_report(str(lake)).to_json()


def test_export_in_processes_writes_the_same_lake(lake, runs, tmp_path):
    """--jobs 2: the same report; a bad recording among them is one line, exit 2."""
    folder = tmp_path / "lake"
    done = btlog("export", *map(str, runs), "--parquet", str(folder), "--jobs", "2")
    assert done.returncode == 0, done.stderr
    assert duckdb_report(str(folder)).to_json() == duckdb_report(str(lake)).to_json()
    assert len(list(folder.glob("runs/*/*/*.parquet"))) == 2
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not a recording")
    failed = btlog(
        "export", str(runs[0]), str(bad), "--parquet", str(tmp_path / "l2"), "--jobs", "2"
    )
    assert failed.returncode == 2
    assert failed.stderr.count("\n") == 1 and "bad.mcap" in failed.stderr


def test_exports_into_one_lake_at_once_give_the_lake_of_one_export(lake, runs, tmp_path):
    """Two CI jobs exporting into one shared lake: the same report as one export."""
    folder = tmp_path / "shared"
    halves = [runs[0::2], runs[1::2]]
    jobs = [
        subprocess.Popen(
            btlog_command("export", *half, "--parquet", folder), env=btlog_environment()
        )
        for half in halves
    ]
    assert [job.wait(timeout=120) for job in jobs] == [0, 0]
    compact_lake(folder)  # the two final compactions may each have left the other's files
    assert duckdb_report(str(folder)).to_json() == duckdb_report(str(lake)).to_json()
    assert len(list(folder.glob("transitions/*/*/*.parquet"))) == 2


@pytest.mark.parametrize(
    ("held", "command"),
    [(False, ["fleet", "{lake}", "--compact", "--json"]), (True, ["fleet", "{lake}", "--json"])],
    ids=["a compaction waits for a reader", "a reader waits for a compaction"],
)
def test_compaction_and_readers_wait_for_each_other(lake, tmp_path, held, command):
    copy = tmp_path / "lake"
    shutil.copytree(lake, copy)
    arguments = [part.format(lake=copy) for part in command]
    with lake_lock(copy, exclusive=held):
        waiting = subprocess.Popen(
            btlog_command(*arguments),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=btlog_environment(),
        )
        with pytest.raises(subprocess.TimeoutExpired):
            waiting.wait(timeout=3)  # the other side holds the lock
    out, err = waiting.communicate(timeout=60)
    assert waiting.returncode == 0, err
    assert json.loads(out) == duckdb_report(str(lake)).to_json()


def test_reading_a_folder_that_is_no_lake_leaves_nothing_behind(tmp_path):
    done = btlog("fleet", str(tmp_path))
    assert done.returncode == 2 and "not a btlog lake" in done.stderr
    assert list(tmp_path.iterdir()) == []

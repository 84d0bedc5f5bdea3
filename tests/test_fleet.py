"""A fleet of runs: export to a Parquet lake, the fleet report, SQL over the lake, Spark."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from btlog.fleet.lake import export_runs, open_lake
from btlog.fleet.report import duckdb_report
from btlog.replay.database import open_runs
from btlog.runner import RunConfig, execute

ROOT = Path(__file__).resolve().parent.parent
KITTING = str(ROOT / "trees" / "kitting.xml")
TAXI = str(ROOT / "trees" / "taxi.xml")


def btlog(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "btlog.cli.main", *args], capture_output=True, text=True
    )


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
    return folder


def test_layout_is_hive_partitioned_by_domain_date_and_run(lake, runs):
    files = sorted(lake.glob("transitions/*/*/*/data.parquet"))
    assert len(files) == len(runs)
    domains = {f.parts[-4] for f in files}
    assert domains == {"domain=kitting", "domain=taxi"}
    assert all(f.parts[-3].startswith("date=") and f.parts[-2].startswith("run_id=") for f in files)


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


def test_causes_follow_the_causal_chain(lake):
    """The failed taxi run: its root failed because pick up passenger failed."""
    report = duckdb_report(str(lake), domain="taxi")
    assert report.runs == 2
    causes = {(r["failed_node"], r["cause"], r["verb"]) for r in report.causes}
    assert ("go deliver passenger", "pick up passenger", "failed") in causes


def test_fleet_command_prints_the_report_and_json(lake, runs):
    shown = btlog("fleet", str(lake))
    assert shown.returncode == 0, shown.stderr
    assert f"{len(runs)} runs:" in shown.stdout
    taxi = btlog("fleet", str(lake), "--domain", "taxi")
    assert "2 runs: 1 FAILURE, 1 SUCCESS" in taxi.stdout
    assert "pick up passenger" in taxi.stdout
    as_json = btlog("fleet", str(lake), "--domain", "kitting", "--json")
    assert as_json.returncode == 0
    import json

    assert json.loads(as_json.stdout)["runs"] == 6


def test_a_partition_filter_reads_only_its_partitions(lake, tmp_path):
    """With the taxi files made unreadable garbage, a kitting query still answers (it
    never opened them) while an unfiltered one fails."""
    copy = tmp_path / "lake"
    shutil.copytree(lake, copy)
    for file in copy.glob("transitions/domain=taxi/*/*/data.parquet"):
        file.write_bytes(b"not parquet at all")
    only = btlog(
        "sql", "--lake", str(copy), "SELECT count(*) FROM transitions WHERE domain = 'kitting'"
    )
    assert only.returncode == 0, only.stderr
    every = btlog("sql", "--lake", str(copy), "SELECT count(*) FROM transitions")
    assert every.returncode == 2
    assert every.stderr.count("\n") == 1


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


def test_reexport_replaces_a_runs_folder(lake, runs, tmp_path):
    copy = tmp_path / "lake"
    shutil.copytree(lake, copy)
    export_runs(runs[:2], copy)
    assert duckdb_report(str(copy)).to_json() == duckdb_report(str(lake)).to_json()


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
    import json

    assert json.loads(done.stdout) == duckdb_report(str(lake)).to_json()

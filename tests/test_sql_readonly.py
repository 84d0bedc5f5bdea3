"""``btlog sql`` is read-only: no query touches files, the network, settings or the caches."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from btlog.replay import cache
from btlog.replay.database import ReplayError, open_runs
from tests.cli_support import assert_bad_input, btlog
from tests.mcap_support import record_loop

ROOT = Path(__file__).resolve().parent.parent
COUNT = "SELECT count(*) AS n FROM transitions"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    return record_loop(tmp_path_factory.mktemp("sql") / "run.mcap", ticks=60)


@pytest.mark.parametrize(
    "query",
    [
        "SELECT * FROM read_csv('/etc/passwd')",
        "SELECT * FROM glob('/*')",
        "COPY (SELECT 1) TO '{tmp}/out.csv'",
        "ATTACH '{tmp}/new.duckdb' AS p",
        "INSTALL httpfs",
        "LOAD httpfs",
        "SET enable_external_access = true",
        "SELECT 1; DETACH run0",
        "EXPLAIN ANALYZE DELETE FROM transitions",
        "DETACH run0; ATTACH '{cache}' AS p; DELETE FROM p.transitions WHERE seq > 10",
    ],
)
def test_queries_that_reach_outside_are_refused(recording, tmp_path, query):
    with open_runs(recording) as database:
        database.lock()
        [place] = database._attached
        with pytest.raises(ReplayError, match="SQL error"):
            database.sql(query.format(tmp=tmp_path, cache=place))
    assert list(tmp_path.iterdir()) == [], "nothing was written"
    with open_runs(recording) as database:
        assert database.ingested == [], "the cache is intact and current"
        assert database.sql(COUNT)[1][0][0] > 10 * 2


def test_the_cli_query_cannot_change_later_answers(recording, tmp_path):
    before = btlog("sql", str(recording), COUNT, "--format", "csv")
    assert before.returncode == 0, before.stderr
    [place] = cache.entries(cache.cache_root())[-1:]
    attack = f"DETACH run0; ATTACH '{place.path}' AS p; DELETE FROM p.transitions WHERE seq > 10"
    refused = btlog("sql", str(recording), attack)
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1
    after = btlog("sql", str(recording), COUNT, "--format", "csv")
    assert after.stdout == before.stdout
    assert "read-only" in btlog("sql", "--help").stdout


def test_no_run_is_added_once_locked(recording):
    with open_runs(recording) as database:
        database.lock()
        with pytest.raises(ReplayError, match="locked"):
            database.add(recording)
        assert database.sql(COUNT)[1][0][0] > 0


@pytest.fixture(scope="module")
def lake(recording, tmp_path_factory) -> Path:
    from btlog.fleet.lake import export_runs

    root = tmp_path_factory.mktemp("lake") / "lake"
    export_runs([recording], root)
    return root


@pytest.fixture
def secret_cwd(tmp_path) -> Path:
    """A folder holding ``.tmp/secret.txt``: DuckDB's default temp folder, which its
    ``allowed_directories`` would keep readable if btlog left the default."""
    (tmp_path / ".tmp").mkdir()
    (tmp_path / ".tmp" / "secret.txt").write_text("SECRET\n", encoding="utf-8")
    return tmp_path


@pytest.mark.parametrize("source", ["recording", "lake"])
def test_sql_reads_no_file_at_all(source, recording, lake, secret_cwd):
    where = [str(recording)] if source == "recording" else ["--lake", str(lake)]

    def sql(query: str):
        return btlog("sql", *where, query, "--format", "csv", cwd=secret_cwd)

    settings = sql(
        "SELECT current_setting('allowed_directories')::VARCHAR AS allowed, "
        "current_setting('temp_directory') AS temp, "
        "current_setting('enable_external_access') AS external"
    )
    assert settings.returncode == 0, settings.stderr
    allowed, temp, external = settings.stdout.splitlines()[1].split(",", 2)
    assert temp == "" and external == "False"
    if source == "recording":
        assert allowed == "[]"
    else:
        assert allowed == f"[{lake.resolve()}/]", "only the lake's own folder"
        own = sql(f"SELECT count(*) FROM glob('{lake.resolve()}/runs/**')")
        assert own.returncode == 0 and int(own.stdout.splitlines()[1]) >= 1, own.stderr
    for query in (
        "SELECT * FROM read_text('.tmp/secret.txt')",
        "SELECT * FROM glob('.tmp/*')",
        f"SELECT * FROM read_text('{secret_cwd}/.tmp/secret.txt')",
        f"SELECT * FROM read_text('{lake.resolve()}/../../.tmp/secret.txt')",
    ):
        refused = sql(query)
        assert_bad_input(refused, "Permission Error")
        assert "SECRET" not in refused.stdout + refused.stderr


@pytest.mark.parametrize("source", ["recording", "lake"])
def test_a_query_ends_at_its_timeout(source, recording, lake):
    where = [str(recording)] if source == "recording" else ["--lake", str(lake)]
    started = time.monotonic()
    stopped = btlog("sql", *where, "--timeout", "1", "SELECT count(*) FROM range(100000000000)")
    assert time.monotonic() - started < 30, "stopped at the limit, not after counting"
    assert_bad_input(stopped, "time limit of 1 s", "--timeout")
    quick = btlog("sql", *where, "--timeout", "1", "SELECT 6 * 7 AS n", "--format", "csv")
    assert quick.returncode == 0 and quick.stdout.splitlines()[1] == "42", quick.stderr
    assert_bad_input(btlog("sql", *where, "--timeout", "-1", "SELECT 1"), "--timeout", "-1")
    assert "default 60" in btlog("sql", "--help").stdout

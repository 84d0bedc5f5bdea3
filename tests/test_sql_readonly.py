"""``btlog sql`` is read-only: no query touches files, the network, settings or the caches."""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.replay import cache
from btlog.replay.database import ReplayError, open_runs
from tests.cli_support import btlog
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

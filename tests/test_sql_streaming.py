"""``btlog sql`` prints a result as it is read: any number of rows in bounded memory, the
output the same as when it was read whole (CSV, one JSON array, tables of ``TABLE_ROWS``
rows)."""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
from pathlib import Path

import pytest

from btlog.cli.commands import TABLE_ROWS
from tests.cli_support import btlog, btlog_command, btlog_environment
from tests.test_damage import record


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sql") / "run.mcap"
    record(path)
    return path


def test_json_and_csv_are_the_whole_result_row_by_row(run, tmp_path):
    count = TABLE_ROWS + 2_345
    query = f"SELECT range AS n, range % 3 AS r, 'x' || range AS s FROM range({count})"
    rows = [{"n": i, "r": i % 3, "s": f"x{i}"} for i in range(count)]
    done = btlog("sql", run, query, "--format", "json", "--cache-dir", tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout == json.dumps(rows, indent=2) + "\n"
    empty = btlog(
        "sql", run, "SELECT 1 AS n WHERE false", "--format", "json", "--cache-dir", tmp_path
    )
    assert empty.stdout == "[]\n"
    csv = btlog("sql", run, query, "--format", "csv", "--cache-dir", tmp_path)
    assert csv.stdout.splitlines() == ["n,r,s", *(f"{i},{i % 3},x{i}" for i in range(count))]
    table = btlog("sql", run, query, "--cache-dir", tmp_path, env={"COLUMNS": "80"})
    assert table.returncode == 0, table.stderr
    assert table.stdout.count(" s ") == 2  # two tables, each with its header
    assert f"x{count - 1} " in table.stdout


def test_a_result_of_millions_of_rows_is_printed_in_bounded_memory(run, tmp_path):
    query = "SELECT range AS n, range * 7 AS m FROM range(10000000)"
    args = btlog_command("sql", run, query, "--format", "csv", "--cache-dir", tmp_path)
    with tempfile.TemporaryFile() as out:
        child = subprocess.Popen(args, stdout=out, stderr=subprocess.PIPE, env=btlog_environment())
        _pid, status, usage = os.wait4(child.pid, 0)
        assert status == 0
        assert out.seek(0, os.SEEK_END) > 10_000_000 * 4
    # read whole, 3M rows took 1.2 GB (10M: ~4 GB); streamed, ~110 MB alone, but up to
    # 944 MB was seen with the suite's other workers running (cause not found): the bound
    # is the one the README promises for every command, 2 GB, less a margin
    assert usage.ru_maxrss * 1024 < 1_500_000_000, usage.ru_maxrss

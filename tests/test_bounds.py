"""Memory and time bounded by the input's size (issue 24): a wide tree, a blackboard dump
tiny on disk but large in memory, many SubTrees.

The snapshots of a run whose state is large are spread (``snapshot_interval``), write
rows are read a row at a time, and DuckDB's memory follows the process's address-space
limit; these tests run the real command line under such a limit (``ulimit -v``)."""

from __future__ import annotations

import time
from pathlib import Path

import orjson
import pytest

from btlog.replay.database import open_runs
from btlog.replay.snapshots import STATE_BYTES_PER_EVENT
from btlog.view.export import export_data
from btlog.view.model import RunView
from tests.cli_support import btlog
from tests.mcap_support import record_tree, subtrees_tree, wide_tree, write_blackboard_dump

#: The address space the commands are given: what a small container allows.
ADDRESS_SPACE = 2 << 30


@pytest.fixture(scope="module")
def dump(tmp_path_factory) -> Path:
    """20,000 keys of 1 KB in one message: 100 KB on disk, 20 MB of values."""
    return write_blackboard_dump(tmp_path_factory.mktemp("dump") / "dump.mcap", 20_000, 1000)


@pytest.fixture(scope="module")
def wide(tmp_path_factory) -> Path:
    """A Sequence of 20,000 leaves, run once (40,003 events)."""
    return record_tree(tmp_path_factory.mktemp("wide") / "wide.mcap", wide_tree(20_000), 1)


def test_a_large_state_spreads_the_snapshots(dump: Path) -> None:
    with open_runs(dump, cache=False) as database:
        run = database.run()
        assert run.snapshot_every * STATE_BYTES_PER_EVENT >= 20_000 * 1000
        _columns, [(count, stored)] = database.sql(
            f"SELECT count(*), sum(strlen(state::VARCHAR)) FROM {run.snapshots_table()}"
        )
        assert count == 1 and stored < 10_000, "the dump is stored once, in the tables"
        _tree, state = run.state_at("end")
        board = state.blackboard[""]
        assert len(board) == 20_000 and board["key19999"] == "v" * 1000 + "19999"


@pytest.mark.parametrize(
    "command",
    [
        ("sql", "SELECT count(*) AS n, max(strlen(value::VARCHAR)) FROM blackboard"),
        ("show", "--at", "end", "--blackboard"),
        ("explain",),
    ],
    ids=lambda c: c[0],
)
def test_a_blackboard_dump_is_read_within_an_address_space_limit(dump, command) -> None:
    result = btlog(command[0], dump, *command[1:], address_space=ADDRESS_SPACE)
    assert result.returncode == 0, result.stderr
    if command[0] == "sql":
        assert "20000" in result.stdout and "1007" in result.stdout
    if command[0] == "show":
        assert 'key19999 = "' + "v" * 1000 + '19999"' in result.stdout


def test_a_wide_tree_is_read_within_an_address_space_limit(wide: Path, tmp_path: Path) -> None:
    with open_runs(wide, cache=False) as database:
        run = database.run()
        assert run.snapshot_every >= 20_000 * 48 // STATE_BYTES_PER_EVENT
        [(snapshots,)] = database.sql(f"SELECT count(*) FROM {run.snapshots_table()}")[1]
        assert snapshots <= 3, "40,003 events of a 20,001-node state: 3 snapshots at most"
    for command in (
        ("sql", "SELECT count(*) FROM nodes"),
        ("explain",),
        ("show", "--at", "end"),
        ("timeline", "--node", "wide"),
        ("ask", "What are you doing?"),
        ("view", "--export", tmp_path / "wide.html"),
    ):
        result = btlog(command[0], wide, *command[1:], address_space=ADDRESS_SPACE)
        assert result.returncode == 0, (command, result.stderr)
    page = (tmp_path / "wide.html").read_text(encoding="utf-8")
    assert "AlwaysSuccess" in page and len(page) < 20_000 * 400, "a page linear in the tree"


def _export_of(path: Path) -> tuple[float, int, dict]:
    """(seconds, bytes of its JSON, run data) of the exported page's data for ``path``."""
    started = time.perf_counter()
    with open_runs(path, cache=False) as database:
        data = export_data([RunView(database, database.run(), "run")], None, None)
    return time.perf_counter() - started, len(orjson.dumps(data)), data["runs"][0]


def test_an_export_of_many_subtrees_is_linear(tmp_path: Path) -> None:
    """5,000 SubTrees took minutes and a page of 345 MB (every answer set held the goal's
    5,000 steps): the answers that depend only on the tree are computed once, and the
    page holds each distinct answer once."""
    small = record_tree(tmp_path / "s500.mcap", subtrees_tree(500), 1)
    large = record_tree(tmp_path / "s1000.mcap", subtrees_tree(1000), 1)
    _export_of(small)  # imports and caches warmed
    small_time, small_size, _ = _export_of(small)
    large_time, large_size, run = _export_of(large)
    assert large_size < 2.5 * small_size, (small_size, large_size)
    assert large_time < 4 * small_time + 2, (small_time, large_time)
    table = run["answers"]["table"]
    goals = [a for a in table if a["intent"] == "how_goal"]
    assert len(goals) == 1 and "I need to do 1000 steps" in goals[0]["answer"]
    assert len(run["answers"]["sets"]) > 1000, "a set for each leaf run"
    exported = btlog("view", large, "--export", tmp_path / "page.html")
    assert exported.returncode == 0, exported.stderr

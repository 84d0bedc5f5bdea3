"""Memory and time bounded by the input's size (issue 24): a wide tree, a blackboard dump
tiny on disk but large in memory, many SubTrees.

The snapshots of a run whose state is large are spread (``snapshot_interval``), write
rows are read a row at a time, and DuckDB's memory follows the process's address-space
limit; these tests run the real command line under such a limit (``ulimit -v``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.replay.database import open_runs
from btlog.replay.snapshots import STATE_BYTES_PER_EVENT
from tests.cli_support import btlog
from tests.mcap_support import record_tree, wide_tree, write_blackboard_dump

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


def test_a_wide_tree_is_read_within_an_address_space_limit(wide: Path) -> None:
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
    ):
        result = btlog(command[0], wide, *command[1:], address_space=ADDRESS_SPACE)
        assert result.returncode == 0, (command, result.stderr)

"""The command line's rough edges a new user hit (issue #26), each through the real
command line: flags between arguments, CSV line ends, ``ask`` at the end by default,
the tree changing "once", ``btlog cache`` naming recordings, ``btlog fleet`` by path, and
the live progress bar in a real terminal."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests.cli_support import ROOT, Terminal, btlog, btlog_command, btlog_environment

RECORDINGS = ROOT / "recordings"
CHUCK = RECORDINGS / "kitting-look-at-chuck-fails.mcap"
QUERY = "SELECT run_id, final_status FROM runs"


@pytest.fixture(scope="module")
def copies(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("edges")
    for name in ("kitting-look-at-chuck-fails.mcap", "kitting-can-you.mcap", "taxi-human.mcap"):
        (folder / name).write_bytes((RECORDINGS / name).read_bytes())
    return folder


def test_sql_takes_its_flags_between_its_arguments(copies: Path) -> None:
    runs = ["kitting-look-at-chuck-fails.mcap", "taxi-human.mcap"]
    before = btlog("sql", "--format", "csv", *runs, QUERY, cwd=copies)
    between = btlog("sql", runs[0], "--format", "csv", runs[1], QUERY, cwd=copies)
    after = btlog("sql", *runs, QUERY, "--format", "csv", cwd=copies)
    assert before.returncode == between.returncode == after.returncode == 0, between.stderr
    assert before.stdout == between.stdout == after.stdout
    assert before.stdout.count("SUCCESS") == 2


def test_csv_lines_end_with_a_newline_not_crlf(copies: Path) -> None:
    done = subprocess.run(
        btlog_command("sql", "kitting-look-at-chuck-fails.mcap", QUERY, "--format", "csv"),
        cwd=copies, env=btlog_environment(), capture_output=True, check=False, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert b"\r" not in done.stdout
    assert done.stdout.endswith(b"\n") and done.stdout.count(b"\n") == 2


def test_ask_defaults_to_the_end_as_show_does(copies: Path) -> None:
    question = "What went wrong?"
    default = btlog("ask", "kitting-look-at-chuck-fails.mcap", question, "--json", cwd=copies)
    at_end = btlog(
        "ask", "kitting-look-at-chuck-fails.mcap", "--at", "end", question, "--json", cwd=copies
    )
    assert default.returncode == 0, default.stderr
    assert json.loads(default.stdout)["answer"] == json.loads(at_end.stdout)["answer"]
    assert json.loads(default.stdout)["moment"] == {**json.loads(at_end.stdout)["moment"]}
    assert json.loads(default.stdout)["moment"]["at"] == "end"


def test_a_tree_changed_once_says_once(copies: Path) -> None:
    done = btlog("export", "kitting-can-you.mcap", "--to", "btlog", "out.btlog", cwd=copies)
    assert done.returncode == 2
    assert "the tree changed once during the run" in done.stderr
    assert "1 times" not in done.stderr


def test_cache_lists_the_recording_of_each_cache(copies: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    for name in ("kitting-look-at-chuck-fails.mcap", "taxi-human.mcap"):
        shown = btlog("show", name, "--cache-dir", str(cache), cwd=copies)
        assert shown.returncode == 0, shown.stderr
    listed = btlog("cache", "--cache-dir", str(cache))
    assert listed.returncode == 0, listed.stderr
    lines = listed.stdout.splitlines()
    assert any(str(copies / "taxi-human.mcap") in line for line in lines)
    assert any(str(copies / "kitting-look-at-chuck-fails.mcap") in line for line in lines)
    as_json = json.loads(btlog("cache", "--cache-dir", str(cache), "--json").stdout)
    recordings = {Path(f["recording"]).name for f in as_json["files"] if f["recording"]}
    assert {"taxi-human.mcap", "kitting-look-at-chuck-fails.mcap"} <= recordings


def test_fleet_lists_nodes_by_path_with_completions(copies: Path, tmp_path: Path) -> None:
    lake = tmp_path / "lake"
    runs = ["kitting-look-at-chuck-fails.mcap", "kitting-can-you.mcap"]
    assert btlog("export", *runs, "--parquet", str(lake), cwd=copies).returncode == 0
    shown = btlog("fleet", str(lake), "--nodes", "200", env={"COLUMNS": "250"})
    assert shown.returncode == 0, shown.stderr
    assert "completed" in shown.stdout.splitlines()[2]
    table = shown.stdout.split("└")[0]  # the nodes' table, before the causes'
    rows = [line for line in table.splitlines() if line.startswith("│")]
    report = json.loads(btlog("fleet", str(lake), "--json").stdout)
    assert len(rows) == len(report["nodes"])
    labels = [row.split("│")[1].strip() for row in rows]
    assert len(set(labels)) == len(labels), "every node is told apart"
    look = next(n for n in report["nodes"] if n["name"] == "look at chuck")
    row = next(r for r in rows if r.split("│")[1].strip() == look["path"])
    assert row.split("│")[3].strip() == str(look["completed"])


def test_the_progress_bar_shows_the_tick_of_a_live_answer(tmp_path: Path) -> None:
    kitting = str(ROOT / "trees" / "kitting.xml")
    args = ["run", kitting, "--domain", "kitting", "--ask", "30s=What are you doing?"]
    terminal = Terminal(*args, "-o", "k.mcap", cwd=tmp_path, columns=100)
    output = terminal.finish()
    assert terminal.process.returncode == 0, output
    before_answer = output.split("[30s] What are you doing?")[0]
    assert "tick 301" in before_answer  # the tick the answer is given before
    assert "tick 0 " not in before_answer.rsplit("running", 1)[-1]
    assert (tmp_path / "k.mcap").exists()


@pytest.mark.parametrize("at", ["tick:300", "12s", "seq:40", "end", "-2s", "tick:0"])
def test_every_header_names_the_same_moment(copies: Path, at: str) -> None:
    """show, explain --json, ask --json and replay print the resolved moment's seq, tick
    and time (the viewer's: tests/test_view.py), the time being the moment's own."""
    from btlog.replay.database import open_runs

    name = "kitting-look-at-chuck-fails.mcap"
    with open_runs(copies / name, cache_dir=copies / "cache") as database:
        moment = database.run().resolve(at)
    expected = moment.to_json()
    seq = "before the first event" if moment.seq is None else f"seq {moment.seq}"
    head = f"at {at}: {seq}, tick {moment.tick}, {moment.t_ns / 1e9:.3f}s"
    shown = btlog("show", name, "--at", at, cwd=copies)
    assert shown.stdout.splitlines()[0].startswith(head), shown.stdout
    explained = btlog("explain", name, "--at", at, "--json", cwd=copies)
    assert json.loads(explained.stdout)["moment"] == expected
    asked = btlog("ask", name, "--at", at, "What are you doing?", "--json", cwd=copies)
    assert json.loads(asked.stdout)["moment"] == expected
    replay = btlog("replay", name, "--script", "-", cwd=copies, input=f"g {at}\nq\n")
    assert f"  {head}" in replay.stdout.split("── event ")[-1].splitlines()[0]

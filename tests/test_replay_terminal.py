"""``btlog replay`` on a real terminal (a pty): the arrow keys are keystrokes, Enter
repeats, and ``t``/``f``/``b`` move by the run's clock, also over ticks and seconds
without events (issue #26). Scripts drive the same commands with ``--script``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from btlog.replay.database import open_runs
from tests.cli_support import ROOT, Terminal, btlog

CHUCK = ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
RIGHT, LEFT, DOWN, UP = "\x1b[C", "\x1b[D", "\x1b[B", "\x1b[A"
HEADER = re.compile(r"── event (\d+)/(\d+)  at (\S+): (?:seq (\d+)|before the first event), "
                    r"tick (\d+), ([0-9.]+)s")  # fmt: skip


@pytest.fixture(scope="module")
def chuck(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("replay-terminal")
    (folder / CHUCK.name).write_bytes(CHUCK.read_bytes())
    return folder / CHUCK.name


def header_after(terminal: Terminal, keys: str) -> tuple[int, int, float]:
    """Press ``keys``; the (events applied, tick, seconds) of the header printed."""
    terminal.send(keys)
    terminal.expect("── event")  # the step's header (the line being typed is redrawn)
    seen = "── event" + ANSI.sub("", terminal.expect("replay>"))
    found = HEADER.findall(seen)
    assert found, seen
    count, _total, _at, _seq, tick, seconds = found[-1]
    return int(count), int(tick), float(seconds)


def test_arrow_keys_are_keystrokes_and_enter_repeats(chuck: Path) -> None:
    terminal = Terminal("replay", chuck.name, cwd=chuck.parent)
    try:
        terminal.expect("replay>")
        assert header_after(terminal, RIGHT)[0] == 2  # no Enter needed
        assert header_after(terminal, RIGHT)[0] == 3
        assert header_after(terminal, LEFT)[0] == 2
        _count, tick, _t = header_after(terminal, DOWN)
        assert tick == 2
        assert header_after(terminal, "\r")[1] == 3  # Enter repeats ↓
        assert header_after(terminal, UP)[1] == 2
        # ↓ then a typed command: the arrow is a keystroke, not text on the line
        header_after(terminal, DOWN)
        _count, tick, seconds = header_after(terminal, "g 10.4s\r")
        assert seconds == 10.4 and "unknown command" not in terminal.output
        terminal.send("q\r")
        terminal.finish()
    finally:
        if terminal.process.poll() is None:
            terminal.process.kill()
    assert terminal.process.returncode == 0


def test_ticks_and_seconds_move_by_the_runs_clock(chuck: Path) -> None:
    """From 10.4 s: ``b 2`` lands at 8.4 s, ``f 1`` at 9.4 s, ``t`` one tick on, even
    where no event happened; each header is the read model's resolved moment."""
    terminal = Terminal("replay", chuck.name, cwd=chuck.parent)
    with open_runs(chuck) as database:
        run = database.run()
        try:
            terminal.expect("replay>")
            header_after(terminal, "g 10.4s\r")
            count, tick, seconds = header_after(terminal, "b 2\r")
            moment = run.resolve("8.4s")
            assert (count, tick, seconds) == (moment.count, moment.tick, 8.4)
            count, tick, seconds = header_after(terminal, "f 1\r")
            assert seconds == 9.4 and tick == run.resolve("9.4s").tick
            quiet = run.resolve("tick:290")  # ticks 282-299 have no events
            header_after(terminal, "g tick:290\r")
            count, tick, seconds = header_after(terminal, "t\r")
            after = run.resolve("tick:291")
            assert (count, tick, seconds) == (quiet.count, 291, after.t_ns / 1e9)
            count, tick, seconds = header_after(terminal, "f 0.5\r")
            assert (count, tick, seconds) == (quiet.count, 296, 29.5)
            terminal.send("q\r")
            terminal.finish()
        finally:
            if terminal.process.poll() is None:
                terminal.process.kill()


def test_steps_stay_on_one_screen_and_list_the_events_stepped_over(chuck: Path) -> None:
    script = "n 5\n\nn 2\np\nt\nq\n"
    replay = btlog("replay", chuck.name, "--plain", "--script", "-", cwd=chuck.parent,
                   input=script)  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    assert "unknown command" not in replay.stdout
    steps = replay.stdout.split("── event ")[1:]
    positions = [int(step.split("/")[0]) for step in steps]
    assert positions == [1, 6, 11, 13, 12, positions[-1]] and positions[-1] > 12
    assert all(len(step.splitlines()) <= 24 for step in steps)
    assert "look at chuck" not in steps[1]  # the whole tree is not reprinted
    assert "move to see chuck #6  IDLE -> RUNNING" in steps[1]  # the events stepped over


def test_ask_answers_at_the_moment_as_btlog_ask_does(chuck: Path) -> None:
    """At 12 s, past the last event (10.4 s), a running node has run to the moment asked,
    in the replay as in ``btlog ask`` (one answer, every surface)."""
    question = "How long did retreat arm take?"
    asked = btlog("ask", chuck.name, "--at", "12s", question, cwd=chuck.parent)
    assert asked.returncode == 0, asked.stderr
    assert asked.stdout.strip() == "retreat arm has been running for 1.600 s."
    replay = btlog("replay", chuck.name, "--plain", "--script", "-", cwd=chuck.parent,
                   input=f"g 12s\nask {question}\nq\n")  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    assert replay.stdout.rstrip().splitlines()[-1] == asked.stdout.strip()


def test_a_jump_lists_the_last_events_it_stepped_over_and_counts_the_rest(chuck: Path) -> None:
    """A jump reads only the events it shows (a jump over a day-long run stays small)."""
    replay = btlog("replay", chuck.name, "--plain", "--script", "-", cwd=chuck.parent,
                   input="g seq:40\ng seq:10\nq\n")  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    forward, back = replay.stdout.split("── event ")[2:]
    assert forward.startswith("41/") and "  … 35 events, then:" in forward
    assert [int(line.split()[0]) for line in forward.splitlines()[2:7]] == [36, 37, 38, 39, 40]
    assert back.startswith("11/") and "  back over … 25 events, then:" in back
    seqs = [int(line.split()[2]) for line in back.splitlines()[2:7]]
    assert seqs == [36, 37, 38, 39, 40]

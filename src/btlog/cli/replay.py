"""``btlog replay``: step forward and back through a run.

A line-oriented terminal interface: each command moves the position (by event, by tick,
by time, or to any moment) and prints, within one screen, where it landed: the events it
just stepped over (the last few), the current node with its ancestors, and the answers
to Q1–Q6 there; ``tree`` draws the whole tree with its statuses. It reads commands from
the keyboard, or from a file or standard input with ``--script``, so tests and scripts
can drive it.

Commands: ``n [K]`` / ``p [K]`` next/previous K events (→ / ←), ``t [K]`` / ``T [K]``
next/previous K ticks (↓ / ↑), ``f S`` / ``b S`` forward/back S seconds, ``g WHEN`` go to
a moment, ``tree`` the tree, ``ask QUESTION``, ``bb`` toggle the blackboard (shown with
``tree``), ``h`` help, ``q`` quit; Enter repeats the last command.
"""

from __future__ import annotations

import sys
from argparse import Namespace
from collections.abc import Iterator
from typing import TYPE_CHECKING

from rich.text import Text

from btlog.cli.commands import timeline_line
from btlog.explain.hierarchy import current_nodes
from btlog.explain.questions import UnknownQuestion, answer, explain
from btlog.render.escape import safe
from btlog.render.terminal import blackboard_lines, format_ns, make_console, tree_lines

if TYPE_CHECKING:
    from rich.console import Console

    from btlog.replay.database import Run
    from btlog.state import State
    from btlog.tree.model import Tree

HELP = (
    "commands: n [K] next K events (→) | p [K] previous K events (←) | t [K] next K ticks "
    "(↓) | T [K] previous K ticks (↑) | f S forward S seconds | b S back S seconds | g WHEN "
    "go to a moment | tree the tree | ask QUESTION | bb toggle blackboard | h help | q quit "
    "| Enter repeats"
)
#: Arrow keys as a terminal sends them (normal and application cursor mode).
ARROWS = {
    "\x1b[C": "n",
    "\x1bOC": "n",
    "\x1b[D": "p",
    "\x1bOD": "p",
    "\x1b[B": "t",
    "\x1bOB": "t",
    "\x1b[A": "T",
    "\x1bOA": "T",
}
#: The events a step lists (the last ones it stepped over).
SHOWN_EVENTS = 5


class Stepper:
    """The position in a run (the number of events applied) and what to show there."""

    def __init__(self, run: Run, console: Console) -> None:
        self.run = run
        self.console = console
        self.total = run.state_at("end")[1].seq
        self.position = min(1, self.total)
        self.show_blackboard = False

    def state(self) -> tuple[Tree, State]:
        """(tree, state) at the current position."""
        if self.total == 0:
            return self.run.state_at("end")
        return self.run.state_at(f"seq:{self.position - 1}")

    def move_events(self, count: int) -> None:
        """Move by ``count`` events (negative: back)."""
        self.position = max(1, min(self.total, self.position + count))

    def move_ticks(self, count: int) -> None:
        """Move to the end of the tick ``count`` ticks away."""
        tick = self.state()[1].tick + count
        self.go(f"tick:{max(tick, 1)}")

    def move_seconds(self, seconds: float) -> None:
        """Move by ``seconds`` of run time."""
        t_ns = self.state()[1].t_ns + round(seconds * 1e9)
        self.go(f"{max(t_ns, 0)}ns")

    def go(self, moment: str) -> None:
        """Move to any moment form."""
        self.position = max(1, self.run.state_at(moment)[1].seq)

    def header(self, state: State) -> None:
        """The position: event, seq, tick and time."""
        self.console.print(
            f"── event {self.position}/{self.total}  seq {state.seq - 1}  "
            f"tick {state.tick}  {format_ns(state.t_ns)}",
            highlight=False,
        )

    def render(self, before: int | None = None) -> None:
        """Print the step within one screen: the position, the events stepped over since
        position ``before`` (the last few), the current node's ancestry, and Q1–Q6."""
        tree, state = self.state()
        console = self.console
        self.header(state)
        if before is not None and before != self.position:
            low, high = sorted((before, self.position))
            entries = self.run.timeline(start=f"seq:{low}", end=f"seq:{high - 1}")
            verb = "" if self.position > before else "back over "
            if len(entries) > SHOWN_EVENTS:
                console.print(f"  {verb}… {len(entries) - SHOWN_EVENTS} events, then:")
            for entry in entries[-SHOWN_EVENTS:]:
                console.print(f"  {verb}{timeline_line(entry._asdict())}", highlight=False)
        for node in current_nodes(tree, state):
            path = [*reversed([a.description for a in node.ancestors()]), node.description]
            console.print("  current: " + " › ".join(safe(p) for p in path), highlight=False)
        for result in explain(tree, state, self.run.history()):
            console.print(f"{result.question}  {safe(result.text)}", highlight=False)

    def render_tree(self) -> None:
        """Print the position and the whole tree (and the blackboard when toggled on)."""
        tree, state = self.state()
        self.header(state)
        current = {n.uid for n in current_nodes(tree, state)}
        for line in tree_lines(tree, state, current):
            self.console.print(line)
        if self.show_blackboard:
            for line in blackboard_lines(state) or [Text("(the blackboard is empty)")]:
                self.console.print(line)


def _commands(script: str | None) -> Iterator[str]:
    if script is None:
        while True:
            try:
                yield input("replay> ")
            except EOFError:
                return
    else:
        stream = sys.stdin if script == "-" else open(script, encoding="utf-8")  # noqa: SIM115
        with stream:
            yield from (line.rstrip("\n") for line in stream)


def _count(parts: list[str], default: float = 1) -> float:
    if len(parts) < 2:
        return default
    try:
        return float(parts[1])
    except ValueError:
        raise ValueError(f"not a number: {parts[1]!r}") from None


def keys_to_command(line: str) -> str:
    """A line of arrow keys as the command they stand for (``→→`` is ``n 2``); any other
    line as it is."""
    text = line.strip()
    for key, word in ARROWS.items():
        if text and text.replace(key, "") == "":
            return f"{word} {text.count(key)}"
    return line


def _apply(stepper: Stepper, line: str) -> bool:
    """Run one command; False to quit."""
    parts = line.strip().split(maxsplit=1)
    word = parts[0] if parts else "n"
    before = stepper.position
    moves = {
        "n": lambda: stepper.move_events(int(_count(parts))),
        "p": lambda: stepper.move_events(-int(_count(parts))),
        "t": lambda: stepper.move_ticks(int(_count(parts))),
        "T": lambda: stepper.move_ticks(-int(_count(parts))),
        "f": lambda: stepper.move_seconds(_count(parts)),
        "b": lambda: stepper.move_seconds(-_count(parts)),
    }
    if word in ("q", "quit", "exit"):
        return False
    if word in ("h", "help", "?"):
        stepper.console.print(HELP, highlight=False)
    elif word == "bb":
        stepper.show_blackboard = not stepper.show_blackboard
        stepper.render_tree()
    elif word == "tree":
        stepper.render_tree()
    elif word == "ask":
        tree, state = stepper.state()
        question = parts[1] if len(parts) > 1 else ""
        text = answer(tree, state, question, stepper.run.history()).text
        stepper.console.print(safe(text), highlight=False)
    elif word == "g" and len(parts) > 1:
        stepper.go(parts[1])
        stepper.render(before)
    elif word in moves:
        moves[word]()
        stepper.render(before)
    else:
        stepper.console.print(f"unknown command {safe(line.strip())!r}; {HELP}", highlight=False)
    return True


def replay(args: Namespace) -> int:
    """``btlog replay``: the stepping loop."""
    from btlog.replay.database import open_runs

    database = open_runs(args.run)
    try:
        stepper = Stepper(database.run(args.run), make_console(args.plain))
        stepper.render()
        last = "n"
        for line in _commands(args.script):
            command = keys_to_command(line) if line.strip() else last  # Enter repeats
            last = command
            try:
                if not _apply(stepper, command):
                    break
            except (ValueError, UnknownQuestion) as error:
                stepper.console.print(f"error: {safe(error)}", highlight=False)
    finally:
        database.close()
    return 0

"""``btlog replay``: step forward and back through a run.

A line-oriented terminal interface: each command moves the position (by event, by tick,
by time, or to any moment) and prints the tree with its statuses, the current node and
the answers to Q1–Q6 there. It reads commands from the keyboard, or from a file or
standard input with ``--script``, so tests and scripts can drive it.

Commands: ``n [K]`` / ``p [K]`` next/previous K events (Enter = ``n``), ``t [K]`` / ``T [K]``
next/previous K ticks, ``f S`` / ``b S`` forward/back S seconds, ``g WHEN`` go to a moment,
``ask QUESTION``, ``bb`` toggle the blackboard, ``h`` help, ``q`` quit.
"""

from __future__ import annotations

import sys
from argparse import Namespace
from collections.abc import Iterator
from typing import TYPE_CHECKING

from rich.text import Text

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
    "commands: n [K] next K events | p [K] previous K events | t [K] next K ticks | "
    "T [K] previous K ticks | f S forward S seconds | b S back S seconds | g WHEN go to "
    "a moment | ask QUESTION | bb toggle blackboard | h help | q quit"
)


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

    def render(self) -> None:
        """Print the position, the tree, and Q1–Q6."""
        tree, state = self.state()
        console = self.console
        console.print(
            f"── event {self.position}/{self.total}  seq {state.seq - 1}  "
            f"tick {state.tick}  {format_ns(state.t_ns)}",
            highlight=False,
        )
        current = {n.uid for n in current_nodes(tree, state)}
        for line in tree_lines(tree, state, current):
            console.print(line)
        if self.show_blackboard:
            for line in blackboard_lines(state) or [Text("(the blackboard is empty)")]:
                console.print(line)
        for result in explain(tree, state, self.run.history()):
            console.print(f"{result.question}  {safe(result.text)}", highlight=False)


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


def _apply(stepper: Stepper, line: str) -> bool:
    """Run one command; False to quit."""
    parts = line.strip().split(maxsplit=1)
    word = parts[0] if parts else "n"
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
        stepper.render()
    elif word == "ask":
        tree, state = stepper.state()
        question = parts[1] if len(parts) > 1 else ""
        text = answer(tree, state, question, stepper.run.history()).text
        stepper.console.print(safe(text), highlight=False)
    elif word == "g" and len(parts) > 1:
        stepper.go(parts[1])
        stepper.render()
    elif word in moves:
        moves[word]()
        stepper.render()
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
        for line in _commands(args.script):
            try:
                if not _apply(stepper, line):
                    break
            except (ValueError, UnknownQuestion) as error:
                stepper.console.print(f"error: {safe(error)}", highlight=False)
    finally:
        database.close()
    return 0

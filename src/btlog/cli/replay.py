"""``btlog replay``: step forward and back through a run.

On a terminal the arrow keys are keystrokes (read by ``prompt_toolkit``, which knows every
terminal's key sequences): → / ← one event, ↓ / ↑ one tick, Enter repeats the last
command, and a command line with history and editing for the rest. Each command moves
the position and prints, within one screen, where it landed: the moment's header (the
one every command prints, ``btlog.replay.moments.Resolved``), the events it just stepped
over (the last few), the current node with its ancestors, and the answers to Q1–Q6
there; ``tree`` draws the whole tree with its statuses. With ``--script`` (a file, or
``-`` for standard input) it reads the same commands a line each, so tests and scripts
can drive it.

The position is a moment of the run's clock, not only an event: ``t``/``T`` go to the
end of the next or previous tick and ``f``/``b`` move by seconds of run time, also over
ticks and seconds in which nothing happened (the header then says the last event's time
apart from the moment's). Commands: ``n [K]`` / ``p [K]`` next/previous K events,
``t [K]`` / ``T [K]`` next/previous K ticks, ``f S`` / ``b S`` forward/back S seconds,
``g WHEN`` go to a moment, ``tree`` the tree, ``ask QUESTION``, ``bb`` toggle the
blackboard (shown with ``tree``), ``h`` help, ``q`` quit.
"""

from __future__ import annotations

import sys
from argparse import Namespace
from collections.abc import Iterator
from typing import TYPE_CHECKING

from rich.text import Text

from btlog.cli.commands import moment_header, timeline_line
from btlog.explain.hierarchy import current_nodes
from btlog.explain.questions import UnknownQuestion, answer, explain
from btlog.render.escape import safe
from btlog.render.terminal import blackboard_lines, make_console, print_lines, tree_lines
from btlog.replay.moments import time_moment

if TYPE_CHECKING:
    from prompt_toolkit.filters import Filter
    from prompt_toolkit.key_binding import KeyPressEvent
    from rich.console import Console

    from btlog.replay.database import Run
    from btlog.replay.moments import Resolved
    from btlog.state import State
    from btlog.tree.model import Tree

HELP = (
    "keys: → next event | ← previous event | ↓ next tick | ↑ previous tick | Enter repeats; "
    "commands: n [K] next K events | p [K] previous K events | t [K] next K ticks | "
    "T [K] previous K ticks | f S forward S seconds | b S back S seconds | g WHEN go to a "
    "moment | tree the tree | ask QUESTION | bb toggle blackboard | h help | q quit"
)
#: The command each arrow key stands for.
ARROW_COMMANDS = {"right": "n", "left": "p", "down": "t", "up": "T"}
#: The events a step lists (the last ones it stepped over).
SHOWN_EVENTS = 5


class Stepper:
    """The position in a run (a resolved moment: its events applied, its tick and time)
    and what to show there."""

    def __init__(self, run: Run, console: Console) -> None:
        self.run = run
        self.console = console
        self.total = run.extent.events
        self.moment: Resolved = run.resolve("seq:0" if self.total else "tick:0")
        self.show_blackboard = False

    @property
    def position(self) -> int:
        """The number of events applied."""
        return self.moment.count

    def state(self) -> tuple[Tree, State]:
        """(tree, state) at the current position."""
        return self.run.state_after(self.moment.count)

    def move_events(self, count: int) -> None:
        """Move by ``count`` events (negative: back), within the first and last."""
        if self.total:
            seq = max(0, min(self.total - 1, self.position - 1 + count))
            self.go(f"seq:{seq}")

    def move_ticks(self, count: int) -> None:
        """Move to the end of the tick ``count`` ticks away (whether or not it has
        events), within the run's ticks."""
        tick = max(0, min(self.run.extent.last_tick, self.moment.tick + count))
        self.go(f"tick:{tick}")

    def move_seconds(self, seconds: float) -> None:
        """Move by ``seconds`` of run time, within the run."""
        t_ns = self.moment.t_ns + round(seconds * 1e9)
        self.go(time_moment(max(0, min(self.run.extent.duration_ns, t_ns))))

    def go(self, moment: str) -> None:
        """Move to any moment form."""
        self.moment = self.run.resolve(moment)

    def header(self) -> None:
        """The position: which event of how many, and the moment's header."""
        self.console.print(
            f"── event {self.position}/{self.total}  {moment_header(self.moment)}",
            highlight=False,
        )

    def render(self, before: int | None = None) -> None:
        """Print the step within one screen: the position, the events stepped over since
        position ``before`` (the last few), the current node's ancestry, and Q1–Q6."""
        tree, state = self.state()
        console = self.console
        self.header()
        if before is not None and before != self.position:
            low, high = sorted((before, self.position))
            # the last few only (a jump over a day-long run reads five events, not all):
            # every seq is one event of the timeline
            shown = max(low, high - SHOWN_EVENTS)
            entries = self.run.timeline(start=f"seq:{shown}", end=f"seq:{high - 1}")
            verb = "" if self.position > before else "back over "
            if shown > low:
                console.print(f"  {verb}… {shown - low} events, then:")
            for entry in entries:
                console.print(f"  {verb}{timeline_line(entry._asdict())}", highlight=False)
        for node in current_nodes(tree, state):
            path = [*reversed([a.description for a in node.ancestors()]), node.description]
            console.print("  current: " + " › ".join(safe(p) for p in path), highlight=False)
        for result in explain(tree, state, self.run.history()):
            console.print(f"{result.question}  {safe(result.text)}", highlight=False)

    def render_tree(self) -> None:
        """Print the position and the whole tree (and the blackboard when toggled on)."""
        tree, state = self.state()
        self.header()
        current = {n.uid for n in current_nodes(tree, state)}
        print_lines(self.console, tree_lines(tree, state, current))
        if self.show_blackboard:
            print_lines(
                self.console, blackboard_lines(state) or [Text("(the blackboard is empty)")]
            )


def _typed_commands(console: Console) -> Iterator[str]:
    """Commands from the keyboard: an arrow key on an empty line is its command at once
    (``ARROW_COMMANDS``), anything else is typed and entered; Ctrl-D ends."""
    from prompt_toolkit import PromptSession
    from prompt_toolkit.key_binding import KeyBindings

    keys = KeyBindings()
    for key, command in ARROW_COMMANDS.items():

        def take(event: KeyPressEvent, command: str = command) -> None:
            event.app.exit(result=command)

        keys.add(key, filter=_empty_line())(take)
    session: PromptSession[str] = PromptSession(key_bindings=keys)
    while True:
        try:
            yield session.prompt("replay> ")
        except EOFError:
            return
        except KeyboardInterrupt:
            console.print("(q quits)", highlight=False)


def _empty_line() -> Filter:
    """A prompt_toolkit filter: the line being typed is empty."""
    from prompt_toolkit.application.current import get_app
    from prompt_toolkit.filters import Condition

    return Condition(lambda: not get_app().current_buffer.text)


def _commands(script: str | None, console: Console) -> Iterator[str]:
    if script is None:
        yield from _typed_commands(console)
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
        text = answer(tree, state, question, stepper.run.history(), stepper.moment.t_ns).text
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
        console = make_console(args.plain)
        stepper = Stepper(database.run(args.run), console)
        stepper.render()
        script = "-" if args.script is None and not sys.stdin.isatty() else args.script
        last = "n"
        for line in _commands(script, console):
            command = line if line.strip() else last  # Enter repeats
            last = command
            try:
                if not _apply(stepper, command):
                    break
            except (ValueError, UnknownQuestion) as error:
                stepper.console.print(f"error: {safe(error)}", highlight=False)
    finally:
        database.close()
    return 0

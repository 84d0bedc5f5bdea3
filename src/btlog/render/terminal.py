"""Terminal rendering: a tree with its statuses, timelines, answers.

Everything here returns ``rich.text.Text`` lines built from plain strings with styles,
never from markup, so a node named ``[red]x`` or holding escape codes prints literally:
names come from untrusted XML and are passed through ``safe`` (``btlog.render.escape``)
first; consoles never read markup or emoji codes. Colour follows the
console (``NO_COLOR`` is honoured by rich; ``--plain`` turns it off).
"""

from __future__ import annotations

import json
from collections.abc import Iterable

from rich.console import Console
from rich.text import Text

from btlog.render.escape import safe
from btlog.state import State
from btlog.status import IDLE, Status
from btlog.tree.model import Node, Tree

STATUS_STYLES = {
    Status.IDLE: "dim",
    Status.RUNNING: "bold yellow",
    Status.SUCCESS: "green",
    Status.FAILURE: "bold red",
    Status.SKIPPED: "cyan",
}


#: Lines printed by one call of rich (its per-call work is about half a millisecond).
PRINT_BATCH = 1000


def print_lines(console: Console, lines: Iterable[Text]) -> None:
    """Print ``lines`` one a line, as ``console.print`` would one by one: straight to the
    console's file when it shows no styles (output to a file or a pipe, ``--plain``,
    where rich's work per line made a 150,000-node tree take a minute; its consoles
    never wrap), else through rich in batches."""
    batch: list[Text] = []
    for line in lines:
        batch.append(line)
        if len(batch) == PRINT_BATCH:
            _print_batch(console, batch)
            batch = []
    if batch:
        _print_batch(console, batch)


def _print_batch(console: Console, batch: list[Text]) -> None:
    if console.color_system is None and console.soft_wrap:
        console.file.write("".join(f"{line.plain}\n" for line in batch))
    else:
        console.print(Text("\n").join(batch))


def make_console(plain: bool = False, stderr: bool = False) -> Console:
    """A console for output; ``plain`` disables colour and styling. Strings printed on
    it are never read as markup (``[link=…]``) or emoji codes (``:warning:``)."""
    if plain:
        return Console(
            color_system=None,
            no_color=True,
            highlight=False,
            markup=False,
            emoji=False,
            stderr=stderr,
            soft_wrap=True,
        )
    return Console(highlight=False, markup=False, emoji=False, stderr=stderr, soft_wrap=True)


def node_label(node: Node, status: Status, current: bool) -> Text:
    """One node's line: description, type, uid, status, and a mark if current."""
    text = Text()
    text.append(safe(node.description), style="bold" if current else "")
    if node.name and node.name != node.type:
        text.append(f"  {safe(node.type)}", style="dim")
    text.append(f"  #{node.uid}", style="dim")
    text.append(f"  {status.name}", style=STATUS_STYLES[status])
    if node.added_seq is not None and (node.parent is None or node.parent.added_seq is None):
        text.append(f"  (inserted at seq {node.added_seq})", style="magenta")
    if current:
        text.append("  ◀ current", style="bold magenta")
    return text


def tree_lines(tree: Tree, state: State | None, current: Iterable[int] = ()) -> list[Text]:
    """The tree drawn with box characters, one ``Text`` per node."""
    marked = set(current)
    lines: list[Text] = []

    def visit(node: Node, prefix: str, last: bool, root: bool) -> None:
        status = state.status_of(node.uid) if state is not None else IDLE
        line = Text()  # only the box characters are dim, not the whole line
        line.append(prefix + ("" if root else ("└── " if last else "├── ")), style="dim")
        line.append_text(node_label(node, status, node.uid in marked))
        lines.append(line)
        child_prefix = prefix if root else prefix + ("    " if last else "│   ")
        for index, child in enumerate(node.children):
            visit(child, child_prefix, index == len(node.children) - 1, False)

    visit(tree.root, "", True, True)
    return lines


def blackboard_lines(state: State) -> list[Text]:
    """The blackboard per scope (root scope shown as ``(root)``)."""
    lines: list[Text] = []
    for scope in sorted(state.blackboard):
        entries = state.blackboard[scope]
        if not entries:
            continue
        lines.append(Text(f"[{safe(scope) or '(root)'}]", style="bold"))
        for key in sorted(entries):
            value = json.dumps(entries[key], sort_keys=True, default=repr)
            lines.append(Text(f"  {safe(key)} = {safe(value)}"))
    return lines


def format_ns(t_ns: int) -> str:
    """Seconds with millisecond precision."""
    return f"{t_ns / 1e9:.3f}s"

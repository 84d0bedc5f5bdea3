"""HTML rendering: one moment of a run as a standalone page (``btlog show --html``).

The page holds the tree with each node's status, the current node marked, the answers to
Q1–Q6 and the blackboard. Everything that comes from the recording — node names, types,
blackboard keys and values, answers — is escaped with ``html.escape``; the page loads
nothing from the network and runs no script.
"""

from __future__ import annotations

import html
import json
from collections.abc import Iterable

from btlog.explain.questions import Answer
from btlog.state import State
from btlog.tree.model import Node, Tree

_COLOURS = {
    "IDLE": "#888",
    "RUNNING": "#b58900",
    "SUCCESS": "#2e7d32",
    "FAILURE": "#c62828",
    "SKIPPED": "#00838f",
}
_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em; }
ul { list-style: none; padding-left: 1.4em; border-left: 1px solid #ddd; }
.status { font-weight: bold; margin-left: .6em; }
.type, .uid { color: #777; margin-left: .6em; font-size: .9em; }
.current { background: #fff3c4; }
table { border-collapse: collapse; } td, th { padding: .2em .8em; text-align: left; }
"""


def _node(node: Node, state: State, current: set[int]) -> str:
    status = state.status_of(node.uid).name
    kind = (
        f'<span class="type">{html.escape(node.type)}</span>'
        if node.name and node.name != node.type
        else ""
    )
    label = (
        f'<span class="name">{html.escape(node.description)}</span>{kind}'
        f'<span class="uid">#{node.uid}</span>'
        f'<span class="status" style="color:{_COLOURS[status]}">{status}</span>'
    )
    if node.uid in current:
        label += " ◀ current"
    css = ' class="current"' if node.uid in current else ""
    children = "".join(_node(child, state, current) for child in node.children)
    return f"<li{css}>{label}{f'<ul>{children}</ul>' if children else ''}</li>"


def page(
    title: str, tree: Tree, state: State, current: Iterable[int], answers: Iterable[Answer]
) -> str:
    """The whole HTML document for one moment."""
    rows = "".join(
        f"<tr><th>{html.escape(a.question)}</th><td>{html.escape(a.text)}</td></tr>"
        for a in answers
    )
    board = "".join(
        f"<tr><td>{html.escape(scope or '(root)')}</td><td>{html.escape(key)}</td>"
        f"<td><code>{html.escape(json.dumps(value, sort_keys=True, default=repr))}</code></td>"
        "</tr>"
        for scope, entries in sorted(state.blackboard.items())
        for key, value in sorted(entries.items())
    )
    return (
        '<!DOCTYPE html>\n<html><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>"
        f"<h1>{html.escape(title)}</h1>"
        f"<p>seq {state.seq}, tick {state.tick}, {state.t_ns / 1e9:.3f} s</p>"
        f"<ul>{_node(tree.root, state, set(current))}</ul>"
        f"<h2>Answers</h2><table>{rows}</table>"
        f"<h2>Blackboard</h2><table>{board or '<tr><td>(empty)</td></tr>'}</table>"
        "</body></html>\n"
    )

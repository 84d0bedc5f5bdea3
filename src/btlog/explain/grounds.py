"""Grounded reasons: what the failing node reported, or read, when it failed.

The paper's failure answers name the leaf that failed and stop there; its section 8
asks for more — the perception result, the planner's error. A run's events hold some
of it: the blackboard. So a failure's leaf is grounded in

- the **outputs it wrote** in its failing activation (Nav2's ``error_code_id``,
  ``error_msg``, any ``{key}`` output), named by their ports:
  ``… because follow path failed (error_code_id = 106).``
- for a **condition** that wrote nothing, the **values of its keyed inputs** at the
  moment it failed, with who last wrote each and when:
  ``… because battery OK failed (battery_level = 12, written by battery monitor at
  3.200 s).``

Values are shown as compact JSON, each at most ``MAX_VALUE_CHARS`` characters and at most
``MAX_ITEMS`` of them, so a reason stays one readable clause; like every recorded string
they are escaped by the renderer that prints them.
"""

from __future__ import annotations

from typing import Any

import orjson

from btlog.executor.blackboard import board_of
from btlog.explain.words import seconds, words
from btlog.history import ANY_STATUS, History, Transition
from btlog.status import FAILURE
from btlog.tree.model import CONDITION, INOUT, INPUT, Node, Tree

#: At most this many values in one reason.
MAX_ITEMS = 4
#: A value longer than this is cut, with an ellipsis.
MAX_VALUE_CHARS = 60


def _shown(value: Any) -> str:
    text = value if isinstance(value, str) else orjson.dumps(value, default=repr).decode()
    return text if len(text) <= MAX_VALUE_CHARS else text[: MAX_VALUE_CHARS - 1] + "…"


def _port_of(leaf: Node, key: str) -> str:
    """The port of ``leaf`` that names blackboard ``key`` (the key itself if none)."""
    for name, port in leaf.ports.items():
        if port.key == key or (port.key or "").lstrip("@") == key:
            return name
    return key


def grounds(tree: Tree, leaf: Node, failed: Transition, history: History) -> str:
    """`` (name = value, …)`` for ``leaf``'s FAILURE ``failed`` (see the module
    docstring), or "" when there is nothing to show."""
    # A leaf writes while it ticks, before its status change of that tick is logged: the
    # writes of its failing activation come after its change before that activation.
    start = history.last([leaf.uid], ANY_STATUS, 0, failed.seq + 1, starts=True)
    began = failed.seq if start is None else start.seq
    before = history.last([leaf.uid], ANY_STATUS, 0, began)
    lo = 0 if before is None else before.seq + 1
    reported: dict[str, str] = {}
    for write in history.writes_by(leaf.uid, lo, failed.seq + 1, 4 * MAX_ITEMS):
        reported[_port_of(leaf, write.key)] = _shown(write.value)
    items = [f"{name} = {value}" for name, value in reported.items()]
    if not items and leaf.kind == CONDITION:
        items = _inputs(tree, leaf, failed, history)
    return f" ({'; '.join(items[:MAX_ITEMS])})" if items else ""


def _inputs(tree: Tree, leaf: Node, failed: Transition, history: History) -> list[str]:
    """The condition's keyed inputs at its failure, with their writers."""
    keyed = [p.key for p in leaf.ports.values() if p.key and p.direction in (INPUT, INOUT)]
    if not keyed:
        return []
    _, then = history.state_after(failed.seq + 1)
    board = board_of(leaf, then.blackboard)
    items = []
    for key in dict.fromkeys(keyed):
        scope, resolved, found = board.locate(key)
        if not found:
            continue
        write = history.last_write(scope, resolved, 0, failed.seq + 1)
        text = f"{key} = {_shown(then.blackboard[scope][resolved])}"
        if write is not None and write.writer is not None and write.writer in tree.nodes:
            text += f", written by {words(tree.node(write.writer))} at {seconds(write.t_ns)} s"
        items.append(text)
    return items


def grounded(text: str, tree: Tree, leaf: Node, now: int, history: History) -> str:
    """``text``, a sentence ending in ``{leaf} failed.``, with the grounds of ``leaf``'s
    last failure before event ``now`` added before its full stop."""
    failed = history.last([leaf.uid], (FAILURE,), 0, now)
    if failed is None or not text.endswith(" failed."):
        return text
    return text[:-1] + grounds(tree, leaf, failed, history) + "."

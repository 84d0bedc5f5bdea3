"""How an answer speaks of nodes (their words) and of times.

The paper's ``d(n)`` is a node's name, or its registration ID when it has none; the
paper's trees name their nodes in English ("look at chuck"), so ``d(n)`` reads as a verb
phrase. Real trees name nodes as identifiers — ``ComputePathToPose``,
``ClearLocalCostmap-Context``, ``follow_path`` — and leave most control nodes unnamed
(BehaviorTree.CPP then gives them their type as a name: a ``<Sequence>`` is named
"Sequence"). An answer that says "I ComputePathToPose in order to Sequence." is no
answer. So, in answers (never in tables, SQL or the timeline, which keep names as
recorded):

- a node's **own description** comes first: its ``_description`` attribute, which
  BehaviorTree.CPP 4 reserves on every node (and on a ``<BehaviorTree>``, for the SubTree
  that runs it), or what a descriptions file (``--descriptions FILE``) gives for its path,
  name or type — the loader stores both as the node's ``_description``, so a recording
  carries them and post-hoc answers equal live ones;
- else its name or type as **words**: an identifier is cut at its case changes,
  underscores and hyphens and lower-cased ("compute path to pose", "clear local costmap
  context"), acronyms kept ("read IMU"); a node's own type standing first or last in its
  name is dropped ("FallbackComputePathToPose" on a Fallback is "compute path to pose");
  a name that already has spaces is kept as it is, so the paper's answers do not change;
- a node is **named** when its name is neither empty nor its type. Only named nodes
  (and SubTrees) are purposes, subgoals, steps or goals; an unnamed control node is
  never spoken of — the answer climbs to the nearest named ancestor instead.
"""

from __future__ import annotations

import re

from btlog.tree.descriptions import DESCRIPTION
from btlog.tree.model import SUBTREE, Node, Tree

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")
_WORD = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+[0-9]*|[A-Z]+[0-9]*|[0-9]+")


def split_identifier(text: str) -> list[str]:
    """The words of an identifier: ``ClearLocalCostmap-Context`` → ``clear, local,
    costmap, context``; acronyms stay upper case (``ReadIMUData`` → ``read, IMU, data``)."""
    words = []
    for part in re.split(r"[_\-]+", text):
        for word in _WORD.findall(part):
            words.append(word if len(word) > 1 and word.isupper() else word.lower())
    return words


def humanize(text: str, own_type: str = "") -> str:
    """``text`` as words when it is an identifier (see the module docstring), else as it
    is; ``own_type``, the node's type, is dropped from either end of the words."""
    if not _IDENTIFIER.match(text):
        return text
    words = split_identifier(text)
    if own_type and own_type != text and _IDENTIFIER.match(own_type):
        drop = split_identifier(own_type)
        if len(words) > len(drop) and words[: len(drop)] == drop:
            words = words[len(drop) :]
        elif len(words) > len(drop) and words[-len(drop) :] == drop:
            words = words[: -len(drop)]
    return " ".join(words) if words else text


def is_named(node: Node) -> bool:
    """True when the node has a name of its own (not empty, not its type), a description,
    or is a SubTree (whose name is the subtree's)."""
    if node.attributes.get(DESCRIPTION, "").strip():
        return True
    return node.kind == SUBTREE or (bool(node.name) and node.name != node.type)


def words(node: Node) -> str:
    """The node as an answer speaks of it (see the module docstring)."""
    own = node.attributes.get(DESCRIPTION, "").strip()
    if own:
        return " ".join(own.split())
    if node.name and node.name != node.type:
        return humanize(node.name, node.type)
    return humanize(node.description)


def named_ancestor(node: Node, *, skip_decorators: bool = False) -> Node | None:
    """The nearest ancestor that is named (a decorator too, unless ``skip_decorators``)."""
    for ancestor in node.ancestors():
        if is_named(ancestor) and not (skip_decorators and ancestor.kind == "decorator"):
            return ancestor
    return None


def first_named(node: Node) -> Node:
    """``node`` when it is named, else the first named node below it (depth first) —
    what an unnamed branch does first ("fell back to clear local costmap context");
    ``node`` itself when nothing below is named."""
    for inner in node.walk():
        if is_named(inner) and inner.kind != "decorator":
            return inner
    return node


def goal_words(tree: Tree) -> str:
    """The goal as an answer speaks of it: the root when it is named, else the main
    tree's own name (its ``BehaviorTree`` ID)."""
    root = tree.root
    if is_named(root) or not tree.name:
        return words(root)
    return humanize(tree.name)


def seconds(t_ns: int) -> str:
    """A time or duration as answers and the commands print it: seconds, millisecond
    precision."""
    return f"{t_ns / 1e9:.3f}"

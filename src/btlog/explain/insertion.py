"""Dynamic insertion as a subgoal (the paper's Algorithms 8 and 9): "Can you X?"

A node cannot simply be run again anywhere: its leaves may read blackboard keys that
other nodes write. Algorithm 8 finds the *self-contained* node: starting from the node
that matches X (a Sequence or SubTree preferred, the shallowest), it climbs to ancestors
until every keyed input of its execution descendants is written by one of them.
Algorithm 9 inserts a deep copy of that node right after the current subgoal
(``btlog.explain.hierarchy.subgoal_node``: the nearest SubTree above the current node,
else the goal's step that holds it), in the subgoal's parent; where that parent is a
decorator (one child only), right after the decorator, in the nearest control node.

``plan_insertion`` is pure: it returns where the copy would go. The live executor
applies the plan (recording a ``TreeMutation``); a post-hoc question applies it to a
copy of the tree, to show what would have happened.
"""

from __future__ import annotations

from dataclasses import dataclass

from btlog.explain.hierarchy import subgoal_node
from btlog.explain.words import words
from btlog.tree.model import CONTROL, INOUT, INPUT, OUTPUT, SUBTREE, Node, Tree

PREFERRED_TYPES = ("Sequence", "SubTree")


@dataclass(frozen=True)
class InsertionPlan:
    """Insert a copy of ``source`` under ``parent`` right after ``after``."""

    requested: Node
    source: Node
    parent: Node
    after: Node

    def to_json(self) -> dict:
        """The plan as uids."""
        return {
            "requested_uid": self.requested.uid,
            "source_uid": self.source.uid,
            "parent_uid": self.parent.uid,
            "after_uid": self.after.uid,
        }


def find_requested(tree: Tree, wanted: str) -> Node | None:
    """The node whose d(n) or words are ``wanted`` (case-insensitive): a Sequence or
    SubTree if there is one, else any node; the shallowest, then the first in tree order."""
    key = " ".join(wanted.lower().split())
    matches = [n for n in tree if key in (n.description.lower(), words(n).lower())]
    if not matches:
        return None
    preferred = [n for n in matches if n.type in PREFERRED_TYPES or n.kind == SUBTREE]
    pool = preferred or matches
    return min(pool, key=lambda n: n.depth)


def _keys(node: Node, directions: tuple[str, ...]) -> list[str]:
    keys: list[str] = []
    for leaf in node.walk():
        if not leaf.is_execution:
            continue
        for port in leaf.ports.values():
            key = port.key
            if port.direction in directions and key is not None and key not in keys:
                keys.append(key)
    return keys


def self_contained(node: Node) -> Node | None:
    """Algorithm 8: the nearest node at or above ``node`` whose execution descendants
    write every keyed input its execution descendants read; None if there is none."""
    found: Node | None = node
    for key in _keys(node, (INPUT, INOUT)):
        while found is not None and key not in _keys(found, (OUTPUT, INOUT)):
            found = found.parent
        if found is None:
            return None
    return found


def plan_insertion(tree: Tree, current: Node | None, wanted: str) -> InsertionPlan | None:
    """Algorithms 8 and 9: where a copy of the self-contained node for ``wanted`` goes
    (after the current subgoal), or None when it cannot be done."""
    requested = find_requested(tree, wanted)
    if requested is None or current is None:
        return None
    after = subgoal_node(current)
    while after is not None and after.parent is not None and after.parent.kind != CONTROL:
        after = after.parent
    if after is None or after is tree.root or after.parent is None:
        return None
    source = self_contained(requested)
    if source is None or source is tree.root:
        return None
    return InsertionPlan(requested, source, after.parent, after)


def apply_to_copy(tree: Tree, plan: InsertionPlan, seq: int | None = None) -> Tree:
    """A copy of ``tree`` with the plan applied (for showing a post-hoc answer)."""
    copy = Tree.from_description(tree.describe())
    inserted = copy.copy_subtree(copy.node(plan.source.uid), copy.next_uid)
    copy.insert_after(copy.node(plan.parent.uid), copy.node(plan.after.uid), inserted, seq)
    return copy

"""Hierarchical explanations (the paper's Algorithms 1–6): what, why, subgoal, goal, how.

The paper frames a tree as semantic sets {goal, subgoals, steps, actions}: the goal is
the main tree's root, a subgoal is a SubTree, steps are the named, non-decorator nodes
below a (sub)goal whose names differ from it, and actions are the execution nodes.
Each function here takes the tree and the current node (see ``current_nodes``) and
returns the sentence of the paper's templates; ``d(n)`` is ``Node.description``.
"""

from __future__ import annotations

from collections.abc import Callable

from btlog.state import State
from btlog.status import IDLE, RUNNING
from btlog.tree.model import DECORATOR, SUBTREE, Node, Tree


def current_nodes(tree: Tree, state: State) -> list[Node]:
    """The execution nodes RUNNING now (tree order); if none, the last execution node to
    change status (resets to IDLE do not count); empty before any leaf ran."""
    running = [n for n in tree if n.is_execution and state.status.get(n.uid, IDLE) is RUNNING]
    if running:
        return running
    if state.last_leaf is not None and state.last_leaf in tree.nodes:
        return [tree.node(state.last_leaf)]
    return []


def join_answers(texts: list[str]) -> str:
    """Distinct answers joined with " and " (one answer per current node)."""
    distinct = list(dict.fromkeys(texts))
    if len(distinct) == 1:
        return distinct[0]
    return " and ".join(t.rstrip(".") for t in distinct[:-1]) + " and " + distinct[-1]


def per_node(nodes: list[Node], render: Callable[[Node], str], empty: str) -> str:
    """``render`` for each current node, joined; ``empty`` (the refusal) when there is
    none. Only real answers are joined: a node whose answer is the refusal itself (a
    branch of a Parallel outside any subgoal) is left out, never spliced in."""
    texts = [text for text in (render(n) for n in nodes) if text != empty]
    return join_answers(texts) if texts else empty


def doing(node: Node) -> str:
    """Q1 (Algorithm 1): ``I {d(n)}.``"""
    return f"I {node.description}."


def reason_node(node: Node) -> Node | None:
    """Algorithm 2's p: the nearest non-decorator ancestor with a non-empty name that
    differs from d(n)."""
    for ancestor in node.ancestors():
        if ancestor.kind != DECORATOR and ancestor.name and ancestor.name != node.description:
            return ancestor
    return None


def why(node: Node) -> str:
    """Q2 (Algorithm 2): ``I {d(n)} in order to {p}.``"""
    reason = reason_node(node)
    if reason is None:
        return f"I {node.description} because it is my goal."
    return f"I {node.description} in order to {reason.description}."


def subgoal_node(node: Node) -> Node | None:
    """Algorithm 3's p: the nearest SubTree ancestor."""
    return next((a for a in node.ancestors() if a.kind == SUBTREE), None)


def subgoal(node: Node) -> str:
    """Q3 (Algorithm 3)."""
    found = subgoal_node(node)
    if found is None:
        return "Sorry. I don't have a subgoal."
    return f"My subgoal is to {found.description}."


def goal(tree: Tree) -> str:
    """Q4 (Algorithm 4): the main tree's root."""
    return f"My goal is to {tree.root.description}."


def steps(target: Node) -> list[Node]:
    """Algorithm 5: depth-first below ``target``, the first named, non-decorator nodes
    whose name differs from the target's; their branches are not explored further."""
    found: list[Node] = []

    def visit(node: Node) -> None:
        if node.kind != DECORATOR and node.name and node.name != target.name:
            found.append(node)
            return
        for child in node.children:
            visit(child)

    for child in target.children:
        visit(child)
    return found


def how(target: Node | None, level: str) -> str:
    """Q5 (Algorithm 6) for ``level`` "goal" or "subgoal"."""
    if target is None:
        return f"Sorry. I don't have a {level}."
    found = steps(target)
    count = len(found)
    listed = " ".join(f"{i}. {n.description}." for i, n in enumerate(found, 1))
    noun = "step" if count == 1 else "steps"
    text = f'To achieve the {level} "{target.description}", I need to do {count} {noun}.'
    return f"{text} {listed}" if listed else text

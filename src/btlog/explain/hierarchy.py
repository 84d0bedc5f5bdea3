"""Hierarchical explanations (the paper's Algorithms 1–6): what, why, subgoal, goal, how.

The paper frames a tree as semantic sets {goal, subgoals, steps, actions}: the goal is
the main tree's root, a subgoal is a SubTree, steps are the named, non-decorator nodes
below a (sub)goal whose names differ from it, and actions are the execution nodes.

Real trees are seldom framed so: Nav2's default trees have no SubTree at all. One rule
covers both (docs/design.md, "Subgoals"): a node's **subgoal** is its nearest named
SubTree ancestor, as in the paper (a SubTree named "MainTree" restates a tree's ID and is
no name, ``words.is_named``); where no SubTree is above it, the **goal's step** that holds
it — the topmost named, non-decorator node between it and the root (Algorithm 5 run from
the root), the node itself when it is such a step. In Nav2's NavigateToPose tree the
goal's steps are "navigate with replanning" and "recovery fallback", so clearing the
local costmap serves the subgoal "navigate with replanning"; in a tree whose root
Sequence holds "get to kitchen", "retry grasp" (a decorator) and "bring coffee", grasping
the cup is itself the subgoal "grasp cup". Q3, Q5, the run's story, ``check --rerun``'s
grouping and "Can you X?" all use this one rule.

Each answer speaks of nodes by their words (``btlog.explain.words``); the current node
is ``current_nodes``'s.
"""

from __future__ import annotations

from collections.abc import Callable

from btlog.explain.words import act, goal_words, is_named, words
from btlog.state import State
from btlog.status import RUNNING
from btlog.tree.model import DECORATOR, SUBTREE, Node, Tree


def current_nodes(tree: Tree, state: State) -> list[Node]:
    """The execution nodes RUNNING now (tree order); if none, the last execution node to
    change status (resets to IDLE do not count); empty before any leaf ran."""
    running = [tree.nodes[uid] for uid in state.running if uid in tree.nodes]
    running = [n for n in running if n.is_execution and state.status_of(n.uid) is RUNNING]
    if running:
        return in_tree_order(running)
    if state.last_leaf is not None and state.last_leaf in tree.nodes:
        return [tree.node(state.last_leaf)]
    return []


def in_tree_order(nodes: list[Node]) -> list[Node]:
    """``nodes`` of one tree in depth-first pre-order, without walking the tree: sorted by
    their paths of positions among siblings (each parent's children indexed once)."""
    if len(nodes) < 2:
        return nodes
    positions: dict[int, dict[int, int]] = {}

    def path(node: Node) -> list[int]:
        steps = []
        while node.parent is not None:
            parent = node.parent
            index = positions.get(id(parent))
            if index is None:
                index = positions[id(parent)] = {id(c): i for i, c in enumerate(parent.children)}
            steps.append(index[id(node)])
            node = parent
        return steps[::-1]

    return sorted(nodes, key=path)


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
    return f"I {act(node)}."


def reason_node(node: Node) -> Node | None:
    """Algorithm 2's p: the nearest named non-decorator ancestor whose words differ from
    the node's."""
    own = words(node)
    for ancestor in node.ancestors():
        if ancestor.kind != DECORATOR and is_named(ancestor) and words(ancestor) != own:
            return ancestor
    return None


def why(node: Node, tree: Tree | None = None) -> str:
    """Q2 (Algorithm 2): ``I {d(n)} in order to {p}.``; with nothing named above the node,
    in order to the goal (the main tree's name), and the root itself is the goal."""
    reason = reason_node(node)
    if reason is not None:
        return f"I {act(node)} in order to {words(reason)}."
    goal_said = goal_words(tree) if tree is not None else None
    if node.parent is None or goal_said is None or goal_said == words(node):
        return f"I {act(node)} because it is my goal."
    return f"I {act(node)} in order to {goal_said}."


def _root_of(node: Node) -> Node:
    while node.parent is not None:
        node = node.parent
    return node


def _is_step_of(node: Node, target: Node) -> bool:
    """Algorithm 5's test: a named non-decorator node whose words differ from the
    (sub)goal's."""
    return node.kind != DECORATOR and is_named(node) and words(node) != words(target)


def subgoal_node(node: Node) -> Node | None:
    """The node's subgoal (see the module docstring): the nearest SubTree ancestor, else
    the goal's step holding the node (the node itself when it is one); None for the root
    and for nodes outside every step."""
    chain = []
    for ancestor in node.ancestors():
        if ancestor.kind == SUBTREE and is_named(ancestor):
            return ancestor
        chain.append(ancestor)
    if not chain:
        return None
    root = chain.pop()  # the root is the goal, never a subgoal
    step = None
    for candidate in [node, *chain]:
        if _is_step_of(candidate, root):
            step = candidate  # the topmost one wins: Algorithm 5 stops there
    return step


def subgoal_of(node: Node, tree: Tree) -> Node:
    """The node's subgoal, or the goal (the root) when it has none: how behaviours are
    grouped (``btlog diff``, ``check --rerun``)."""
    return subgoal_node(node) or tree.root


def subgoals(tree: Tree) -> list[Node]:
    """Every subgoal of the tree, in tree order: its SubTrees, and the goal's steps that
    hold execution nodes outside every SubTree."""
    found: dict[int, Node] = {}
    for node in tree:
        if node.kind == SUBTREE and is_named(node):
            found[node.uid] = node
        elif node.is_execution:
            step = subgoal_node(node)
            if step is not None and step.kind != SUBTREE:
                found[step.uid] = step
    order = {n.uid: i for i, n in enumerate(tree)}
    return sorted(found.values(), key=lambda n: order[n.uid])


def subgoal(node: Node) -> str:
    """Q3 (Algorithm 3)."""
    found = subgoal_node(node)
    if found is None:
        return "Sorry. I don't have a subgoal."
    return f"My subgoal is to {words(found)}."


def goal(tree: Tree) -> str:
    """Q4 (Algorithm 4): the main tree's root."""
    return f"My goal is to {goal_words(tree)}."


def steps(target: Node) -> list[Node]:
    """Algorithm 5: depth-first below ``target``, the first named, non-decorator nodes
    whose words differ from the target's; their branches are not explored further. An
    execution node is its own one step; where nothing below is named, the steps are the
    execution nodes below, in tree order."""
    if target.is_execution:
        return [target]
    found: list[Node] = []
    stack = list(reversed(target.children))
    while stack:
        node = stack.pop()
        if _is_step_of(node, target):
            found.append(node)
        else:
            stack.extend(reversed(node.children))
    return found or [n for n in target.walk() if n.is_execution]


def how(target: Node | None, level: str, tree: Tree | None = None) -> str:
    """Q5 (Algorithm 6) for ``level`` "goal" or "subgoal"."""
    if target is None:
        return f"Sorry. I don't have a {level}."
    found = steps(target)
    count = len(found)
    listed = " ".join(f"{i}. {act(n)}." for i, n in enumerate(found, 1))
    noun = "step" if count == 1 else "steps"
    name = goal_words(tree) if tree is not None and target is tree.root else words(target)
    text = f'To achieve the {level} "{name}", I need to do {count} {noun}.'
    return f"{text} {listed}" if listed else text

"""Questions about one node's past: why did X fail, why didn't you X, when did X last
fail/succeed/start, how long did X take.

``{X}`` is matched as ``--node`` matches (``find_node``): a path, a name, or a type,
case-insensitively; when several nodes match — a SubTree, its root and a Sequence often
share a name — the outermost is meant. Every answer reads the history up to the moment
only, so it is the same live and post hoc.
"""

from __future__ import annotations

from btlog.explain.causes import because
from btlog.explain.failure import spoken
from btlog.explain.grounds import grounds
from btlog.explain.handlers import FallbackHandler, handler_of
from btlog.explain.words import act, goal_words, humanize, is_named, seconds, words
from btlog.history import ANY_STATUS, COMPLETIONS, History, Transition, activation_end
from btlog.state import State
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from btlog.tree.model import Node, Tree

#: How far after a halt (events, and ns of the run's clock: the same tick) the ancestor
#: that halted a node returns its result.
HALT_WINDOW = 4096
HALT_WINDOW_NS = 1_000_000

#: "When did X last …?": the statuses asked about and the words of the answer.
EVENTS: dict[str, tuple[tuple[Status, ...], bool, str, str]] = {
    "fail": ((FAILURE,), False, "failed", "has not failed"),
    "succeed": ((SUCCESS,), False, "succeeded", "has not succeeded"),
    "start": (tuple(Status), True, "started", "has not started"),
}


def _fold(text: str) -> str:
    return " ".join(text.casefold().split())


def find_nodes(tree: Tree, text: str) -> list[Node]:
    """The nodes ``text`` names, outermost first: by path, name or the words an answer
    speaks of them with (``compute path to pose`` is ``ComputePathToPose``), else by
    type (nameless nodes first)."""
    wanted = _fold(text.strip().strip("\"'“”‘’"))
    wanted_bare = wanted[4:] if wanted.startswith("the ") else wanted
    groups: dict[int, list[tuple[int, int, Node]]] = {}
    for order, node in enumerate(tree):
        names = {_fold(node.name), _fold(words(node)), _fold(act(node))}
        if (
            node.path == text
            or _fold(node.path) == wanted
            or wanted in names
            or wanted_bare in names
        ):
            rank = 1
        elif _fold(node.type) == wanted or _fold(humanize(node.type)) == wanted:
            rank = 2 if not is_named(node) else 3
        else:
            continue
        groups.setdefault(rank, []).append((node.depth, order, node))
    if not groups:
        return []
    return [node for _, _, node in sorted(groups[min(groups)], key=lambda m: m[:2])]


def find_node(tree: Tree, text: str) -> Node | None:
    """The outermost node ``text`` names (see ``find_nodes``), or None."""
    found = find_nodes(tree, text)
    return found[0] if found else None


def about(nodes: list[Node], event: str | None, state: State, history: History) -> Node:
    """Of several nodes with the name asked about, the outermost that the question can
    be about: the outermost one with the ``event`` ("fail", "succeed", "start") in its
    history, else the outermost."""
    if event is not None and len(nodes) > 1:
        statuses, starts, _, _ = EVENTS[event]
        for node in nodes:
            if history.last([node.uid], statuses, 0, state.seq, starts=starts) is not None:
                return node
    return nodes[0]


def why_failed(tree: Tree, node: Node, state: State, history: History) -> str:
    """``I could not {d(X)} because {d(leaf)} failed.`` for X's last FAILURE; for an
    execution node, whose failure has no cause below it in the tree, when it failed and
    its grounds (what it reported or, a condition, read): ``{d(X)} failed at {t} s
    ({grounds}).``"""
    failed = history.last([node.uid], (FAILURE,), 0, state.seq)
    if failed is None:
        return f"{words(node)} has not failed."
    if node.is_execution:  # "because it failed" says nothing: when, and its grounds
        found = grounds(tree, node, failed, history)
        return f"{words(node)} failed at {seconds(failed.t_ns)} s{found}."
    return f"I could not {words(node)} because {because(tree, node, failed, history)}."


def why_not(tree: Tree, node: Node, state: State, history: History) -> str:
    """Why X did not happen (see the README's table): X's last activation in its
    parent's last activation — it failed, was halted, still runs or succeeded — or, when
    X did not start there, the earlier sibling's result that kept it from starting."""
    now, asked = state.seq, node
    while node.parent is not None:
        parent = node.parent
        start = history.last([parent.uid], ANY_STATUS, 0, now, starts=True)
        if start is None:
            node = parent
            continue
        if history.first([node.uid], ANY_STATUS, start.seq, now, starts=True) is None:
            return _reason(tree, asked, node, start.seq, state, history)
        return _last_activation(tree, asked, state, history) if node is asked else _not_yet(asked)
    ran = history.last([node.uid], ANY_STATUS, 0, now, starts=True)
    if ran is None or node is not asked:
        return _not_yet(asked)
    return _last_activation(tree, asked, state, history)


def _not_yet(node: Node) -> str:
    return f"I have not started to {act(node)} yet."


def _last_activation(tree: Tree, node: Node, state: State, history: History) -> str:
    """How X's last activation went: ``I did X.``, ``I tried to X, but …``, ``I started
    to X at t s, but stopped at t s because …``, or ``I am still trying to X …``."""
    now = state.seq
    start = history.last([node.uid], ANY_STATUS, 0, now, starts=True)
    assert start is not None
    end = activation_end(history, start, now)
    if end is None:
        return f"I am still trying to {act(node)}: I started at {seconds(start.t_ns)} s."
    if end.status is SUCCESS:
        return f"I did {act(node)}."
    if end.status is FAILURE:
        return f"I tried to {act(node)}, but {_because_of(tree, node, end, history)}."
    text = f"I started to {act(node)} at {seconds(start.t_ns)} s, but stopped at "
    return text + f"{seconds(end.t_ns)} s{_halted_because(tree, node, start, end, now, history)}."


def _because_of(tree: Tree, node: Node, failed: Transition, history: History) -> str:
    """``{leaf} failed`` for X's FAILURE, ``it failed`` when X is the leaf."""
    reason = because(tree, node, failed, history)
    own = f"{words(node)} failed"
    return (
        "it failed" + reason[len(own) :] if reason.startswith(own) and node.is_execution else reason
    )


def _halted_because(
    tree: Tree, node: Node, start: Transition, halt: Transition, now: int, history: History
) -> str:
    """`` because {cause}`` of the halt: the completion of the nearest ancestor that
    completed while X ran (a Timeout, a Parallel's other branch) or that halted it and
    then returned its result (a reactive parent whose check failed), or "" when the tree
    itself was stopped. Nothing after ``now`` is looked at: a live answer cannot know it."""
    ancestors = [a.uid for a in node.ancestors()]
    done = history.last(ancestors, COMPLETIONS, start.seq, halt.seq)
    if done is None:  # halted by an ancestor that completes right after its children stop
        done = history.first(ancestors, COMPLETIONS, halt.seq, min(halt.seq + HALT_WINDOW, now))
        if done is not None and done.t_ns - halt.t_ns > HALT_WINDOW_NS:
            done = None
    if done is None:
        return ""
    return f" because {because(tree, tree.node(done.uid), done, history)}"


def _reason(tree: Tree, asked: Node, node: Node, since: int, state: State, history: History) -> str:
    """Why ``node`` (``asked`` or its ancestor) did not start in its parent's activation
    that began at ``since``: an earlier sibling's result."""
    parent = node.parent
    assert parent is not None
    earlier = [c.uid for c in parent.children[: parent.children.index(node)]]
    fallback = isinstance(handler_of(parent), FallbackHandler)
    if parent.type in ("IfThenElse", "WhileDoElse") and parent.children.index(node) == 2:
        fallback = True
    done = history.last(earlier, (SUCCESS,) if fallback else (FAILURE,), since, state.seq)
    if done is None:
        return _ended_before(tree, asked, parent, since, state, history) or _not_yet(asked)
    sibling = tree.node(done.uid)
    if fallback and (is_named(sibling) or sibling.is_execution):
        return f"I did not {act(asked)} because {words(sibling)} succeeded."
    # an unnamed branch is never spoken of: what decided its result is
    return f"I did not {act(asked)} because {because(tree, sibling, done, history)}."


def _ended_before(
    tree: Tree, asked: Node, parent: Node, since: int, state: State, history: History
) -> str | None:
    """When ``parent``'s activation that began at ``since`` is over without reaching
    ``asked`` (it was stopped, or completed otherwise): ``I did not {X}: {scope} was
    stopped at {t} s, before it was reached{because}.``; None while it still runs."""
    start = history.first([parent.uid], ANY_STATUS, since, since + 1)
    end = None if start is None else activation_end(history, start, state.seq)
    if start is None or end is None:
        return None
    scope = spoken(parent, goal_words(tree))
    if end.status is IDLE:
        how = f"was stopped at {seconds(end.t_ns)} s"
        reason = _halted_because(tree, parent, start, end, state.seq, history)
    else:
        how = f"{'failed' if end.status is FAILURE else 'succeeded'} at {seconds(end.t_ns)} s"
        reason = ""
    return f"I did not {act(asked)}: {scope} {how}, before it was reached{reason}."


def when_last(node: Node, event: str, state: State, history: History) -> str:
    """``{d(X)} last failed at {t} s.`` (succeeded, started), or ``… has not failed.``"""
    statuses, starts, did, never = EVENTS[event]
    found = history.last([node.uid], statuses, 0, state.seq, starts=starts)
    if found is None:
        return f"{words(node)} {never}."
    return f"{words(node)} last {did} at {seconds(found.t_ns)} s."


def how_long(node: Node, state: State, history: History, now_ns: int) -> str:
    """``{d(X)} took {d} s, from {t0} s to {t1} s.`` for its last completed activation;
    ``{d(X)} has been running for {d} s.`` while it runs (until ``now_ns``)."""
    now = state.seq
    start = history.last([node.uid], ANY_STATUS, 0, now, starts=True)
    if start is None:
        return f"{words(node)} has not started."
    if state.status_of(node.uid) is RUNNING:
        return f"{words(node)} has been running for {seconds(now_ns - start.t_ns)} s."
    done = history.last([node.uid], COMPLETIONS, 0, now)
    if done is None:
        return f"{words(node)} has not completed."
    began = history.last([node.uid], ANY_STATUS, 0, done.seq + 1, starts=True)
    t0 = done.t_ns if began is None else began.t_ns
    return (
        f"{words(node)} took {seconds(done.t_ns - t0)} s, "
        f"from {seconds(t0)} s to {seconds(done.t_ns)} s."
    )

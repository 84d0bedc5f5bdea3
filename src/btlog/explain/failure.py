"""Failure explanations (the paper's Algorithm 7): what went wrong, and how it was handled.

Walking up from the current node to its subgoal, two kinds of node handle failures:

- a Fallback whose first child failed in the Fallback's current activation: it fell
  back. ``I could not {d(fallback)} because [I was unable to {d(parent)} as] {d(leaf)}
  failed.`` — the clause in brackets when the failed leaf's parent says something else;
- a RetryUntilSuccessful that has failed k > 0 times in its current run: ``I am retrying
  for attempt {k} to {d(named ancestor of the retry)}. I could not {d(named ancestor of
  the leaf)} because {d(leaf)} failed.``

Nav2's RecoveryNode is both: once its first child failed in its current activation it
falls back (the Fallback sentence, naming the RecoveryNode), and while its first child
is retried after a recovery it is retrying (the retry sentence, for the RecoveryNode
itself, which Nav2 trees name after what it protects).

When both apply the retry sentence comes first. "The failed leaf" is read from the order
of events: the execution node inside the failed branch whose FAILURE is the most recent
since the handler's activation began, so a failure of an earlier attempt is never
blamed for a later one.
"""

from __future__ import annotations

from collections.abc import Iterator

from btlog.state import RECOVERY_TYPE, RETRY_TYPE, State
from btlog.tree.model import SUBTREE, Node

FALLBACK_TYPES = ("Fallback", "ReactiveFallback", RECOVERY_TYPE)
NOTHING_WRONG = "Nothing went wrong."


def _named_ancestor(node: Node) -> Node | None:
    return next((a for a in node.ancestors() if a.name), None)


def failed_leaf(branch: Node, state: State, since: int) -> Node | None:
    """The execution node in ``branch`` whose most recent FAILURE (at or after event
    ``since``) is the latest; any failed node if no execution node failed."""
    best: tuple[int, int, Node] | None = None
    for node in branch.walk():
        failed = state.last_failure.get(node.uid)
        if failed is None or failed < since:
            continue
        rank = (1 if node.is_execution else 0, failed)
        if best is None or rank > best[:2]:
            best = (*rank, node)
    return None if best is None else best[2]


def _fallback_sentence(fallback: Node, state: State) -> str | None:
    since = state.activation.get(fallback.uid)
    first = fallback.children[0] if fallback.children else None
    if since is None or first is None or not state.failed_since(first.uid, since):
        return None
    leaf = failed_leaf(first, state, since) or first
    text = f"I could not {fallback.description} because "
    parent = leaf.parent
    if parent is not None and parent is not fallback and parent.description != fallback.description:
        text += f"I was unable to {parent.description} as "
    return text + f"{leaf.description} failed."


def _retry_attempt(retry: Node, state: State) -> str | None:
    attempts = state.retry_attempts.get(retry.uid, 0)
    if attempts <= 0:
        return None
    target = retry if retry.type == RECOVERY_TYPE else _named_ancestor(retry)
    if target is None:
        return None
    return f"I am retrying for attempt {attempts} to {target.description}."


def _retry_sentence(retry: Node, state: State) -> str | None:
    head = _retry_attempt(retry, state)
    if head is None:
        return None
    since = state.activation.get(retry.uid, 0)
    leaf = failed_leaf(retry, state, since)
    if leaf is None:
        return head
    context = _named_ancestor(leaf)
    what = context.description if context is not None else leaf.description
    return f"{head} I could not {what} because {leaf.description} failed."


def what_went_wrong(node: Node | None, state: State) -> str:
    """Q6 for one current node (Algorithm 7)."""
    if node is None:
        return NOTHING_WRONG
    child, ancestor = node, node.parent
    while ancestor is not None and ancestor.kind != SUBTREE:
        if ancestor.type in FALLBACK_TYPES:
            sentence = _fallback_sentence(ancestor, state)
            if sentence is not None:
                retries = [_retry_attempt(a, state) for a in _retrying(ancestor, child)]
                return " ".join([*(r for r in retries if r), sentence])
        elif ancestor.type == RETRY_TYPE:
            sentence = _retry_sentence(ancestor, state)
            if sentence is not None:
                return sentence
        child, ancestor = ancestor, ancestor.parent
    return NOTHING_WRONG


def _retrying(node: Node, via: Node) -> Iterator[Node]:
    """The retrying handlers from ``node`` up to the subgoal, reached from ``node``'s child
    ``via``: every RetryUntilSuccessful, and a RecoveryNode when reached through its
    first child (the one it retries)."""
    current: Node | None = node
    while current is not None and current.kind != SUBTREE:
        if current.type == RETRY_TYPE or (
            current.type == RECOVERY_TYPE and current.children[0] is via
        ):
            yield current
        via, current = current, current.parent

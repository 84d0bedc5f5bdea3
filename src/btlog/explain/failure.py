"""Failure explanations (the paper's Algorithm 7): what went wrong, and how it was handled.

Walking up from the current node to its subgoal, two kinds of failure handler
(``btlog.explain.handlers``) have something to say:

- one that **fell back**: a Fallback (or Nav2's RecoveryNode) whose first child failed in
  its current activation. ``I could not {fallback} because [I was unable to {step} as]
  {leaf} failed.`` — the clause in brackets names the nearest named node between the
  leaf and the fallback when it says something else than the fallback;
- one that **retries**: a RetryUntilSuccessful (or a RecoveryNode retrying its first
  child) whose child has failed k > 0 times in its current activation. ``I am retrying
  for attempt {k} to {what}. I could not {step} because {leaf} failed.`` — *what* is the
  retry's own words when it is named (a user who names a RetryUntilSuccessful "retry
  grasp" says what it retries), else, as in the paper, its nearest named ancestor;
  *step* is the nearest named ancestor of the leaf. A named retry is never said to have
  failed: when nothing named lies between the leaf and it, the answer is ``I am retrying
  for attempt {k} to {what} because {leaf} failed.``

When both apply the retry sentence comes first. Unnamed nodes are never spoken of: the
answer climbs to the nearest named one (``btlog.explain.words``).

**The failed leaf** is found down the causal chain, from the failed child: at each node,
the child whose failure came last before the node's own, down to an execution node — so
a failure of an earlier attempt, or of another branch, is never blamed.

**Guards are not failures.** A condition that fails in front of the branch it guards is
the tree choosing a branch, not something going wrong: Nav2's ``GoalUpdated`` first in a
ReactiveFallback, ``IsGoalNearby`` in the ReactiveSequence that decides whether to
replan. The rule reads the tree's structure and the run, not names: a handler's child
failed *by guard* when no action below it failed in that activation, and either no
action below it started (conditions or scripts decided), or the leaf of its failure is a
condition that a reactive control (ReactiveSequence, ReactiveFallback, PipelineSequence)
within the child re-checks on every tick. A condition checked once after actions in a
plain Sequence (the paper's "check if grasped") is a real failure. A handler whose child
failed by guard has nothing to say; the walk goes on up, to a handler that holds a real
failure (or to "Nothing went wrong."). The same test marks guard failures in the run's
story and the fleet's causes (``btlog.explain.causes.by_design``)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

from btlog.explain.handlers import handler_of
from btlog.explain.words import goal_words, is_named, named_ancestor, words
from btlog.state import State
from btlog.tree.model import ACTION, CONDITION, DECORATOR, SUBTREE, Node, Tree

NOTHING_WRONG = "Nothing went wrong."


def failed_leaf(branch: Node, state: State, since: int) -> Node | None:
    """The execution node whose failure made ``branch`` fail (its last failure at or
    after event ``since``), down the causal chain; when the chain stops at a node none of
    whose children failed (an Inverter, a Timeout), the latest failed execution node in
    ``branch`` since then; None when nothing in ``branch`` failed since ``since``."""
    node, until = branch, state.last_failure.get(branch.uid)
    if until is None or until < since:
        return _latest_failed(branch, state, since)
    while node.children:
        failed = [
            (seq, child)
            for child in node.children
            if (seq := state.last_failure.get(child.uid)) is not None and since <= seq <= until
        ]
        # A child that failed with no execution node failing below it failed by design
        # (a ForceFailure clean-up): the real failure is the one it was the alternative to.
        real = [pair for pair in failed if _has_failed_leaf(pair[1], state, since, pair[0])]
        if not (real or failed):
            break
        until, node = max(real or failed, key=lambda pair: pair[0])
    return node if node.is_execution else _latest_failed(node, state, since) or node


def _has_failed_leaf(branch: Node, state: State, since: int, until: int) -> bool:
    return any(
        n.is_execution and since <= state.last_failure.get(n.uid, -1) <= until
        for n in branch.walk()
    )


def _latest_failed(branch: Node, state: State, since: int) -> Node | None:
    best: tuple[int, int, Node] | None = None
    for node in branch.walk():
        failed = state.last_failure.get(node.uid)
        if failed is None or failed < since:
            continue
        rank = (1 if node.is_execution else 0, failed)
        if best is None or rank > best[:2]:
            best = (*rank, node)
    return None if best is None else best[2]


#: Controls that tick their earlier children again on every tick: a condition under one
#: is re-checked while the branch runs, the idiom of a guard.
REACTIVE_TYPES = frozenset({"ReactiveSequence", "ReactiveFallback", "PipelineSequence"})


def decided_by_guard(child: Node, leaf: Node | None, started: bool, failed: bool) -> bool:
    """The guard rule (see the module docstring), given the leaf of ``child``'s failure,
    whether an action below ``child`` started in that activation and whether one failed:
    no action failed, and either no action started (only conditions, or scripts, decided)
    or the leaf is a condition re-checked by a reactive control within ``child``."""
    if leaf is None or failed:
        return False
    if not started and leaf.kind != ACTION:
        return True
    return leaf.kind == CONDITION and _reactive_between(leaf, child)


def _reactive_between(leaf: Node, top: Node) -> bool:
    for ancestor in leaf.ancestors():
        if ancestor.type in REACTIVE_TYPES:
            return True
        if ancestor is top:
            return False
    return False


#: Whether a handler's child failed by design (with the run's history: see
#: ``btlog.explain.causes.by_design``); without it, guards are told from the state alone.
ByDesign = Callable[[Node], bool]


def _by_design(child: Node, state: State, designed: ByDesign | None) -> bool:
    return failed_by_guard(child, state) or (designed is not None and designed(child))


def failed_by_guard(child: Node, state: State) -> bool:
    """True when ``child``'s last failure was a guard's (``decided_by_guard``)."""
    began, failed = state.activation.get(child.uid), state.last_failure.get(child.uid)
    if began is None or failed is None or failed < began:
        return False
    actions = [n for n in child.walk() if n.kind == ACTION]
    started = any(began <= state.activation.get(a.uid, -1) <= failed for a in actions)
    broke = any(began <= state.last_failure.get(a.uid, -1) <= failed for a in actions)
    return decided_by_guard(child, failed_leaf(child, state, began), started, broke)


def _clause_node(leaf: Node, handler: Node) -> Node | None:
    """The nearest named, non-decorator node between ``leaf`` and ``handler``."""
    for ancestor in leaf.ancestors():
        if ancestor is handler:
            return None
        if is_named(ancestor) and ancestor.kind != DECORATOR:
            return ancestor
    return None


def spoken(node: Node, goal: str | None) -> str:
    """The words of ``node`` if it is named, else of its nearest named ancestor; the
    goal's words (``goal``) when nothing above is named."""
    named = node if is_named(node) else named_ancestor(node)
    if named is not None:
        return words(named)
    return goal if goal is not None else words(node)


def _fallback_sentence(
    fallback: Node, first: Node, state: State, goal: str | None, designed: ByDesign | None
) -> tuple[str, Node] | None:
    since = state.activation.get(fallback.uid)
    if since is None or not state.failed_since(first.uid, since):
        return None
    if _by_design(first, state, designed):
        return None
    leaf = failed_leaf(first, state, since) or first
    said = spoken(fallback, goal)
    text = f"I could not {said} because "
    step = _clause_node(leaf, fallback)
    if step is not None and words(step) != said:
        text += f"I was unable to {words(step)} as "
    return text + f"{words(leaf)} failed.", leaf


def _retry_target(retry: Node, goal: str | None) -> str | None:
    """What a retry's sentence says it retries for (see the module docstring)."""
    if is_named(retry):
        return words(retry)
    named = named_ancestor(retry)
    return words(named) if named is not None else goal


def _retry_attempt(
    retry: Node, state: State, goal: str | None, designed: ByDesign | None
) -> str | None:
    attempts = state.retry_attempts.get(retry.uid, 0)
    if attempts <= 0:
        return None
    handler = handler_of(retry)
    child = handler.retried(retry) if handler is not None else None
    if child is not None and (
        _by_design(child, state, designed) or _recovering(retry, child, state)
    ):
        return None
    target = _retry_target(retry, goal)
    if target is None:
        return None
    return f"I am retrying for attempt {attempts} to {target}."


def _recovering(handler: Node, child: Node, state: State) -> bool:
    """True while a handler that falls back from the child it retries (a RecoveryNode)
    recovers: it retries only once the recovery is over and the child runs again."""
    rule = handler_of(handler)
    if rule is None or rule.falls_back_from(handler) is not child:
        return False
    return state.activation.get(child.uid, -1) <= state.last_failure.get(child.uid, -1)


def _retry_sentence(
    retry: Node, state: State, goal: str | None, designed: ByDesign | None
) -> tuple[str, Node | None] | None:
    head = _retry_attempt(retry, state, goal, designed)
    if head is None:
        return None
    since = state.activation.get(retry.uid, 0)
    leaf = failed_leaf(retry.children[0], state, since)
    if leaf is None:
        return head, None
    if is_named(retry):
        step = _clause_node(leaf, retry)
        if step is None:
            return f"{head[:-1]} because {words(leaf)} failed.", leaf
    else:
        step = named_ancestor(leaf)
    what = words(step) if step is not None else words(leaf)
    return f"{head} I could not {what} because {words(leaf)} failed.", leaf


def diagnose(
    node: Node | None,
    state: State,
    tree: Tree | None = None,
    designed: ByDesign | None = None,
) -> tuple[str, Node | None]:
    """Q6 for one current node (Algorithm 7) and the node it blames (None when nothing
    went wrong, or a retry's leaf is unknown); ``tree`` gives the goal's words for
    handlers with nothing named above them; ``designed`` tells, from the run's history, a
    handler's child that failed by design (a ForceFailure or an Inverter over a
    success), which is skipped as a guard is."""
    if node is None:
        return NOTHING_WRONG, None
    goal = goal_words(tree) if tree is not None else None
    child, ancestor = node, node.parent
    while ancestor is not None and ancestor.kind != SUBTREE:
        handler = handler_of(ancestor)
        if handler is not None:
            first = handler.falls_back_from(ancestor)
            found = (
                None
                if first is None
                else _fallback_sentence(ancestor, first, state, goal, designed)
            )
            if first is not None and found is not None:
                attempts = (
                    _retry_attempt(a, state, goal, designed) for a in _retrying(ancestor, child)
                )
                retries = [r for r in attempts if r]
                if retries or not _retried_since(ancestor, first, state):
                    return " ".join([*retries, found[0]]), found[1]
            if handler.retried(ancestor) is not None and first is None:
                retried = _retry_sentence(ancestor, state, goal, designed)
                if retried is not None:
                    return retried
        child, ancestor = ancestor, ancestor.parent
    return NOTHING_WRONG, None


def _retried_since(handler: Node, first: Node, state: State) -> bool:
    """True when ``handler`` retries the child it fell back from (a RecoveryNode) and that
    child ran again after its failure: the failure was handled, and once the handler's
    retry is over (it completed) nothing is wrong any more."""
    rule = handler_of(handler)
    if rule is None or rule.retried(handler) is not first:
        return False
    return state.activation.get(first.uid, -1) > state.last_failure.get(first.uid, -1)


def what_went_wrong(node: Node | None, state: State, tree: Tree | None = None) -> str:
    """Q6 for one current node (Algorithm 7): the text of ``diagnose``."""
    return diagnose(node, state, tree)[0]


def _retrying(node: Node, via: Node) -> Iterator[Node]:
    """The retrying handlers from ``node`` up to the subgoal, reached from ``node``'s child
    ``via``: each handler that retries the child it was reached through."""
    current: Node | None = node
    while current is not None and current.kind != SUBTREE:
        handler = handler_of(current)
        if handler is not None and handler.retried(current) is via:
            yield current
        via, current = current, current.parent

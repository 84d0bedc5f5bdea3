"""Causes over a run's history: why a node completed as it did, and Q6 over the history.

**The causal chain.** A control node or decorator completes because one of its children
completed: the one whose completion came last in the parent's activation (a Sequence
fails when a child fails, a Fallback when its last child fails, a retry when its last
attempt fails, an Inverter fails when its child succeeds). From a completion, following
that child down, in event order, to an execution node gives the *cause*: the leaf whose
result decided it. It is ``succeeded`` rather than ``failed`` when the leaf's SUCCESS
was turned into a failure on the way up (an Inverter, a ForceFailure). One exception: a
fallback whose last alternative failed only by design (a clean-up under ForceFailure,
like the kitting tree's "reset arm") failed because of the failure it fell back from,
so the chain follows its first child's failure instead.

**By design.** Not every failure is something gone wrong: a *guard* (a condition that
fails in front of the branch it guards, before any action of the branch started; see
``btlog.explain.failure``) is the tree choosing a branch, and a failure *made* from a
success (a ForceFailure clean-up, an Inverter over a check) is the tree's own doing.
``by_design`` is that test over the history; the run's story leaves such failures out of
its episodes and the fleet's causes mark them, so neither blames them for what went wrong.

**What went wrong? (Q6) over the history.** When Algorithm 7 has something to say at
the moment, that is the answer (word for word the paper's). Otherwise, after the root
completed with FAILURE: ``I could not {d(root)} because {d(leaf)} failed.`` Otherwise,
when Algorithm 7 had something to say earlier: ``At {t} s: {what it said then}`` for the
last failure episode it spoke of — ``t`` the time its leaf failed, the sentence Q6's
right after the failure, exactly as the run's story tells that episode. Only when there
is none: ``Nothing went wrong.``

The last such moment is found without a replay. Algorithm 7 speaks only while a
failure handler (``btlog.explain.handlers``) above the current node, within its
subgoal, holds a failure of one of its children: a *window* that opens with the child's
FAILURE and closes when the handler starts again (a fallback) or completes (a retry).
For each handler, its last window before the moment that a real failure (not a guard's)
opened is read from the history, and in it the last moment the current node was inside
the handler's branch; Algorithm 7 is then run on the state at that moment, which both
checks the candidate and gives the words. Each handler's last such window is looked at
(not earlier ones of the same handler).
"""

from __future__ import annotations

from btlog.explain.failure import NOTHING_WRONG, decided_by_guard, diagnose, spoken
from btlog.explain.grounds import grounded, grounds
from btlog.explain.handlers import FallbackHandler, handler_of
from btlog.explain.hierarchy import current_nodes, per_node
from btlog.explain.words import goal_words, is_named, seconds, words
from btlog.history import ANY_STATUS, COMPLETIONS, History, Transition
from btlog.state import State
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS
from btlog.tree.model import ACTION, SUBTREE, Node, Tree

#: How many earlier failures of one handler's children are looked at for one that was
#: not a guard's (Q6 over the history).
GUARD_LOOKBACK = 64

#: Statuses that make a node the current one (resets to IDLE do not).
ACTIVE = (RUNNING, SUCCESS, FAILURE)


def algorithm7(tree: Tree, state: State, history: History | None = None) -> str:
    """Algorithm 7 at the moment ``state``, for every current node; with the run's
    ``history``, each blamed leaf's failure is grounded (``btlog.explain.grounds``)."""
    return _algorithm7(tree, state, history)[0]


def _algorithm7(tree: Tree, state: State, history: History | None) -> tuple[str, list[Node]]:
    """``algorithm7``'s answer and the leaves it blames."""
    blamed: list[Node] = []

    def render(node: Node) -> str:
        text, leaf = diagnose_over_history(node, tree, state, history)
        if leaf is not None:
            blamed.append(leaf)
        return text

    return per_node(current_nodes(tree, state), render, NOTHING_WRONG), blamed


def diagnose_over_history(
    node: Node | None, tree: Tree, state: State, history: History | None
) -> tuple[str, Node | None]:
    """Algorithm 7 for one current node (``diagnose``) with the run's history: a handler's
    child that failed by design (``by_design``) is skipped as a guard is, and the blamed
    leaf's failure is grounded (``btlog.explain.grounds``), and, when the chain
    stopped at a decorator or control that failed with no execution node failing below
    it (an Inverter over a success), told by what decided it (``… because {check}
    succeeded.``)."""
    if history is None:
        return diagnose(node, state, tree)

    def designed(child: Node) -> bool:
        failed = history.last([child.uid], (FAILURE,), 0, state.seq)
        return failed is not None and by_design(tree, child, failed, history)

    text, leaf = diagnose(node, state, tree, designed)
    if leaf is None:
        return text, leaf
    if not leaf.is_execution:
        failed = history.last([leaf.uid], (FAILURE,), 0, state.seq)
        tail = f"{words(leaf)} failed."
        if failed is not None and text.endswith(tail):
            return f"{text[: -len(tail)]}{because(tree, leaf, failed, history)}.", leaf
    return grounded(text, tree, leaf, state.seq, history), leaf


def activation_start(node: Node, before: int, history: History, lo: int = 0) -> int:
    """Where the node's last activation before event ``before`` begins in the events
    (``lo`` when it has none since ``lo``): its start out of IDLE, or, when that start
    is its result (a node that completes in the tick it started logs only its result,
    after its children's changes), right after its previous change."""
    start = history.last([node.uid], ANY_STATUS, lo, before, starts=True)
    if start is None:
        return lo
    if start.status in COMPLETIONS:
        previous = history.last([node.uid], ANY_STATUS, lo, start.seq)
        return lo if previous is None else previous.seq + 1
    return start.seq


def cause(tree: Tree, node: Node, completion: Transition, history: History) -> Transition:
    """The completion of the execution node that caused ``completion`` of ``node`` (the
    causal chain, see the module docstring); ``completion`` itself for a leaf, or when no
    child completed in the activation (e.g. a Timeout halted it)."""
    lo = 0
    while node.children:
        lo = activation_start(node, completion.seq + 1, history, lo)
        uids = [c.uid for c in node.children]
        child = history.last(uids, COMPLETIONS, lo, completion.seq)
        if child is None:
            child, lo = _still_completed(uids, lo, completion.seq, history), 0
        if child is None or child.uid not in tree.nodes:
            break
        if completion.status is FAILURE and isinstance(handler_of(node), FallbackHandler):
            child = _original_failure(tree, node, child, lo, history)
        node, completion = tree.node(child.uid), child
    return completion


def _still_completed(uids: list[int], lo: int, hi: int, history: History) -> Transition | None:
    """The child that completed before event ``lo`` and has not changed since, up to
    ``hi``: ticked again, it returned the same result, which changes nothing and is not
    logged (an IfThenElse's condition failing on every tick); None when there is none."""
    earlier = history.last(uids, COMPLETIONS, 0, lo)
    if earlier is None or history.last([earlier.uid], ANY_STATUS, earlier.seq + 1, hi):
        return None
    return earlier


def _original_failure(
    tree: Tree, fallback: Node, last: Transition, lo: int, history: History
) -> Transition:
    """A fallback failed because its last alternative failed; when that alternative
    failed only by design (its cause *succeeded*: a ForceFailure clean-up), the failure
    it was the alternative to — the first child's — is the cause."""
    if cause(tree, tree.node(last.uid), last, history).status is not SUCCESS:
        return last
    first = history.last([fallback.children[0].uid], (FAILURE,), lo, last.seq)
    return last if first is None else first


def actions_below(node: Node) -> list[int]:
    """The uids of the action nodes in ``node``'s branch."""
    return [n.uid for n in node.walk() if n.kind == ACTION]


def by_guard(tree: Tree, node: Node, failed: Transition, history: History) -> bool:
    """True when ``node``'s FAILURE ``failed`` was a guard's
    (``btlog.explain.failure.decided_by_guard``, its facts read from the history)."""
    actions = actions_below(node)
    if not actions:
        return True  # only conditions or scripts below: nothing else can have decided
    began = activation_start(node, failed.seq + 1, history)
    started = history.first(actions, ANY_STATUS, began, failed.seq + 1, starts=True)
    broke = history.first(actions, (FAILURE,), began, failed.seq + 1)
    leaf = tree.nodes.get(cause(tree, node, failed, history).uid)
    return decided_by_guard(node, leaf, started is not None, broke is not None)


def by_design(tree: Tree, node: Node, failed: Transition, history: History) -> bool:
    """True when ``node``'s FAILURE ``failed`` is the tree's own doing (see the module
    docstring): a guard's, or made from a success."""
    return (
        by_guard(tree, node, failed, history)
        or cause(tree, node, failed, history).status is SUCCESS
    )


#: The precondition that makes a node return each result without running its children.
_DECIDING_PRECONDITION = {FAILURE: "_failureIf", SUCCESS: "_successIf"}


def because(tree: Tree, node: Node, completion: Transition, history: History) -> str:
    """``{d(leaf)} failed`` (or ``succeeded``) for the cause of ``completion``; when the
    cause is an unnamed control or decorator that decided by its own precondition (no
    child completed), the precondition: ``the precondition _failureIf="x < 2" held``."""
    leaf = cause(tree, node, completion, history)
    culprit = tree.node(leaf.uid)
    if not culprit.is_execution and not is_named(culprit):
        attribute = _DECIDING_PRECONDITION.get(leaf.status, "")
        script = culprit.attributes.get(attribute)
        if script:
            return f'the precondition {attribute}="{script}" held'
    if leaf.status is SUCCESS:
        return f"{words(culprit)} succeeded"
    return f"{words(culprit)} failed{grounds(tree, culprit, leaf, history)}"


def last_completion(node: Node, state: State, history: History) -> Transition | None:
    """The node's last completion at or before the moment, if it has not started since."""
    done = history.last([node.uid], COMPLETIONS, 0, state.seq)
    if done is None or history.last([node.uid], ANY_STATUS, done.seq + 1, state.seq, True):
        return None
    return done


def root_failure(tree: Tree, state: State, history: History) -> str | None:
    """``I could not {d(root)} because …`` when the root's last result was FAILURE."""
    done = last_completion(tree.root, state, history)
    if done is None or done.status is not FAILURE:
        return None
    return f"I could not {goal_words(tree)} because {because(tree, tree.root, done, history)}."


def _scope(handler: Node) -> list[int]:
    """The execution nodes from which Algorithm 7's walk reaches ``handler`` (its
    descendants, not crossing a SubTree)."""
    found: list[int] = []
    stack = list(handler.children)
    while stack:
        node = stack.pop()
        if node.is_execution:
            found.append(node.uid)
        elif node.kind != SUBTREE:
            stack.extend(node.children)
    return found


def _window_end(handler: Node, failed: Transition, now: int, history: History) -> int:
    """The moment (a count of events) just before the handler's window closes, or now."""
    rule = handler_of(handler)
    assert rule is not None
    if rule.lasts_until_restart:
        close = history.first([handler.uid], ANY_STATUS, failed.seq + 1, now, starts=True)
    else:
        close = history.first([handler.uid], (SUCCESS, FAILURE, IDLE), failed.seq + 1, now)
    return now if close is None else close.seq


def _candidate(
    handler: Node, failed: Transition, end: int, leaves: list[int], history: History
) -> int | None:
    """The last moment in the window (after ``failed``, up to ``end``) at which the
    current node was inside the handler's branch."""
    scope = _scope(handler)
    last_leaf = history.last(leaves, ACTIVE, 0, end)
    if last_leaf is None:
        return None
    if last_leaf.uid in scope:
        return end
    inside = history.last(scope, ACTIVE, 0, end)
    if inside is None:
        return None
    leaving = history.first(leaves, ACTIVE, inside.seq + 1, end)
    moment = end if leaving is None else leaving.seq
    return moment if moment > failed.seq else None


def earlier_wrong(tree: Tree, state: State, history: History) -> tuple[int, str] | None:
    """(time, sentence) of the failure episode Algorithm 7 last spoke of before
    ``state``: the time its leaf failed and what Q6 said then (``episode_sentence``),
    as the run's story tells that episode."""
    now = state.seq
    handlers = tree.shaped("handlers", lambda: [n for n in tree if handler_of(n) is not None])
    windows = []
    for handler in handlers:
        failed = _last_real_failure(tree, handler, now, history)
        if failed is not None:
            windows.append((failed.seq, handler, failed))
    leaves = tree.shaped("leaf uids", lambda: [n.uid for n in tree if n.is_execution])
    best: tuple[int, Transition] | None = None
    for _, handler, failed in sorted(windows, key=lambda w: w[0], reverse=True):
        end = _window_end(handler, failed, now, history)
        if best is not None and end <= best[0]:
            continue
        moment = _candidate(handler, failed, end, leaves, history)
        if moment is None or (best is not None and moment <= best[0]):
            continue
        then_tree, then = history.state_after(moment)
        if algorithm7(then_tree, then, history) != NOTHING_WRONG:
            best = (moment, failed)
    if best is None:
        return None
    failed = best[1]
    leaf_done = cause(tree, tree.node(failed.uid), failed, history)
    leaf = tree.node(leaf_done.uid)
    seen = _first_handled(leaf, leaf_done, now, history) or failed
    return leaf_done.t_ns, episode_sentence(tree, seen, leaf, history)


def _first_handled(
    leaf: Node, leaf_done: Transition, now: int, history: History
) -> Transition | None:
    """The failure, caused by ``leaf_done``, that the innermost failure handler above the
    leaf saw: where the run's story tells the episode from."""
    child = leaf
    for ancestor in leaf.ancestors():
        if handler_of(ancestor) is not None:
            seen = history.first([child.uid], (FAILURE,), leaf_done.seq, now)
            if seen is not None:
                return seen
        child = ancestor
    return None


def episode_sentence(tree: Tree, failed: Transition, leaf: Node, history: History) -> str:
    """What went wrong in a failure episode: Q6 about the failed ``leaf`` right after
    its handler saw the failure ``failed`` of its child (Algorithm 7, grounded), or the
    cause when Algorithm 7 is silent. The run's story tells each episode so, and "What
    went wrong?" after the fact tells the last one so."""
    then_tree, then = history.state_after(failed.seq + 1)
    text, _blamed = diagnose_over_history(then_tree.nodes.get(leaf.uid), then_tree, then, history)
    if text != NOTHING_WRONG:
        return text
    done = history.last([leaf.uid], (FAILURE,), 0, failed.seq + 1)
    reason = "" if done is None else grounds(tree, leaf, done, history)
    return could_not(tree, tree.node(failed.uid), leaf, reason)


def could_not(tree: Tree, node: Node, leaf: Node, reason: str = "") -> str:
    """``I could not {node} because {leaf} failed{reason}.``: ``node`` as spoken (the goal
    for the root), ``reason`` the leaf's grounds. An episode Algorithm 7 is silent about
    is told so, and the run's story names each kind of failure so."""
    goal = goal_words(tree)
    what = goal if node is tree.root else spoken(node, goal)
    return f"I could not {what} because {words(leaf)} failed{reason}."


def _last_real_failure(tree: Tree, handler: Node, now: int, history: History) -> Transition | None:
    """The last failure of one of ``handler``'s children before event ``now`` that was
    not by design (at most ``GUARD_LOOKBACK`` failures back)."""
    children = [c.uid for c in handler.children if actions_below(c)]
    hi = now
    for _ in range(GUARD_LOOKBACK):
        failed = history.last(children, (FAILURE,), 0, hi)
        if failed is None:
            return None
        if not by_design(tree, tree.node(failed.uid), failed, history):
            return failed
        hi = failed.seq
    return None


def what_went_wrong_over_history(tree: Tree, state: State, history: History | None) -> str:
    """Q6: Algorithm 7 now; else the root's failure; else Algorithm 7's last answer."""
    now = algorithm7(tree, state, history)
    if now != NOTHING_WRONG or history is None:
        return now
    failed = root_failure(tree, state, history)
    if failed is not None:
        return failed
    earlier = earlier_wrong(tree, state, history)
    if earlier is not None:
        return f"At {seconds(earlier[0])} s: {earlier[1]}"
    return NOTHING_WRONG

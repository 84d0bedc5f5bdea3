"""What will you do next? The control flow of BehaviorTree.CPP, read forward.

``after(node, status)`` answers: if ``node`` completed now with ``status``, which
execution nodes would be ticked next? The completion travels up the tree: each parent
either ticks another child (its *entry*: the execution nodes a fresh tick of it reaches
first — every child's under a Parallel) or completes in turn, with a status of its own.
Each control or decorator type has one rule (``FLOW``; types without one behave as a
Sequence when they are controls and pass the status through when decorators), so a new
node type is one entry. ``None`` means the root completes: the tree is finished.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from btlog.explain.handlers import attempts_of
from btlog.explain.words import act, goal_words
from btlog.history import History
from btlog.state import State
from btlog.status import FAILURE, RUNNING, SUCCESS, Status
from btlog.tree.model import CONTROL, Node, Tree, blackboard_key
from btlog.tree.ports import split_queue

#: A rule's result: execution nodes ticked next, or the parent's own completion status.
Step = list[Node] | Status


class Now(NamedTuple):
    """The moment a rule looks at: its state and the history up to it."""

    state: State
    history: History | None


Rule = Callable[[Node, Node, Status, Now], Step]


def entry(node: Node, state: State) -> list[Node]:
    """The execution nodes a fresh tick of ``node`` reaches first."""
    if node.is_execution or not node.children:
        return [node]
    if node.type in ("Parallel", "ParallelAll"):
        return [leaf for child in node.children for leaf in entry(child, state)]
    if node.type.startswith("Switch"):
        return entry(node.children[_switch_case(node, state)], state)
    return entry(node.children[0], state)


def _switch_case(node: Node, state: State) -> int:
    """The child a Switch would tick, from the blackboard (the default when unknown)."""
    default = len(node.children) - 1
    port = node.ports.get("variable")
    key = blackboard_key(port.value) if port is not None else None
    value = state.blackboard.get(node.scope, {}).get(key) if key else None
    if value is None:
        return default
    for index in range(default):
        case = node.ports.get(f"case_{index + 1}")
        if case is not None and case.value == str(value):
            return index
    return default


def _in_order(on: Status) -> Rule:
    """Sequence (``on`` SUCCESS) and Fallback (``on`` FAILURE): the next child on ``on``,
    else the child's status is the parent's."""

    def rule(parent: Node, child: Node, status: Status, now: Now) -> Step:
        index = parent.children.index(child)
        if status is on and index + 1 < len(parent.children):
            return entry(parent.children[index + 1], now.state)
        return status

    return rule


def _parallel(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """The others still running go on; when none is, the Parallel completes."""
    others = [
        leaf
        for other in parent.children
        if other is not child
        for leaf in other.walk()
        if leaf.is_execution and now.state.status_of(leaf.uid) is RUNNING
    ]
    return others or status


def _if_then_else(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """The condition chooses a branch; a branch's result is the node's."""
    if parent.children.index(child) != 0:
        return status
    if status is SUCCESS:
        return entry(parent.children[1], now.state)
    return entry(parent.children[2], now.state) if len(parent.children) == 3 else FAILURE


def _retry(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """A failure is retried while attempts are left."""
    if status is SUCCESS:
        return SUCCESS
    limit = attempts_of(parent, "num_attempts")
    if limit is None or now.state.retry_attempts.get(parent.uid, 0) + 1 < limit:
        return entry(child, now.state)
    return FAILURE


def _repeat(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """A success is repeated ``num_cycles`` times."""
    if status is FAILURE:
        return FAILURE
    limit = attempts_of(parent, "num_cycles")
    if limit is None:
        return entry(child, now.state)
    done = _successes_in_activation(parent, child, now)
    return entry(child, now.state) if done + 1 < limit else SUCCESS


def _constant(result: Status) -> Rule:
    """ForceSuccess, ForceFailure: always ``result``."""

    def rule(parent: Node, child: Node, status: Status, now: Now) -> Step:
        return result

    return rule


def _through(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """Decorators and SubTrees without a rule: the child's status is theirs."""
    return status


def _inverter(parent: Node, child: Node, status: Status, now: Now) -> Step:
    return FAILURE if status is SUCCESS else SUCCESS


def _until_failure(parent: Node, child: Node, status: Status, now: Now) -> Step:
    return entry(child, now.state) if status is SUCCESS else FAILURE


_SEQUENCE = _in_order(SUCCESS)


def _try_catch(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """TryCatch: the try children as a Sequence; a failure runs the catch (the last
    child), after which the node fails."""
    catch = parent.children[-1]
    if child is catch:
        return FAILURE
    if status is FAILURE:
        return entry(catch, now.state)
    index = parent.children.index(child)
    return (
        entry(parent.children[index + 1], now.state) if index + 2 < len(parent.children) else status
    )


def _loop(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """LoopInt/Double/String/Bool: the child runs once per element of the queue (a
    literal, or a list or string entry), then the node returns ``if_empty``."""
    if status is FAILURE:
        return FAILURE
    port = parent.ports.get("queue")
    queue: object = port.value if port is not None else ""
    key = blackboard_key(port.value) if port is not None else None
    if key is not None:
        queue = now.state.blackboard.get(parent.scope, {}).get(key)
    if isinstance(queue, str):
        queue = split_queue(queue)
    if not isinstance(queue, list):
        return entry(child, now.state)
    done = _successes_in_activation(parent, child, now)
    if done + 1 < len(queue):
        return entry(child, now.state)
    empty = parent.ports.get("if_empty")
    return FAILURE if empty is not None and empty.value.strip().upper() == "FAILURE" else SUCCESS


def _successes_in_activation(parent: Node, child: Node, now: Now) -> int:
    """How many times ``child`` succeeded since ``parent`` last started."""
    if now.history is None:
        return 0
    seq = now.state.seq
    start = now.history.last([parent.uid], tuple(Status), 0, seq, starts=True)
    return now.history.count([child.uid], (SUCCESS,), 0 if start is None else start.seq, seq)


def _recovery(parent: Node, child: Node, status: Status, now: Now) -> Step:
    """Nav2's RecoveryNode: the first child's failure runs the recovery, whose success
    runs the first child again."""
    first = parent.children[0]
    if child is first:
        return status if status is SUCCESS else entry(parent.children[-1], now.state)
    return entry(first, now.state) if status is SUCCESS else FAILURE


FLOW: dict[str, Rule] = {
    "Sequence": _SEQUENCE,
    "AsyncSequence": _SEQUENCE,
    "SequenceWithMemory": _in_order(SUCCESS),
    "ReactiveSequence": _in_order(SUCCESS),
    "Fallback": _in_order(FAILURE),
    "AsyncFallback": _in_order(FAILURE),
    "ReactiveFallback": _in_order(FAILURE),
    "TryCatch": _try_catch,
    **{f"Loop{item}": _loop for item in ("Int", "Double", "String", "Bool")},
    "Parallel": _parallel,
    "ParallelAll": _parallel,
    "IfThenElse": _if_then_else,
    "WhileDoElse": _if_then_else,
    "RetryUntilSuccessful": _retry,
    "Repeat": _repeat,
    "KeepRunningUntilFailure": _until_failure,
    "Inverter": _inverter,
    "ForceSuccess": _constant(SUCCESS),
    "ForceFailure": _constant(FAILURE),
    "RecoveryNode": _recovery,
}


def after(node: Node, status: Status, state: State, history: History | None) -> list[Node] | None:
    """The execution nodes ticked next if ``node`` completes with ``status`` now; None
    when the root would complete."""
    while node.parent is not None:
        parent = node.parent
        rule = FLOW.get(parent.type) or (_SEQUENCE if parent.kind == CONTROL else _through)
        step = rule(parent, node, status, Now(state, history))
        if isinstance(step, list):
            return step
        node, status = parent, step
    return None


def next_sentence(tree: Tree, node: Node, state: State, history: History | None) -> str:
    """``After I {d(current)}, I will {d(next)}.`` (or ``… I will have finished …``)."""
    following = after(node, SUCCESS, state, history)
    if following is None:
        return f"After I {act(node)}, I will have finished {goal_words(tree)}."
    names = list(dict.fromkeys(act(n) for n in following))
    return f"After I {act(node)}, I will {' and '.join(names)}."

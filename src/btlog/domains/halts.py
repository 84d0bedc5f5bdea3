"""Why a simulated run did not finish: livelocks, and loops that end only on a failure.

With scripted leaves a tree can go round in circles that a real robot would not: under a
ReactiveSequence, a scripted action placed where BT.CPP programs put a condition (that
answers at once) is RUNNING on every tick, so the reactive control halts the child after
it each time, and that child never gets to finish; the run then ends at ``--max-ticks``
with "No failures" to tell. Each scripted leaf counts its halts since it last finished;
when it is halted, the node that caused it is looked up (the nearest ancestor with another
child RUNNING, and the execution node RUNNING in that child). After the run, a leaf halted
``HALTS_WORTH_A_WARNING`` times or more in a row gets one warning naming both and the hint
that fits. A run stopped by ``--max-ticks`` inside a loop that only a failure (or a
success) ends — KeepRunningUntilFailure, Repeat or RetryUntilSuccessful without a limit —
says so too: with scripted leaves that always succeed, it never ends.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from btlog.executor.behavior import Behavior
from btlog.status import RUNNING
from btlog.tree.model import CONDITION, Node

#: Halts in a row, without finishing in between, that make a warning.
HALTS_WORTH_A_WARNING = 100


@dataclass(frozen=True)
class HaltCause:
    """What halted a leaf: ``control``, whose other child ``running`` (an execution node,
    or the child itself when none is) was RUNNING; or just the ancestor that halted it."""

    control: Node | None
    running: Node | None


def find_halt_cause(node: Node, behaviors: Mapping[int, Behavior]) -> HaltCause:
    """The nearest ancestor of ``node`` with another child RUNNING while ``node`` is halted,
    and the RUNNING execution node in that child."""
    child = node
    for ancestor in node.ancestors():
        for other in ancestor.children:
            behavior = behaviors.get(other.uid)
            if other is child or behavior is None or behavior.status is not RUNNING:
                continue
            running = next(
                (
                    n
                    for n in other.walk()
                    if n.is_execution
                    and (b := behaviors.get(n.uid)) is not None
                    and b.status is RUNNING
                ),
                other,
            )
            return HaltCause(ancestor, running)
        child = ancestor
    return HaltCause(node.parent, None)


@dataclass
class HaltCount:
    """One leaf's halts: in a row now, the longest streak that ended in a finish, and
    the cause of the last halt."""

    in_a_row: int = 0
    longest_finished: int = 0
    cause: HaltCause | None = None

    def halted(self, cause: HaltCause | None) -> None:
        """Count a halt while RUNNING."""
        self.in_a_row += 1
        self.cause = cause

    def finished(self) -> None:
        """The leaf completed: the streak ends."""
        self.longest_finished = max(self.longest_finished, self.in_a_row)
        self.in_a_row = 0


def halt_warning(node: Node, count: HaltCount, scripted: Mapping[int, bool]) -> str | None:
    """The warning for a leaf halted too often in a row (None when it was not);
    ``scripted`` tells, by uid, the scripted leaves that take RUNNING time."""
    if max(count.in_a_row, count.longest_finished) < HALTS_WORTH_A_WARNING:
        return None
    if count.in_a_row >= HALTS_WORTH_A_WARNING:
        story = f"was halted {count.in_a_row} times in a row and never finished"
    else:
        story = f"was halted {count.longest_finished} times before it finished"
    return f"{node.description!r} {story}: {_hint(node, count.cause, scripted)}"


def _hint(node: Node, cause: HaltCause | None, scripted: Mapping[int, bool]) -> str:
    if cause is None or cause.control is None:
        return "a node above it halts it on every tick"
    control = f"{cause.control.type} {cause.control.description!r}"
    if cause.running is None:
        return f"{control} halts it each time (its own policy, e.g. a timeout)"
    running = cause.running
    said = (
        f"{control} ticks {running.description!r}, which is RUNNING, and halts {node.description!r}"
    )
    if running.is_execution and scripted.get(running.uid):
        what = "condition" if running.kind == CONDITION else "action"
        return (
            f"{said}; {running.description!r} is a scripted {what} that takes time, where a "
            "reactive control expects one that answers in its tick (a condition, or a "
            "synchronous action): give it duration 0 in the outcomes file, or declare it a "
            "condition (--nodes-model)"
        )
    return f"{said} every time, before {node.description!r} can finish"


#: Loops that end only when their child fails (or succeeds), with what ends them.
ENDLESS: dict[str, tuple[str | None, str]] = {
    "KeepRunningUntilFailure": (None, "its child fails"),
    "Repeat": ("num_cycles", "its child fails"),
    "RetryUntilSuccessful": ("num_attempts", "its child succeeds"),
}


def endless_loop_warnings(behaviors: Mapping[int, Behavior]) -> list[str]:
    """For a run stopped while RUNNING: the outermost unbounded loops still running, each
    with what would end it."""
    warnings = []
    for behavior in behaviors.values():
        node = behavior.node
        rule = ENDLESS.get(node.type)
        if rule is None or behavior.status is not RUNNING:
            continue
        port, ends = rule
        if port is not None:
            limit = node.ports.get(port)
            if limit is None or limit.value.strip() != "-1":
                continue
        outer = [a for a in node.ancestors() if a.type in ENDLESS]
        if any(behaviors[a.uid].status is RUNNING for a in outer if a.uid in behaviors):
            continue
        warnings.append(
            f"{node.type} {node.description!r} was still looping: it ends only when {ends} "
            "(script that result in the outcomes file to end the run)"
        )
    return warnings

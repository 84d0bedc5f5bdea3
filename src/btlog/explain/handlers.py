"""Failure handlers: the node types that react to a child's failure, and how.

This is the extension point for new control and decorator types that handle failures
(Nav2's RecoveryNode, for one): register a ``FailureHandler`` under the node's type and
the run's story says how each failure was handled, and Q6 over the history looks for
"what went wrong" in its branch. A handler answers one question: *this child of mine
has just failed for the k-th time in my current activation — what do I do?* It
retries (attempt k + 1 of n), falls back to another child, or lets the failure
propagate to its parent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from btlog.explain.words import first_named, words
from btlog.tree.model import Node

RETRIED = "retried"
FELL_BACK = "fell back"
PROPAGATED = "propagated"


@dataclass(frozen=True)
class Reaction:
    """What a handler did about a child's failure: ``kind`` is ``RETRIED`` (``attempt``
    of ``retries``, None when unlimited), ``FELL_BACK`` (to ``target``) or
    ``PROPAGATED`` (the handler failed too, after ``retries`` retries for a retry).

    An *attempt* is counted as the paper counts it ("I am retrying for attempt 1"): the
    k-th retry, after k failures in the handler's current activation; a
    RetryUntilSuccessful with ``num_attempts="3"`` has 2 retries, attempts 1 and 2."""

    kind: str
    target: Node | None = None
    attempt: int | None = None
    retries: int | None = None

    def text(self) -> str:
        """E.g. ``retried (attempt 1 of 2)``, ``fell back to ask``, ``propagated``."""
        if self.kind == RETRIED:
            of = "" if self.retries is None else f" of {self.retries}"
            return f"retried (attempt {self.attempt}{of})"
        if self.kind == FELL_BACK and self.target is not None:
            return f"fell back to {words(first_named(self.target))}"
        if self.retries is not None:
            return f"gave up after {self.retries} {'retry' if self.retries == 1 else 'retries'}"
        return "no alternative left"


class FailureHandler(Protocol):
    """How one node type reacts to a child's failure."""

    #: True when the "something went wrong" of a failure lasts until the handler starts
    #: again (a fallback); False when it ends with the handler's own result (a retry).
    lasts_until_restart: bool

    def falls_back_from(self, node: Node) -> Node | None:
        """The child whose failure makes ``node`` fall back to another (Algorithm 7's
        Fallback case), or None when ``node`` never falls back."""
        ...

    def retried(self, node: Node) -> Node | None:
        """The child ``node`` ticks again after it failed (Algorithm 7's Retry case), or
        None when ``node`` does not retry."""
        ...

    def react(self, node: Node, child: Node, failures: int) -> Reaction:
        """``child`` of ``node`` failed, the ``failures``-th time in ``node``'s current
        activation: the reaction."""
        ...


class FallbackHandler:
    """Fallback, ReactiveFallback: the next child is tried; after the last, it fails."""

    lasts_until_restart = True

    def falls_back_from(self, node: Node) -> Node | None:
        """The first child."""
        return node.children[0]

    def retried(self, node: Node) -> Node | None:
        """None: a fallback does not retry."""
        return None

    def react(self, node: Node, child: Node, failures: int) -> Reaction:
        """Fall back to the next child, or propagate after the last one."""
        index = node.children.index(child)
        if index + 1 < len(node.children):
            return Reaction(FELL_BACK, node.children[index + 1])
        return Reaction(PROPAGATED)


class RetryHandler:
    """RetryUntilSuccessful: the child is ticked again, ``num_attempts`` times in all."""

    lasts_until_restart = False

    def __init__(self, port: str = "num_attempts") -> None:
        self.port = port

    def falls_back_from(self, node: Node) -> Node | None:
        """None: a retry has nothing to fall back to."""
        return None

    def retried(self, node: Node) -> Node | None:
        """Its one child."""
        return node.children[0]

    def react(self, node: Node, child: Node, failures: int) -> Reaction:
        """Retry while attempts are left (-1: forever), else propagate."""
        attempts = attempts_of(node, self.port)
        retries = None if attempts is None else max(attempts - 1, 0)
        if retries is None or failures <= retries:
            return Reaction(RETRIED, child, failures, retries)
        return Reaction(PROPAGATED, retries=retries)


class RecoveryHandler(FallbackHandler):
    """Nav2's RecoveryNode: a failure of the first child runs the recovery (the second
    child), whose success retries the first, ``number_of_retries`` times at most. Once
    the retried child ran again, what went wrong is over when the node completes, as for
    a retry."""

    lasts_until_restart = False

    def retried(self, node: Node) -> Node | None:
        """The first child, retried after a successful recovery."""
        return node.children[0]

    def react(self, node: Node, child: Node, failures: int) -> Reaction:
        """Fall back to the recovery while retries are left, else propagate."""
        retries = attempts_of(node, "number_of_retries", default=1)
        if child is node.children[0] and (retries is None or failures <= retries):
            return Reaction(FELL_BACK, node.children[-1])
        return Reaction(PROPAGATED)


def attempts_of(node: Node, port: str, default: int | None = None) -> int | None:
    """The node's attempt limit from ``port`` (None: unlimited or not a plain number;
    ``default`` when the port is not given)."""
    port_value = node.ports.get(port)
    if port_value is None:
        return default
    try:
        value = int(port_value.value)
    except ValueError:
        return None
    return None if value < 0 else value


class TryCatchHandler(FallbackHandler):
    """TryCatch: a failure in the try block runs the catch (the last child); then the
    node fails, whatever the catch did."""

    def react(self, node: Node, child: Node, failures: int) -> Reaction:
        """Fall back to the catch, or propagate when the catch itself failed."""
        catch = node.children[-1]
        return Reaction(PROPAGATED) if child is catch else Reaction(FELL_BACK, catch)


HANDLERS: dict[str, FailureHandler] = {
    "Fallback": FallbackHandler(),
    "AsyncFallback": FallbackHandler(),
    "ReactiveFallback": FallbackHandler(),
    "TryCatch": TryCatchHandler(),
    "RetryUntilSuccessful": RetryHandler(),
    "RecoveryNode": RecoveryHandler(),
}


def register_handler(type_name: str, handler: FailureHandler) -> None:
    """Treat nodes of ``type_name`` as failure handlers (see the module docstring)."""
    HANDLERS[type_name] = handler


def handler_of(node: Node) -> FailureHandler | None:
    """The node's failure handler, if its type has one."""
    return HANDLERS.get(node.type) if node.children else None

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

from btlog.tree.model import Node

RETRIED = "retried"
FELL_BACK = "fell back"
PROPAGATED = "propagated"


@dataclass(frozen=True)
class Reaction:
    """What a handler did about a child's failure: ``kind`` is ``RETRIED`` (``attempt``
    of ``attempts``, None when unlimited), ``FELL_BACK`` (to ``target``) or
    ``PROPAGATED`` (the handler failed too, after ``attempts`` attempts for a retry)."""

    kind: str
    target: Node | None = None
    attempt: int | None = None
    attempts: int | None = None

    def text(self) -> str:
        """E.g. ``retried (attempt 2 of 3)``, ``fell back to ask``, ``propagated``."""
        if self.kind == RETRIED:
            of = "" if self.attempts is None else f" of {self.attempts}"
            return f"retried (attempt {self.attempt}{of})"
        if self.kind == FELL_BACK and self.target is not None:
            return f"fell back to {self.target.description}"
        if self.attempts is not None:
            return f"gave up after {self.attempts} attempts"
        return "no alternative left"


class FailureHandler(Protocol):
    """How one node type reacts to a child's failure."""

    #: True when the "something went wrong" of a failure lasts until the handler starts
    #: again (a fallback); False when it ends with the handler's own result (a retry).
    lasts_until_restart: bool

    def react(self, node: Node, child: Node, failures: int) -> Reaction:
        """``child`` of ``node`` failed, the ``failures``-th time in ``node``'s current
        activation: the reaction."""
        ...


class FallbackHandler:
    """Fallback, ReactiveFallback: the next child is tried; after the last, it fails."""

    lasts_until_restart = True

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

    def react(self, node: Node, child: Node, failures: int) -> Reaction:
        """Retry while attempts are left (-1: forever), else propagate."""
        attempts = attempts_of(node, self.port)
        if attempts is None or failures < attempts:
            return Reaction(RETRIED, child, failures + 1, attempts)
        return Reaction(PROPAGATED, attempts=attempts)


class RecoveryHandler(FallbackHandler):
    """Nav2's RecoveryNode: a failure of the first child runs the recovery (the second
    child), whose success retries the first, ``number_of_retries`` times at most."""

    lasts_until_restart = True

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


HANDLERS: dict[str, FailureHandler] = {
    "Fallback": FallbackHandler(),
    "ReactiveFallback": FallbackHandler(),
    "RetryUntilSuccessful": RetryHandler(),
    "RecoveryNode": RecoveryHandler(),
}


def register_handler(type_name: str, handler: FailureHandler) -> None:
    """Treat nodes of ``type_name`` as failure handlers (see the module docstring)."""
    HANDLERS[type_name] = handler


def handler_of(node: Node) -> FailureHandler | None:
    """The node's failure handler, if its type has one."""
    return HANDLERS.get(node.type) if node.children else None

"""What a simulated domain provides: per-type timing and effects for scripted leaves.

A domain turns the leaves of a tree into simulated robot skills. Timing and results come
from the run's outcomes (with the domain's per-type durations as defaults); the domain
adds the effects — blackboard outputs that flow through ports, a simulated world that
changes — and may turn a result into FAILURE when an effect cannot be carried out.
"""

from __future__ import annotations

from btlog.domains.outcomes import Effect, Outcome, Outcomes, scripted_leaf_factory
from btlog.executor.behavior import LeafFactory
from btlog.tree.model import Node, Tree


class Domain:
    """A simulated domain. Subclasses set ``name`` and override ``duration``/``effect``."""

    name = "scripted"

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed

    def duration(self, node: Node) -> Outcome | None:
        """The default outcome of a leaf type where the outcomes file says nothing."""
        return None

    def effect(self, node: Node) -> Effect | None:
        """What the leaf does when it completes (None: nothing)."""
        return None

    def leaf_factory(self, tree: Tree, outcomes: Outcomes) -> LeafFactory:
        """The executor's factory for this domain's leaves."""
        return scripted_leaf_factory(
            tree, outcomes, self.seed, effects=self.effect, durations=self.duration
        )

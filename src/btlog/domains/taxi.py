"""The Taxi domain (the paper's section 7.2), simulated on the grid of ``taxi_world``.

The tree's actions drive a deterministic Taxi MDP: each ``move …`` moves the taxi one
cell (walls leave it in place), ``pick up`` and ``drop off`` fail where they are not
legal. After every action the taxi's cell, whether the passenger is aboard and the
reward so far are written to the root blackboard (``@taxi``, ``@passenger in taxi``,
``@reward``).
"""

from __future__ import annotations

from btlog.domains.base import Domain
from btlog.domains.outcomes import Effect, Outcome, ScriptedLeaf
from btlog.domains.taxi_mdp import ACTIONS, DROP_OFF, PICK_UP, TaxiWorld, default_world
from btlog.status import FAILURE, SUCCESS, Status
from btlog.tree.model import Node

#: Seconds one taxi action takes.
ACTION_SECONDS = 1.0


class TaxiDomain(Domain):
    """The simulated Taxi domain on ``world`` (the paper's grid by default)."""

    name = "taxi"

    def __init__(self, seed: int = 0, world: TaxiWorld | None = None) -> None:
        super().__init__(seed)
        self.world = world or default_world()
        self.state = self.world.start_state()
        self.reward = 0.0

    def duration(self, node: Node) -> Outcome | None:
        return Outcome(SUCCESS, round(ACTION_SECONDS * 1e9)) if node.type in ACTIONS else None

    def effect(self, node: Node) -> Effect | None:
        return self._act if node.type in ACTIONS else None

    def _act(self, leaf: ScriptedLeaf, status: Status) -> Status:
        if status is not SUCCESS:
            return status
        action = leaf.node.type
        before = self.state
        self.state, reward = self.world.step(before, action)
        self.reward += reward
        leaf.blackboard.set("@taxi", [self.state.row, self.state.col])
        leaf.blackboard.set("@passenger in taxi", self.state.in_taxi)
        leaf.blackboard.set("@reward", round(self.reward, 6))
        if action == PICK_UP and not self.state.in_taxi:
            return FAILURE
        if action == DROP_OFF and not self.state.delivered:
            return FAILURE
        return SUCCESS

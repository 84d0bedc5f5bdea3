"""The state at a moment: a projection folded from the events.

``State`` is everything the explanation algorithms need at one moment of a run, and
nothing that the events do not hold: each node's status; when each node's current
activation began (its last change out of IDLE, unless that change was its result
returned right after its own halt: see ``btlog.history.resumes``); when each node last
failed; how many failed attempts each RetryUntilSuccessful has made in its current run
(BT.CPP's ``try_count``: its child's failures, reset when the retry completes or is
halted) and likewise each Nav2 RecoveryNode (its first child's failures); the last
execution node to change status; the blackboard per scope; and, through ``TreeMutation``
events, the shape of the tree.

``StateProjection`` folds events into a ``State``. It is the only fold: the executor's
live subscriber and the replay from a recording use the same class, so the live answer
and the post-hoc answer at every event boundary are computed from equal states.
A ``State`` serialises to JSON so that the read model can keep snapshots and fold only
the tail of a long run.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from btlog.events import (
    PRUNE,
    BlackboardWrite,
    Event,
    StatusChange,
    Subscriber,
    TickRecord,
    TreeMutation,
)
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from btlog.tree.model import EXECUTION_KINDS, Tree, link_nodes

RETRY_TYPE = "RetryUntilSuccessful"
#: Nav2's RecoveryNode: a handler that falls back to its recovery child, then retries.
RECOVERY_TYPE = "RecoveryNode"


@dataclass
class State:
    """The state after the first ``seq`` events (``seq`` = number of events applied)."""

    seq: int = 0
    t_ns: int = 0
    tick: int = 0
    status: dict[int, Status] = field(default_factory=dict)
    activation: dict[int, int] = field(default_factory=dict)
    last_failure: dict[int, int] = field(default_factory=dict)
    retry_attempts: dict[int, int] = field(default_factory=dict)
    last_leaf: int | None = None
    blackboard: dict[str, dict[str, Any]] = field(default_factory=dict)
    mutations: list[TreeMutation] = field(default_factory=list)
    #: The node the last event reset from RUNNING to IDLE (None after any other event):
    #: its result, if it comes next, ends that activation (``btlog.history.resumes``).
    halted: int | None = None
    #: The nodes whose status is RUNNING (kept in step with ``status`` by the fold, filled
    #: from it when a state is built): the current nodes without a walk of the tree.
    running: set[int] = field(default_factory=set)

    def __post_init__(self) -> None:
        if not self.running:
            self.running = {uid for uid, status in self.status.items() if status is RUNNING}

    def status_of(self, uid: int) -> Status:
        """A node's status (IDLE if it never changed)."""
        return self.status.get(uid, IDLE)

    def failed_since(self, uid: int, since: int) -> bool:
        """True when node ``uid`` failed at or after event ``since``."""
        failed = self.last_failure.get(uid)
        return failed is not None and failed >= since

    def to_json(self) -> dict:
        """A JSON-ready snapshot (mutations are kept apart, by the read model)."""
        return {
            "seq": self.seq,
            "t_ns": self.t_ns,
            "tick": self.tick,
            "status": {str(k): int(v) for k, v in self.status.items()},
            "activation": {str(k): v for k, v in self.activation.items()},
            "last_failure": {str(k): v for k, v in self.last_failure.items()},
            "retry_attempts": {str(k): v for k, v in self.retry_attempts.items()},
            "last_leaf": self.last_leaf,
            "blackboard": self.blackboard,
            "halted": self.halted,
        }

    @classmethod
    def from_json(cls, data: dict, mutations: Sequence[TreeMutation] = ()) -> State:
        """Rebuild a snapshot written by ``to_json``."""
        return cls(
            seq=data["seq"],
            t_ns=data["t_ns"],
            tick=data["tick"],
            status={int(k): Status(v) for k, v in data["status"].items()},
            activation={int(k): v for k, v in data["activation"].items()},
            last_failure={int(k): v for k, v in data["last_failure"].items()},
            retry_attempts={int(k): v for k, v in data["retry_attempts"].items()},
            last_leaf=data["last_leaf"],
            blackboard=copy.deepcopy(data["blackboard"]),
            mutations=list(mutations),
            halted=data.get("halted"),
        )


class StateProjection(Subscriber):
    """Folds events into a ``State`` and keeps the tree's shape in step with mutations.

    ``base`` is the tree as recorded at the start; the projection works on its own copy.
    """

    def __init__(self, base: Tree, state: State | None = None) -> None:
        self.tree = base.copy_nodes()
        self.state = state if state is not None else State()
        self._index_tree()
        for mutation in self.state.mutations:
            self._change_tree(mutation)

    def _index_tree(self) -> None:
        self._execution = {n.uid for n in self.tree if n.kind in EXECUTION_KINDS}
        self._retry_parent = {
            n.uid: n.parent.uid
            for n in self.tree
            if n.parent is not None
            and (
                n.parent.type == RETRY_TYPE
                or (n.parent.type == RECOVERY_TYPE and n.parent.children[0] is n)
            )
        }
        self._retries = {n.uid for n in self.tree if n.type in (RETRY_TYPE, RECOVERY_TYPE)}

    # -- the fold ----------------------------------------------------------------------
    def on_status(
        self, seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
    ) -> None:
        """Apply a status change."""
        state = self.state
        state.seq = seq + 1
        state.t_ns = t_ns
        state.tick = tick
        state.status[uid] = status
        if status is RUNNING:
            state.running.add(uid)
        else:
            state.running.discard(uid)
        if prev is IDLE and not (status in (SUCCESS, FAILURE) and state.halted == uid):
            state.activation[uid] = seq
        state.halted = uid if prev is RUNNING and status is IDLE else None
        if status is FAILURE:
            state.last_failure[uid] = seq
            retry = self._retry_parent.get(uid)
            if retry is not None:
                state.retry_attempts[retry] = state.retry_attempts.get(retry, 0) + 1
        if uid in self._retries and status is not RUNNING:
            state.retry_attempts.pop(uid, None)
        if status is not IDLE and uid in self._execution:
            state.last_leaf = uid

    def on_write(
        self,
        seq: int,
        t_ns: int,
        tick: int,
        scope: str,
        key: str,
        value: Any,
        type_name: str,
        writer_uid: int | None,
    ) -> None:
        """Apply a blackboard write (or removal)."""
        state = self.state
        state.seq = seq + 1
        state.t_ns = t_ns
        state.tick = tick
        state.halted = None
        entries = state.blackboard.setdefault(scope, {})
        if type_name == "unset":
            entries.pop(key, None)
        else:
            entries[key] = value

    def on_mutation(self, mutation: TreeMutation) -> None:
        """Apply a change of the tree."""
        state = self.state
        state.seq = mutation.seq + 1
        state.t_ns = mutation.t_ns
        state.tick = mutation.tick
        state.halted = None
        state.mutations.append(mutation)
        self._change_tree(mutation)

    def on_tick(self, record: TickRecord) -> None:
        """Ticks carry no state beyond their events."""

    def apply(self, event: Event) -> None:
        """Apply one event record."""
        if isinstance(event, StatusChange):
            self.on_status(*event)
        elif isinstance(event, BlackboardWrite):
            self.on_write(*event)
        else:
            self.on_mutation(event)

    def _change_tree(self, mutation: TreeMutation) -> None:
        if mutation.op == PRUNE:
            self._prune(mutation)
        else:
            self._insert(mutation)

    def _prune(self, mutation: TreeMutation) -> None:
        """Take the subtree out; its nodes have no status any more."""
        node = self.tree.nodes.get(mutation.inserted_root_uid)
        if node is None or node.parent is None:
            return
        for removed in node.walk():
            self.state.status.pop(removed.uid, None)
        self.tree.remove(node)
        self._index_tree()

    def _insert(self, mutation: TreeMutation) -> None:
        parent = self.tree.node(mutation.parent_uid)
        after = None if mutation.after_uid is None else self.tree.node(mutation.after_uid)
        nodes = link_nodes(mutation.nodes)
        root = next(n for n in nodes if n.parent is None)
        self.tree.insert_after(parent, after, root, mutation.seq)
        self._index_tree()

"""The executor: builds behaviours from a tree, ticks the root, and feeds subscribers.

One ``tick()`` is BT.CPP's ``tickOnce``: the root is ticked, ticked again at once while a
node signalled a wake-up and the root is still RUNNING, and reset after it completes.
Every status change, blackboard write and tree mutation gets the next ``seq`` and the
clock's time and is delivered, in execution order, to each subscriber. With no
subscriber the nodes find ``emit_status`` empty and pay nothing more.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from btlog.events import (
    CHANGE,
    StatusBatch,
    Subscriber,
    TickRecord,
    TreeMutation,
    change_rows,
    type_name,
)
from btlog.executor.actions import ACTIONS
from btlog.executor.behavior import (
    Behavior,
    ControlBehavior,
    LeafFactory,
    NodeExecutionError,
    Runtime,
)
from btlog.executor.blackboard import UNSET, Blackboard, subtree_remapping
from btlog.executor.clock import SimClock, WallClock
from btlog.executor.controls import CONTROLS, Sequence
from btlog.executor.decorators import DECORATORS, PassThrough
from btlog.executor.nav2_controls import NAV2_CONTROLS
from btlog.executor.nav2_decorators import NAV2_DECORATORS
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from btlog.tree.model import CONTROL, DECORATOR, SUBTREE, Node, Tree
from btlog.tree.ports import parse_literal
from btlog.tree.registry import Registry

#: The most times a tick ticks the root again at once when a node asks (BT.CPP's wake-up
#: signal). BT.CPP re-ticks while real time passes, so a timer ends a retry that fails
#: at once forever (BT.CPP's test Parallel.PauseWithRetry); on the simulated clock no
#: time passes within a tick, so the tick ends here and the clock moves on.
MAX_WAKE_UPS = 100

#: ``TickRecord`` from a tuple, a third faster than its ``__new__`` (once a tick)
_tick_record = TickRecord._make

#: How a control or decorator btlog has no code for runs (the loader warns about each
#: type): as a Sequence, and as its child (``btlog.tree.declared``).
PASS_THROUGH: dict[str, type[Behavior]] = {CONTROL: Sequence, DECORATOR: PassThrough}

BUILTIN_BEHAVIORS: dict[str, type[Behavior]] = {
    **CONTROLS,
    **DECORATORS,
    **NAV2_CONTROLS,
    **NAV2_DECORATORS,
    **ACTIONS,
}


class Executor:
    """Runs a ``Tree`` with BehaviorTree.CPP v4 semantics.

    ``leaf_factory`` builds leaves whose type has no implementation (the outcomes of a
    simulated run); without one, such a tree is refused.
    """

    def __init__(
        self,
        tree: Tree,
        registry: Registry | None = None,
        clock: SimClock | WallClock | None = None,
        leaf_factory: LeafFactory | None = None,
    ) -> None:
        self.tree = tree
        self.registry = registry or Registry()
        self.runtime = Runtime(clock or SimClock())
        self.leaf_factory = leaf_factory
        self.subscribers: list[Subscriber] = []
        #: status changes not yet numbered, for a sole subscriber that takes batches
        self._batch: StatusBatch | None = None
        self.root_board = Blackboard("")
        self.root_board.on_write = self._on_write
        self._initial_writes: list[tuple[Blackboard, str, Any]] = []
        self.behaviors: dict[int, Behavior] = {}
        self.root = self._build(tree.root, self.root_board)
        self.started = False
        self.torn_down = False
        self.last_status: Status = IDLE

    # -- construction ------------------------------------------------------------------
    def _behavior_class(self, node: Node) -> Callable[..., Behavior] | None:
        node_type = self.registry.get(node.type)
        if node_type is not None and node_type.factory is not None:
            factory: Callable[..., Behavior] = node_type.factory
            return factory
        return BUILTIN_BEHAVIORS.get(node.type)

    def _build(self, node: Node, board: Blackboard) -> Behavior:
        cls = self._behavior_class(node)
        if node.kind == SUBTREE and cls is not None:
            inner = self._subtree_board(node, board)
            behavior = cls(node, self.runtime, board)
            behavior.children = [self._build(node.children[0], inner)]
        elif cls is None and node.children and node.kind in PASS_THROUGH:
            behavior = PASS_THROUGH[node.kind](node, self.runtime, board)
            behavior.children = [self._build(child, board) for child in node.children]
        elif cls is None:
            if self.leaf_factory is None or node.children:
                raise NodeExecutionError(node, f"no implementation of node type {node.type!r}")
            behavior = self.leaf_factory(node, self.runtime, board)
        else:
            behavior = cls(node, self.runtime, board)
            behavior.children = [self._build(child, board) for child in node.children]
        behavior.check_ports()
        if node.kind != SUBTREE:
            for name, port in node.ports.items():
                key = port.key
                if key is not None:
                    board.declare(name if key == "=" else key)
        if self._batch is not None:  # a subtree inserted while a recorder listens
            behavior.changes = change_rows(node.uid)
        self.behaviors[node.uid] = behavior
        return behavior

    def _subtree_board(self, node: Node, parent: Blackboard) -> Blackboard:
        if node.attributes.get("shared_blackboard") == "true":
            return parent
        scope = node.children[0].scope
        remap, autoremap, literals = subtree_remapping(node)
        board = Blackboard(scope, parent, remap, autoremap)
        for name, written in literals:
            value = parse_literal(written)
            board.preset(name, value)
            self._initial_writes.append((board, name, value))
        return board

    def preset(self, key: str, value: Any) -> None:
        """Set a root blackboard entry before the first tick, as a BT.CPP program sets one
        before ticking; its write is reported when the run begins."""
        if self.started:
            raise RuntimeError("preset() after the run began")
        self.root_board.preset(key, value)
        self._initial_writes.append((self.root_board, key, value))

    # -- subscribers -------------------------------------------------------------------
    def subscribe(self, subscriber: Subscriber) -> None:
        """Deliver every later event to ``subscriber``."""
        self.subscribers.append(subscriber)
        self._wire()

    def unsubscribe(self, subscriber: Subscriber) -> None:
        """Stop delivering events to ``subscriber``."""
        self.subscribers.remove(subscriber)
        self._wire()

    def _wire(self) -> None:
        """Build the ``emit_status`` the nodes call: with one subscriber that takes status
        changes in batches, the executor's batch (see ``settle``); otherwise a call of
        every subscriber's ``on_status``."""
        self.settle()
        subscribers = tuple(self.subscribers)
        runtime = self.runtime
        runtime.append_row = None
        self._batch = None
        if not subscribers:
            runtime.emit_status = None
            return
        if len(subscribers) == 1 and subscribers[0].takes_status_batches():
            for behavior in self.behaviors.values():
                if not behavior.changes:
                    behavior.changes = change_rows(behavior.uid)
            append = runtime.append_row = self._batch_appender(subscribers[0])

            def emit_change(uid: int, prev: Status, new: Status) -> None:
                append(CHANGE.pack(uid, prev, new))

            runtime.emit_status = emit_change
            return
        now = runtime.clock.now_ns
        handlers = tuple(s.on_status for s in subscribers)

        def emit(uid: int, prev: Status, new: Status) -> None:
            seq = runtime.seq
            runtime.seq = seq + 1
            t = now()
            for handler in handlers:
                handler(seq, t, runtime.tick, uid, prev, new)

        runtime.emit_status = emit

    def _batch_appender(self, taker: Subscriber) -> Callable[[bytes], None]:
        """Start a batch for ``taker`` and return what adds a change to it: the list's
        own ``append`` with a simulated clock, whose time changes only between ticks
        (``settle`` gives it once for the batch); otherwise a function that also notes
        the change's time."""
        clock = self.runtime.clock
        batch = self._batch = StatusBatch(taker, timed=not clock.simulated)
        if batch.times is None:
            return batch.changes.append
        add, add_time, now = batch.changes.append, batch.times.append, clock.now_ns

        def append_timed(change: bytes) -> None:
            add(change)
            add_time(now())

        return append_timed

    def settle(self) -> None:
        """Number the batched status changes and hand them to the subscriber that takes
        them. The nodes only append changes (``Runtime.append_row``); numbering and
        timing them here, once for the lot, is what makes a recorded change cheap. It
        runs before anything else takes a ``seq`` (a write, a mutation, ``seq`` itself)
        and before the tick or a simulated clock's time changes (``tick`` settles before
        ``start_tick``), so the numbers and times are those of execution order."""
        batch = self._batch
        if batch is not None and batch.changes:
            runtime = self.runtime
            seq = runtime.seq
            runtime.seq = seq + batch.count()
            batch.hand_over(seq, runtime.tick, runtime.clock.t_ns)

    def _on_write(self, scope: str, key: str, value: Any, writer: int | None) -> None:
        if not self.subscribers:
            return
        self.settle()
        runtime = self.runtime
        seq = runtime.seq
        runtime.seq = seq + 1
        t = runtime.clock.now_ns()
        kind = "unset" if value is UNSET else type_name(value)
        if value is UNSET:
            value = None
        for subscriber in self.subscribers:
            subscriber.on_write(seq, t, self.runtime.tick, scope, key, value, kind, writer)

    # -- running -----------------------------------------------------------------------
    def begin(self) -> None:
        """Report the initial blackboard entries (SubTree literals). Called once, by the
        first ``tick`` if not before; subscribe before it to see them."""
        if self.started:
            return
        self.started = True
        for board, key, value in self._initial_writes:
            self._on_write(board.scope, key, value, None)

    def tick(self) -> Status:
        """One tick of the root (BT.CPP's tickOnce); returns the root's status."""
        if not self.started:
            self.begin()
        runtime, root = self.runtime, self.root
        clock = runtime.clock
        if self._batch is not None:  # changes made between ticks (a halt): the last tick's
            self.settle()
        tick = runtime.tick = runtime.tick + 1
        clock.start_tick(tick)
        start = clock.t_ns  # the clock read as the nodes' hot path reads it (no call)
        status = root.execute_tick()
        again = 0
        while status is RUNNING and runtime.wake_up and again < MAX_WAKE_UPS:
            runtime.wake_up = False
            again += 1
            status = root.execute_tick()
        runtime.wake_up = False
        if status is SUCCESS or status is FAILURE:
            root.reset_status()
        self.last_status = status
        subscribers = self.subscribers
        if subscribers:
            if self._batch is not None:
                self.settle()
            record = _tick_record((tick, start, clock.t_ns, status, False))
            for subscriber in subscribers:
                subscriber.on_tick(record)
        return status

    def run(
        self, max_ticks: int | None = None, before_tick: Callable[[Executor], None] | None = None
    ) -> Status:
        """Tick until the root completes or ``max_ticks``; returns the last root status. A
        run stopped by the limit is left RUNNING: ``teardown`` (or ``close``) halts it."""
        status = IDLE
        while max_ticks is None or self.runtime.tick < max_ticks:
            if before_tick is not None:
                before_tick(self)
            status = self.tick()
            if status is SUCCESS or status is FAILURE:
                return status
        return status

    def teardown(self) -> None:
        """End the run as BehaviorTree.CPP does when a tree is destroyed: ``haltTree``,
        which halts what still runs and resets every node left non-IDLE (a
        SequenceWithMemory's completed children, a run stopped by ``max_ticks``). It is
        a tick of its own, at the time the last tick ended, recorded with
        ``teardown=True``; once per run, and only after a first tick."""
        if self.torn_down or not self.started:
            return
        self.torn_down = True
        self.settle()
        runtime = self.runtime
        runtime.tick += 1
        start = runtime.clock.now_ns()
        self.halt()
        self.last_status = IDLE
        if self.subscribers:
            self.settle()
            record = TickRecord(runtime.tick, start, runtime.clock.now_ns(), IDLE, teardown=True)
            for subscriber in self.subscribers:
                subscriber.on_tick(record)

    def halt(self) -> None:
        """Halt the whole tree as BT.CPP's ``haltTree``: halt the root, then every node in
        pre-order (so ``_onHalted`` runs everywhere), then reset the root. The transitions
        are reported in the current tick."""
        self.root.halt_node()
        stack = [self.root]
        while stack:
            behavior = stack.pop()
            behavior.halt_node()
            stack.extend(reversed(behavior.children))
        self.root.reset_status()

    def close(self, teardown: bool = True) -> None:
        """Tear the tree down (unless ``teardown`` is false, e.g. after an error in a
        tick) and tell subscribers the run is over."""
        if teardown:
            self.teardown()
        self.settle()
        for subscriber in self.subscribers:
            subscriber.on_close()

    # -- inspection --------------------------------------------------------------------
    @property
    def seq(self) -> int:
        """The number of events so far (the next event's seq)."""
        self.settle()
        return self.runtime.seq

    def statuses(self) -> dict[int, Status]:
        """Every node's current status by uid."""
        return {uid: b.status for uid, b in self.behaviors.items()}

    def blackboards(self) -> dict[str, dict[str, Any]]:
        """Every scope's entries (only scopes that hold entries)."""
        boards: dict[str, dict[str, Any]] = {}
        seen: set[int] = set()
        for behavior in self.behaviors.values():
            board = behavior.blackboard.board
            if id(board) not in seen and board.entries:
                seen.add(id(board))
                boards[board.scope] = dict(board.entries)
        return boards

    # -- mutation ----------------------------------------------------------------------
    def insert_after(
        self, parent_uid: int, after_uid: int | None, source: Node, question: str = ""
    ) -> TreeMutation:
        """Insert a deep copy of ``source`` (fresh uids) under ``parent_uid`` right after
        ``after_uid``, while running; the parent finds the new child dynamically."""
        parent = self.tree.node(parent_uid)
        parent_behavior = self.behaviors[parent_uid]
        if not isinstance(parent_behavior, ControlBehavior):
            raise ValueError(f"cannot insert under {parent.description!r}: not a control node")
        copy = self.tree.copy_subtree(source, self.tree.next_uid)
        seq = self.seq
        after = None if after_uid is None else self.tree.node(after_uid)
        index = self.tree.insert_after(parent, after, copy, seq)
        board = parent_behavior.blackboard.board
        behavior = self._build(copy, board)
        parent_behavior.insert_child(index, behavior)
        self.runtime.seq += 1
        mutation = TreeMutation(
            seq,
            self.runtime.clock.now_ns(),
            self.runtime.tick,
            "insert",
            parent_uid,
            after_uid,
            [n.describe() for n in copy.walk()],
            question,
        )
        for subscriber in self.subscribers:
            subscriber.on_mutation(mutation)
        return mutation

"""Record a py_trees run: every tick of a ``py_trees.trees.BehaviourTree`` into a btlog
recording, with the same topics, tables and questions as any other.

    with btlog.sources.py_trees.record(tree, "run.mcap") as recorder:
        for _ in range(10):
            tree.tick()
        print(recorder.answer("What are you doing?").text)

The tree's structure becomes the recording's tree (``btlog.sources.py_trees_tree``:
names, types, kinds). Each ``tree.tick()`` (also from ``tick_tock``) is one btlog tick,
numbered as py_trees counts them from the first tick recorded. Every status change of
every behaviour is recorded where py_trees makes it (``btlog.sources.py_trees_hooks``):
INVALID is IDLE, and a change no visitor sees — a RUNNING child of a
``Selector(memory=False)`` pre-empted by a higher priority, a child reset by its
parent's ``stop()`` — is recorded too. Blackboard writes come from py_trees' activity
stream (the key as py_trees names it, the writer the behaviour owning the client, the
value as JSON when it can be, else a bounded ``repr``). Children put in or taken out of
a composite — the tree's ``insert_subtree``, ``prune_subtree``, ``replace_subtree``, or
the composite's own ``add_child``, ``insert_child``, ``remove_child``, ... — are recorded
as mutations (a replacement is a prune then an insert). Times come from the wall clock, or from
``clock`` (seconds, e.g. a simulation's), since the recording started.

The recording is made by the one ``RecordingBuilder`` all importers use, with the ticks
given (``explicit_ticks``). ``answer`` answers a question live from the events so far,
as post hoc ``btlog ask --at seq:N`` answers it from the file, and records the answer.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from importlib import metadata as package_metadata
from typing import Any

from py_trees import common as pt_common
from py_trees import composites as pt_composites

from btlog.events import Backlog, Subscriber, change_rows, type_name
from btlog.explain.questions import Answer, answer
from btlog.history import LiveHistory
from btlog.sources.builder import BuildResult, RecordingBuilder, Source
from btlog.sources.py_trees_hooks import (
    ActivityTap,
    TreeWatch,
    recorded_value,
    tap_blackboard,
    untap_blackboard,
)
from btlog.sources.py_trees_tree import behaviours, build_subtree, tree_of
from btlog.state import State
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from btlog.tree.model import Node, Tree

#: py_trees' statuses as btlog's: INVALID (not ticked since its last reset) is IDLE.
STATUS: dict[Any, Status] = {
    pt_common.Status.SUCCESS: SUCCESS,
    pt_common.Status.FAILURE: FAILURE,
    pt_common.Status.RUNNING: RUNNING,
    pt_common.Status.INVALID: IDLE,
}
#: ``STATUS`` by the id of py_trees' status (an enum's own hash is computed in Python).
STATUS_BY_ID: dict[int, Status] = {id(status): ours for status, ours in STATUS.items()}
#: The blackboard scope of py_trees' one (global) blackboard.
SCOPE = ""
PRUNE = "prune"
INSERT = "insert"


def packed_rows(uid: int) -> dict[int, dict[int, bytes]]:
    """Node ``uid``'s packed changes by the ids of its old and new py_trees status
    (``btlog.sources.py_trees_hooks.Rows``)."""
    rows = change_rows(uid)
    return {id(old): {id(new): rows[STATUS[old]][STATUS[new]] for new in STATUS} for old in STATUS}


def py_trees_version() -> str:
    """The installed py_trees' version ("" when unknown)."""
    try:
        return package_metadata.version("py_trees")
    except package_metadata.PackageNotFoundError:
        return ""


class PyTreesRecorder:
    """Records the ticks of ``tree`` (a ``py_trees.trees.BehaviourTree``) into ``path``
    until ``close``; see the module docstring.

    Each change is put in a list by the behaviour itself (``py_trees_hooks``); the list
    goes to the builder, as one batch at one time, before anything else is recorded (a write, a
    mutation, a tick's start or end, a question). The live history ``answer`` reads is
    brought up to date only when a question is asked (the builder keeps the events for
    it meanwhile: ``btlog.events.Backlog``), so a run nobody questions costs no more
    than its recording; ``answers=False`` keeps no history at all (``answer`` is then
    refused)."""

    def __init__(
        self,
        tree: Any,
        path: str | os.PathLike,
        *,
        metadata: Mapping[str, Any] | None = None,
        blackboard: bool = True,
        clock: Callable[[], float] | None = None,
        answers: bool = True,
        flush_interval: float = 1.0,
        subscribers: Iterable[Subscriber] = (),
    ) -> None:
        self.py_tree = tree
        self.tree, pairs = tree_of(tree.root)
        self._clock = clock
        self._start = clock() if clock is not None else time.monotonic_ns()
        self._start_ns = time.monotonic_ns()
        source = Source(
            "py_trees",
            f"py_trees tree {self.tree.name!r}",
            details={"blackboard": blackboard, "py_trees_version": py_trees_version()},
        )
        record = {"clock": "wall" if clock is None else "sim", **(metadata or {})}
        self.builder = RecordingBuilder(
            path,
            self.tree,
            source,
            metadata=record,
            flush_interval=flush_interval,
            subscribers=subscribers,
            explicit_ticks=True,
        )
        self._history: LiveHistory | None = None
        self._backlog: Backlog | None = None
        if answers:
            self._history = LiveHistory(self.tree)
            self._backlog = Backlog()
            self.builder.subscribe(self._backlog)
        #: the changes the behaviours made, not handed on yet
        self._changes: list[bytes] = []
        #: the time of the tick (of the last event outside ticks): the changes' time
        self._tick_ns = 0
        self._ticking = False
        self._next_uid = self.tree.next_uid
        #: the live tree's behaviours, watched (``py_trees_hooks``)
        self.watch = TreeWatch(self._changes.append)
        self._clients: dict[Any, int | None] = {}
        self._unknown_clients: set[Any] = set()
        self._tap: ActivityTap | None = None
        self._patched: list[str] = []
        #: status changes found by the sweep (made outside ``stop`` and a tick's yield)
        self.swept = 0
        self.result: BuildResult | None = None
        self.builder.begin_mid_run(
            {node.uid: STATUS.get(behaviour.status, IDLE) for behaviour, node in pairs}
        )
        self._hook_all(pairs)
        self.watch.watch_ticks(tree.root)
        if blackboard:
            self._tap = tap_blackboard(self._on_blackboard)
        self._patch_tree()

    # -- the clock -----------------------------------------------------------------------
    def now_ns(self) -> int:
        """The time since the recording started, in ns."""
        if self._clock is None:
            return time.monotonic_ns() - int(self._start)
        return round((self._clock() - self._start) * 1e9)

    # -- hooks ---------------------------------------------------------------------------
    def _hook_all(self, pairs: list[tuple[Any, Node]]) -> None:
        for behaviour, node in pairs:
            self.watch.watch(behaviour, node.uid, packed_rows(node.uid))
            if isinstance(behaviour, pt_composites.Composite):
                self.watch.watch_children(behaviour, self._inserted, self._pruned)
        self._clients.clear()
        self._unknown_clients.clear()

    def _at(self) -> int:
        """The time of an event now: its tick's (py_trees' clock is its ticks'), or,
        between ticks, now."""
        return self._tick_ns if self._ticking else self.now_ns()

    def _hand_on(self) -> None:
        """Give the builder the changes made since the last time (at ``_at``)."""
        changes = self._changes
        if changes:
            self.builder.packed(changes, self._at())
            changes.clear()

    def _on_blackboard(self, item: Any) -> None:
        self._hand_on()
        writer = self._writer_of(item.client_id)
        if item.activity_type == "UNSET":
            self.builder.write(self._at(), SCOPE, item.key, None, writer, "unset")
            return
        value = item.current_value
        label = type_name(value)
        self.builder.write(self._at(), SCOPE, item.key, recorded_value(value), writer, label)

    def _writer_of(self, client_id: Any) -> int | None:
        """The uid of the behaviour whose blackboard client ``client_id`` is (None for a
        client outside the tree)."""
        uid = self._clients.get(client_id)
        if uid is not None or client_id in self._unknown_clients:
            return uid
        for behaviour, known in self.watch.uids.items():
            for client in getattr(behaviour, "blackboards", ()):
                self._clients[client.unique_identifier] = known
        uid = self._clients.get(client_id)
        if uid is None:
            self._unknown_clients.add(client_id)
        return uid

    def _patch_tree(self) -> None:
        """Route the tree's ``tick`` through the recorder."""
        tree = self.py_tree
        original = tree.tick

        def tick(*args: Any, **kwargs: Any) -> None:
            self._hand_on()
            self._tick_ns = self.now_ns()
            self.builder.start_tick(self._tick_ns)
            self._ticking = True
            try:
                original(*args, **kwargs)
            finally:
                self.swept += self.watch.sweep()
                self._hand_on()
                self._ticking = False
                root = STATUS_BY_ID.get(id(tree.root.status), IDLE)
                self.builder.end_tick(self.now_ns(), root)

        tick.__doc__ = original.__doc__
        tree.tick = tick
        self._patched.append("tick")

    # -- mutations -----------------------------------------------------------------------
    def _inserted(self, behaviour: Any) -> None:
        """``behaviour``'s subtree was put in the tree: a mutation, then its statuses."""
        self._hand_on()
        parent_uid = self.watch.uid_of(behaviour.parent)
        if parent_uid is None:
            return
        parent = self.tree.node(parent_uid)
        index = behaviour.parent.children.index(behaviour)
        after_behaviour = behaviour.parent.children[index - 1] if index > 0 else None
        after_uid = None if after_behaviour is None else self.watch.uid_of(after_behaviour)
        after = None if after_uid is None else self.tree.node(after_uid)
        root, pairs = build_subtree(behaviour, self._next_uid)
        self._next_uid += len(pairs)
        self.tree.insert_after(parent, after, root, self.builder.seq)
        records = [node.describe() for node in root.walk()]
        self.builder.mutate(self._at(), INSERT, parent_uid, after_uid, records)
        for child, node in pairs:
            status = STATUS.get(child.status, IDLE)
            if status is not IDLE:
                self.builder.transition(self._at(), node.uid, status)
        self._hook_all(pairs)

    def _pruned(self, behaviour: Any) -> None:
        """``behaviour``'s subtree was taken out of the tree: a mutation naming it."""
        uid = self.watch.uid_of(behaviour)
        if uid is None:
            return
        self._hand_on()
        node = self.tree.node(uid)
        parent = node.parent
        records = [n.describe() for n in node.walk()]
        self.builder.mutate(
            self._at(), PRUNE, parent.uid if parent is not None else uid, None, records
        )
        self.tree.remove(node)
        for removed in behaviours(behaviour):
            self.watch.unwatch(removed)
        self._clients.clear()
        self._unknown_clients.clear()

    # -- questions -----------------------------------------------------------------------
    def answer(self, question: str, at_ns: int | None = None) -> Answer:
        """Answer ``question`` about the run so far (as post hoc at its last event, or at
        ``at_ns`` when that is later), and record the answer on ``/btlog/answers``."""
        history = self.live_history()
        return self.answer_about(question, history.tree, history.state, at_ns)

    def answer_about(
        self, question: str, tree: Tree, state: State, at_ns: int | None = None
    ) -> Answer:
        """Answer ``question`` about an earlier ``state`` of the run (of ``tree``, from
        the live history's ``state_after``), and record the answer."""
        history = self.live_history()
        result = answer(tree, state, question, history, at_ns)
        self.builder.recorder.on_answer(
            state.seq, state.t_ns, state.tick, question, result.intent, result.text
        )
        return result

    @property
    def history(self) -> LiveHistory | None:
        """The live history of the run so far (brought up to date now), or None without
        ``answers``."""
        if self._history is None or self._backlog is None:
            return None
        self._hand_on()
        self.builder.flush_batch()
        self._backlog.catch_up(self._history)
        return self._history

    def live_history(self) -> LiveHistory:
        """``history``, refused (``RuntimeError``) without ``answers``."""
        history = self.history
        if history is None:
            raise RuntimeError("this recorder keeps no live history (answers=False)")
        return history

    # -- the end -------------------------------------------------------------------------
    @property
    def ticks(self) -> int:
        """The ticks recorded so far."""
        return self.builder.tick

    def close(self) -> BuildResult:
        """Stop recording: the tree and blackboard are as they were, the file finished."""
        if self.result is not None:
            return self.result
        self.swept += self.watch.sweep()
        self._hand_on()
        for name in self._patched:
            self.py_tree.__dict__.pop(name, None)
        self._patched.clear()
        if self._tap is not None:
            untap_blackboard(self._tap)
            self._tap = None
        for behaviour in list(self.watch.uids):
            self.watch.unwatch(behaviour)
        self.result = self.builder.close()
        return self.result

    def __enter__(self) -> PyTreesRecorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


@contextmanager
def record(
    tree: Any,
    path: str | os.PathLike,
    *,
    metadata: Mapping[str, Any] | None = None,
    blackboard: bool = True,
    clock: Callable[[], float] | None = None,
    answers: bool = True,
) -> Iterator[PyTreesRecorder]:
    """Record every ``tree.tick()`` inside the block into ``path`` (see the module
    docstring); yields the ``PyTreesRecorder``."""
    recorder = PyTreesRecorder(
        tree, path, metadata=metadata, blackboard=blackboard, clock=clock, answers=answers
    )
    try:
        yield recorder
    finally:
        recorder.close()

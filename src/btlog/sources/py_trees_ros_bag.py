"""Import py_trees_ros runs from a rosbag2 bag (MCAP or SQLite storage), without ROS.

py_trees_ros publishes the tree as ``py_trees_ros_interfaces/msg/BehaviourTree``
snapshots: every behaviour (its name, class, UUID, parent's and children's UUIDs,
type, status) after a tick, and the blackboard activity of that tick.
``btlog.sources.rosbag2`` reads the bag and decodes them (with the bag's own
definition, else the one btlog ships).

The tree is the first snapshot's: behaviours linked by ``child_ids`` from the one with
no parent, each a node as ``btlog.sources.py_trees_tree`` makes it from a live
behaviour (the class is the last part of ``class_name``; a Sequence's or Selector's
memory and a Parallel's policy come from ``additional_detail``). Each snapshot is one
tick: each behaviour whose status differs from the last snapshot's changes (INVALID is
IDLE), in a depth-first walk, a behaviour that starts RUNNING before its children's
changes, any other change after them (children complete before their parent, as
py_trees and BT.CPP order them). WRITE and INITIALISED blackboard activity items are
writes (key, the value's text, the behaviour named as the client when one is). A
snapshot whose behaviours differ from the tree's changes the tree first, at its tick:
a behaviour gone is a ``prune`` mutation of its subtree, a new one under a known parent
an ``insert`` (after its nearest earlier sibling, fresh uids after the largest ever
used), as the live py_trees recorder records ``prune_subtree`` and ``insert_subtree``;
a behaviour that moved to another parent is not followed.

A snapshot tells each status at its tick only; what happened between two snapshots (a
behaviour that ran and was reset, ticks whose snapshots were not published) is not in
the bag, and the import's warnings say so.
"""

from __future__ import annotations

import itertools
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from btlog.sources.builder import BuildResult, RecordingBuilder, Source, SourceError, wall_start
from btlog.sources.py_trees_tree import node_of
from btlog.sources.rosbag2 import open_bag
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from btlog.tree.model import Node, Tree

FORMAT = "py_trees_ros-rosbag2"
SNAPSHOT_TYPE = "py_trees_ros_interfaces/msg/BehaviourTree"
#: py_trees_ros_interfaces' Behaviour status constants as btlog's.
STATUS = {1: IDLE, 2: RUNNING, 3: SUCCESS, 4: FAILURE}
DECORATOR_TYPE = 6
COMPOSITE_TYPES = frozenset({2, 3, 4, 5})
WRITES = frozenset({"WRITE", "INITIALISED"})
BETWEEN = (
    "a snapshot holds each behaviour's status at its tick only: changes between two "
    "snapshots (a behaviour that ran and was reset, or stopped, before the next) are not "
    "in the bag, and the order of a snapshot's changes is inferred (a behaviour starts "
    "before its children change, completes after them)"
)
_ZERO = bytes(16)
INSERT = "insert"
PRUNE = "prune"


@dataclass
class Snapshots:
    """The snapshots of a bag's one BehaviourTree topic, in order."""

    file: str
    topic: str
    messages: list[tuple[int, Any]]
    layout: str
    files: list[str]
    warnings: list[str] = field(default_factory=list)


def snapshot_topics(path: str | os.PathLike) -> list[str]:
    """The topics of the bag that carry BehaviourTree snapshots."""
    with open_bag(path) as bag:
        return sorted(t.name for t in bag.topics.values() if t.type == SNAPSHOT_TYPE)


def read_snapshots(path: str | os.PathLike) -> Snapshots:
    """Read and decode the bag's BehaviourTree snapshots (one topic of that type)."""
    with open_bag(path) as bag:
        topics = sorted(t.name for t in bag.topics.values() if t.type == SNAPSHOT_TYPE)
        if len(topics) != 1:
            listed = ", ".join(sorted(bag.topics)) or "none"
            many = "several" if topics else "no"
            raise SourceError(f"{bag.path}: {many} {SNAPSHOT_TYPE} topics (topics: {listed})")
        messages = [(m.log_time_ns, m.decoded) for m in bag.messages({topics[0]})]
        used = bag.used.get(topics[0])
        found = Snapshots(
            bag.path, topics[0], messages, used.origin if used else "", list(bag.files)
        )
        found.warnings.extend(bag.warnings)
    if not any(getattr(m, "behaviours", None) for _t, m in found.messages):
        raise SourceError(f"{found.file}: {found.topic} holds no snapshot with behaviours")
    return found


def _uuid(value: Any) -> bytes:
    return bytes(getattr(value, "uuid", b"") or b"")


class _Policy:
    """A Parallel's policy as ``node_of`` reads it: its class name and chosen children."""

    def __init__(self, detail: str) -> None:
        self.children = re.findall(r"\d+", detail)


class _Behaviour:
    """A snapshot's behaviour with the attributes ``node_of`` reads from a live one."""

    def __init__(self, message: Any) -> None:
        self.name = str(message.name)
        detail = str(message.additional_detail)
        self.children: list[_Behaviour] = []
        self.memory = detail == "WithMemory"
        if int(message.type) == DECORATOR_TYPE:
            self.decorated = None
        policy = detail.split("(", 1)[0].strip()
        if policy:
            self.policy = type(f"Success{policy}", (_Policy,), {})(detail)
        self.composite = int(message.type) in COMPOSITE_TYPES
        self.class_name = str(message.class_name).rsplit(".", 1)[-1] or "Behaviour"


class _Composite:
    """Marks a composite (``node_of`` looks for a class named Composite)."""


_Composite.__name__ = "Composite"


def build_tree(first: Any, where: str) -> tuple[Tree, dict[bytes, int], list[str]]:
    """The tree of a snapshot, each behaviour's UUID -> uid (pre-order from 1), and the
    behaviours whose parameters the snapshot lacks (their class kept as the type)."""
    by_id: dict[bytes, Any] = {_uuid(b.own_id): b for b in first.behaviours}
    roots = [b for b in first.behaviours if _uuid(b.parent_id) not in by_id]
    if len(roots) != 1:
        raise SourceError(f"{where}: the first snapshot has {len(roots)} root behaviours")
    uids: dict[bytes, int] = {}
    lacking: list[str] = []
    root = build_subtree(roots[0], by_id, uids, itertools.count(1), lacking, where)
    return Tree(root=root, name=str(roots[0].name)), uids, lacking


def build_subtree(
    message: Any,
    by_id: dict[bytes, Any],
    uids: dict[bytes, int],
    numbers: Iterator[int],
    lacking: list[str],
    where: str,
) -> Node:
    """The parentless nodes of the behaviour ``message`` and its descendants (looked up
    in ``by_id``), uids taken from ``numbers`` in pre-order and noted in ``uids``; the
    behaviours whose parameters the snapshot lacks are added to ``lacking``."""
    own = _uuid(message.own_id)
    if own in uids:
        raise SourceError(f"{where}: behaviour {str(message.name)!r} appears twice")
    uid = uids[own] = next(numbers)
    shim = _Behaviour(message)
    shim.children = list(message.child_ids)  # node_of asks only whether it has some
    bases = (_Behaviour, _Composite) if shim.composite else (_Behaviour,)
    shim.__class__ = type(shim.class_name, bases, {})
    try:
        node = node_of(shim, uid)
    except (AttributeError, TypeError, ValueError):  # Retry's attempts, Timeout's...
        lacking.append(shim.name)
        shim.__class__ = type(f"{shim.class_name}_", (_Behaviour,), {})
        node = node_of(shim, uid)
        node.type = node.attributes["py_trees"] = shim.class_name
        if node.name == shim.class_name:  # py_trees' default name: nameless
            node.name, node.path = "", f"::{uid}"
    for child_id in message.child_ids:
        child = by_id.get(_uuid(child_id))
        if child is None:
            raise SourceError(f"{where}: {str(message.name)!r} has a child not in it")
        built = build_subtree(child, by_id, uids, numbers, lacking, where)
        built.parent = node
        node.children.append(built)
    return node


class _Shape:
    """Follows the tree's shape from snapshot to snapshot: a behaviour gone is a prune,
    a new one under a known parent an insert (uids after the largest ever used)."""

    def __init__(self, tree: Tree, uids: dict[bytes, int], builder: RecordingBuilder) -> None:
        self.tree, self.uids, self.builder = tree, uids, builder
        self.numbers = itertools.count(tree.next_uid)
        self.lacking: list[str] = []
        #: behaviours a snapshot could not place (a new root, a parent never seen)
        self.unplaced = 0

    def follow(self, t: int, message: Any, state: dict[int, Status], where: str) -> bool:
        """Make the tree the snapshot's (mutations at ``t``; ``state`` follows it);
        whether it changed."""
        by_id = {_uuid(b.own_id): b for b in message.behaviours}
        if by_id.keys() == self.uids.keys():
            return False
        own_of = {uid: own for own, uid in self.uids.items()}
        for node in list(self.tree):  # pre-order: the top of a gone subtree first
            if node.uid in self.tree.nodes and node.parent and own_of[node.uid] not in by_id:
                self._prune(t, node, state)
        new = [own for own in by_id if own not in self.uids]
        for own in new:
            parent_own = _uuid(by_id[own].parent_id)
            if parent_own in new:
                continue  # built with its new parent
            parent = self.uids.get(parent_own)
            if parent is None:
                self.unplaced += 1
                continue
            self._insert(t, by_id[own], self.tree.node(parent), by_id, state, where)
        return True

    def _prune(self, t: int, node: Node, state: dict[int, Status]) -> None:
        records = [n.describe() for n in node.walk()]
        self.builder.mutate(t, PRUNE, node.parent.uid, None, records)  # type: ignore[union-attr]
        gone = {n.uid for n in node.walk()}
        self.tree.remove(node)
        for own in [own for own, uid in self.uids.items() if uid in gone]:
            del self.uids[own]
        for uid in gone:
            state.pop(uid, None)

    def _insert(
        self,
        t: int,
        behaviour: Any,
        parent: Node,
        by_id: dict[bytes, Any],
        state: dict[int, Status],
        where: str,
    ) -> None:
        siblings = by_id[_uuid(behaviour.parent_id)].child_ids
        ids = [_uuid(child) for child in siblings]
        before = [self.uids.get(own) for own in ids[: ids.index(_uuid(behaviour.own_id))]]
        known = [uid for uid in before if uid is not None and uid in self.tree.nodes]
        after = self.tree.node(known[-1]) if known else None
        root = build_subtree(behaviour, by_id, self.uids, self.numbers, self.lacking, where)
        self.tree.insert_after(parent, after, root, self.builder.seq)
        records = [node.describe() for node in root.walk()]
        self.builder.mutate(t, INSERT, parent.uid, None if after is None else after.uid, records)
        for node in root.walk():
            state[node.uid] = IDLE


def _names(tree: Tree) -> dict[str, list[int]]:
    """The uids of the tree's nodes by py_trees name (a blackboard client's name)."""
    names: dict[str, list[int]] = {}
    for node in tree:
        names.setdefault(str(node.attributes.get("py_trees_name", node.name)), []).append(node.uid)
    return names


def _ordered_changes(tree: Tree, was: dict[int, Status], now: dict[int, Status]) -> list[int]:
    """The uids whose status changes, in the inferred order (the module docstring)."""
    order: list[int] = []

    def visit(node: Node) -> None:
        changes = was[node.uid] is not now[node.uid]
        starts = changes and now[node.uid] is RUNNING
        if starts:
            order.append(node.uid)
        for child in node.children:
            visit(child)
        if changes and not starts:
            order.append(node.uid)

    visit(tree.root)
    return order


def import_snapshots(path: str | os.PathLike, output: str | os.PathLike) -> BuildResult:
    """Import the bag's snapshots as one recording ``output`` (a snapshot is a tick)."""
    bag = read_snapshots(path)
    first_t, first = next((t, m) for t, m in bag.messages if m.behaviours)
    tree, uids, lacking = build_tree(first, f"{bag.file}: {bag.topic}")
    names = _names(tree)
    source = Source.of_file(
        FORMAT,
        bag.file,
        bag.files,
        topic=bag.topic,
        messages=len(bag.messages),
        definition=bag.layout,
        blackboard=True,
    )
    notes: list[str] = []
    builder = RecordingBuilder(
        output,
        tree,
        source,
        started_at=wall_start(first_t // 1000, bag.file, notes),
        attachments=(),
        metadata={"snapshots": BETWEEN},
        explicit_ticks=True,
    )
    builder.warnings.extend(notes)
    state = {uid: IDLE for uid in uids.values()}
    shape = _Shape(tree, uids, builder)
    where = f"{bag.file}: {bag.topic}"
    unknown = skipped = 0
    last_count: int | None = None
    try:
        for t_ns, message in bag.messages:
            t = max(0, t_ns - first_t)
            count = int(getattr(getattr(message, "statistics", None), "count", 0) or 0)
            if last_count is not None and count > last_count + 1:
                skipped += count - last_count - 1
            last_count = count if count else last_count
            builder.start_tick(t)
            if shape.follow(t, message, state, where):
                names = _names(tree)
            now = dict(state)
            for behaviour in message.behaviours:
                uid = uids.get(_uuid(behaviour.own_id))
                status = STATUS.get(int(behaviour.status))
                if uid is None or status is None:
                    unknown += 1
                    continue
                now[uid] = status
            for uid in _ordered_changes(tree, state, now):
                builder.transition(t, uid, now[uid], state[uid])
            for item in message.blackboard_activity:
                if str(item.activity_type) in WRITES:
                    writer = names.get(str(item.client_name), [])
                    builder.write(
                        t,
                        "",
                        str(item.key),
                        str(item.current_value),
                        writer[0] if len(writer) == 1 else None,
                    )
            builder.end_tick(t, now[tree.root.uid])
            state = now
    except BaseException:
        builder.close()
        Path(output).unlink(missing_ok=True)
        raise
    builder.warnings.extend(bag.warnings)
    builder.warnings.append(f"{bag.file}: {BETWEEN}")
    if skipped:
        builder.warnings.append(
            f"{bag.file}: {skipped} ticks have no snapshot in the bag (the statistics' tick "
            "count skips them: py_trees_ros publishes a snapshot only when the tree changed, "
            "or it was dropped); their changes show in the next snapshot"
        )
    if unknown:
        builder.warnings.append(
            f"{bag.file}: {unknown} behaviour entries name a behaviour not in the first "
            "snapshot's tree, or an unknown status; they were left out"
        )
    if shape.unplaced:
        builder.warnings.append(
            f"{bag.file}: {shape.unplaced} behaviours appeared under a parent never seen "
            "(or as a new root); they were left out"
        )
    lacking += [name for name in shape.lacking if name not in lacking]
    if lacking:
        builder.warnings.append(
            f"{bag.file}: the snapshots do not carry the parameters of "
            + ", ".join(repr(name) for name in lacking)
            + "; their py_trees class is kept as their type"
        )
    return builder.close()

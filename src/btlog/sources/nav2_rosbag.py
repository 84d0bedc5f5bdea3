"""Import Nav2 runs from a rosbag2 bag (MCAP or SQLite storage), without ROS.

Nav2's BT navigators publish ``/behavior_tree_log`` (``nav2_msgs/msg/BehaviorTreeLog``,
CDR): once per tick of the BT loop, the status changes of that tick, each with its
(wall-clock) time, node name, node uid (BT.CPP's creation order, the one btlog uses;
bags from Nav2 versions before the field was added have none) and previous and current
status. ``btlog.sources.rosbag2`` reads the bag and decodes them: with the definition
stored in the bag (MCAP; SQLite since Jazzy), else with the definitions of each Nav2
release btlog ships (Humble's SQLite bags hold none), the one that reads the messages
exactly.

The bag holds no tree, so the tree comes from ``--tree`` (or from the tree XML topic a
``btlog export --to nav2`` file carries). Log entries are matched to its nodes by uid,
checked against the name, else by name, which must then be unique in the tree.

Each goal is one recording: a goal starts when the tree's root leaves IDLE. Nav2 flushes
its log only while the tree is RUNNING, so a goal's last transitions (its result, the
root's reset) come with the next goal's first message, or never when the bag ends first.
A goal whose root never completes is imported as it is, with the recording's metadata
``incomplete`` saying so; nothing is invented.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from btlog.sources.btcpp_tree import tree_from_file, tree_from_log_xml
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    RecordingBuilder,
    Source,
    SourceError,
    never_named,
    omitted_changes,
    state_at_first_entry,
    wall_start,
)
from btlog.sources.name_matching import Entry, logged_names, match_names
from btlog.sources.rosbag2 import open_bag
from btlog.status import FAILURE, IDLE, SUCCESS, Status
from btlog.tree.loader import TreeError, load_tree
from btlog.tree.model import Tree
from btlog.tree.registry import Registry

FORMAT = "nav2-rosbag2"
LOG_TOPIC = "/behavior_tree_log"
LOG_TYPE = "nav2_msgs/msg/BehaviorTreeLog"
#: The topic on which ``btlog export --to nav2`` writes the tree's XML.
XML_TOPIC = "/behavior_tree_xml"
XML_TYPE = "std_msgs/msg/String"
STATUS_NAMES = frozenset(s.name for s in Status)
MID_RUN = (
    "the log begins mid-run (the recorder started after the goal did): the state at its "
    "first entry is inferred (each node's previous status in its first entry, RUNNING for "
    "their other ancestors) and recorded as the first tick"
)
NEVER_NAMED = (
    "never in the log while nodes under it run, so RUNNING from the first entry on (the "
    "recorder started after it did, or --tree has nodes the run's tree did not)"
)
OMITTED = (
    "changes the log leaves out were added, each at the time of the entry whose previous "
    "status shows it (resets to IDLE, when Nav2 runs with bt_log_idle_transitions false)"
)
INCOMPLETE = (
    "the bag ends before this goal's result: Nav2 publishes /behavior_tree_log only "
    "while the tree is RUNNING, so the goal's last transitions are missing (not invented)"
)


@dataclass(frozen=True, slots=True)
class LogEntry:
    """One BehaviorTreeStatusChange: absolute time, node name, uid (None if the bag's
    message type has none) and statuses. The bag's entries are all held (goals are split
    and names matched over them), so each is kept small: slots, and one string per name."""

    t_ns: int
    name: str
    uid: int | None
    prev: Status
    status: Status
    #: the number of the message that carried it (Nav2 publishes one a tick)
    message: int = 0


@dataclass
class BagLog:
    """The entries of ``/behavior_tree_log`` in order, and the tree XML if the bag has it."""

    file: str
    entries: list[LogEntry]
    messages: int
    tree_xml: bytes | None = None
    warnings: list[str] = field(default_factory=list)
    #: where the message definition came from: "bag", or the Nav2 releases of btlog's
    layout: str = ""
    #: the bag's storage files, in order
    files: list[str] = field(default_factory=list)


@dataclass
class Goal:
    """The entries of one goal (as uids of the tree) and whether its result is missing."""

    index: int
    entries: list[tuple[LogEntry, int]] = field(default_factory=list)
    complete: bool = False


def _status(text: str, where: str) -> Status:
    name = str(text).strip().upper()
    if name not in STATUS_NAMES:
        raise SourceError(f"{where}: unknown status {text!r}")
    return Status[name]


def _stamp_ns(stamp: object) -> int:
    return int(getattr(stamp, "sec", 0)) * 1_000_000_000 + int(getattr(stamp, "nanosec", 0))


def read_bag(path: str | os.PathLike) -> BagLog:
    """Read and decode ``/behavior_tree_log`` (and the tree XML topic, if any) of a bag in
    MCAP or SQLite storage (``btlog.sources.rosbag2``); what the bag's damage cost is
    in the warnings."""
    with open_bag(path) as bag:
        log = BagLog(bag.path, [], 0)
        topic = bag.topics.get(LOG_TOPIC)
        if topic is None:
            listed = ", ".join(sorted(bag.topics)) or "none"
            raise SourceError(f"{bag.path}: no {LOG_TOPIC} topic (topics: {listed})")
        if topic.type != LOG_TYPE or topic.serialization_format != "cdr":
            raise SourceError(
                f"{bag.path}: {LOG_TOPIC} has type {topic.type or '(none)'!r} "
                f"({topic.serialization_format}); expected {LOG_TYPE} (cdr)"
            )
        for message in bag.messages({LOG_TOPIC, XML_TOPIC}):
            if message.topic == XML_TOPIC:
                if message.type == XML_TYPE:
                    log.tree_xml = str(getattr(message.decoded, "data", "")).encode()
                continue
            log.messages += 1
            where = f"{bag.path}: message {log.messages}"
            log.entries.extend(_entries(message.decoded, log.messages, where))
        log.warnings.extend(bag.warnings)
        log.layout = bag.used[LOG_TOPIC].origin if LOG_TOPIC in bag.used else ""
        log.files = list(bag.files)
    if not log.entries:
        raise SourceError(f"{log.file}: {LOG_TOPIC} holds no status changes")
    return log


def _entries(decoded: object, number: int, where: str) -> Iterator[LogEntry]:
    for event in getattr(decoded, "event_log", []):
        uid = getattr(event, "uid", None)
        yield LogEntry(
            _stamp_ns(event.timestamp),
            sys.intern(str(event.node_name)),
            None if uid is None else int(uid),
            _status(event.previous_status, where),
            _status(event.current_status, where),
            number,
        )


def bag_tree(log: BagLog, tree_file: str | os.PathLike | None, registry: Registry | None) -> Tree:
    """The tree of the run: ``tree_file`` (checked against the bag's XML when it has
    one), else the bag's own tree XML."""
    if log.tree_xml is not None:
        own = tree_from_log_xml(log.tree_xml, f"{log.file} ({XML_TOPIC})", registry)
        return own if tree_file is None else tree_from_file(tree_file, own, registry)
    if tree_file is None:
        raise SourceError(f"{log.file}: the bag holds no tree; give the tree file with --tree")
    try:
        return load_tree(tree_file, registry, accept_unknown=True)
    except TreeError as error:
        raise SourceError(str(error)) from None


def match_uids(entries: list[LogEntry], tree: Tree, where: str) -> tuple[list[int], str]:
    """The tree uid of every entry and how they were matched ("uid" or "name")."""
    if all(e.uid is not None for e in entries):
        for entry in {(e.uid, e.name): e for e in entries}.values():
            node = tree.nodes.get(entry.uid or 0)
            # BT.CPP names a nameless node by its ID (btlog's description); '' is older
            if node is None or entry.name not in logged_names(node) | {node.name}:
                there = "no such node" if node is None else f"it is {node.name!r}"
                raise SourceError(
                    f"{where}: the log's node {entry.name!r} has uid {entry.uid}, but in the "
                    f"tree {there}; --tree is not the tree that ran"
                )
        return [e.uid or 0 for e in entries], "uid"
    named = [Entry(e.name, e.prev, e.status, e.message) for e in entries]
    return match_names(named, tree, where), "name"


def split_goals(entries: list[LogEntry], uids: list[int], root: int) -> list[Goal]:
    """One Goal per run of the tree: a goal starts when the root leaves IDLE after the
    previous goal's result, or while the log still has it running (that goal's end is
    missing). A root leaving IDLE within a goal (Nav2's RecoveryNode halts itself before
    it returns its result) does not start one. Entries before the first start form a goal
    of their own: the bag began during it."""
    goals: list[Goal] = []
    root_status: Status = IDLE
    for entry, uid in zip(entries, uids, strict=True):
        if uid == root and entry.status is not IDLE and entry.prev is IDLE:
            if not goals or goals[-1].complete or root_status is not IDLE:
                goals.append(Goal(len(goals) + 1))
        elif not goals:
            goals.append(Goal(1))
        goal = goals[-1]
        goal.entries.append((entry, uid))
        if uid == root:
            root_status = entry.status
            if entry.status in (SUCCESS, FAILURE):
                goal.complete = True
    return goals


def import_bag(
    path: str | os.PathLike,
    output: str | os.PathLike,
    tree_file: str | os.PathLike | None = None,
    registry: Registry | None = None,
    goal: int | None = None,
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS,
) -> list[BuildResult]:
    """Import every goal of the bag (or goal number ``goal``) as recordings: ``output``
    for one goal, else ``OUT-goalN.mcap`` beside it."""
    log = read_bag(path)
    tree = bag_tree(log, tree_file, registry)
    uids, matched_by = match_uids(log.entries, tree, log.file)
    goals = split_goals(log.entries, uids, tree.root.uid)
    if goal is not None:
        if not 1 <= goal <= len(goals):
            raise SourceError(f"{log.file}: --goal {goal}: the bag has {len(goals)} goals")
        chosen = [goals[goal - 1]]
    else:
        chosen = goals
    output = Path(output)
    attachments = []
    if tree_file is not None:
        attachments.append((Path(tree_file).name, Path(tree_file).read_bytes()))
    elif log.tree_xml is not None:
        attachments.append(("nav2-tree.xml", log.tree_xml))
    results = []
    for item in chosen:
        target = (
            output
            if len(chosen) == 1
            else output.with_name(f"{output.stem}-goal{item.index}{output.suffix or '.mcap'}")
        )
        source = Source.of_file(
            FORMAT,
            log.file,
            log.files,
            topic=LOG_TOPIC,
            messages=log.messages,
            definition=log.layout,
            matched_by=matched_by,
            goal=item.index,
            goals=len(goals),
        )
        results.append(_build(item, tree, source, target, attachments, tick_gap_ns, log.warnings))
    return results


def _build(
    goal: Goal,
    tree: Tree,
    source: Source,
    output: Path,
    attachments: list[tuple[str, bytes]],
    tick_gap_ns: int,
    warnings: list[str],
) -> BuildResult:
    start = goal.entries[0][0].t_ns
    first: dict[int, Status] = {}
    for entry, uid in goal.entries:
        first.setdefault(uid, entry.prev)
    began = state_at_first_entry(tree, first)
    unnamed = never_named(tree, first, began)
    # a log that begins mid-run infers the never-named ancestors too (MID_RUN says so)
    mid_run = MID_RUN if any(s is not IDLE for s in first.values()) else f"{unnamed}: {NEVER_NAMED}"
    metadata = {} if goal.complete else {"incomplete": INCOMPLETE}
    if began:
        metadata["mid_run"] = mid_run
    omitted = omitted_changes(((u, e.prev, e.status) for e, u in goal.entries), began)
    if omitted:
        metadata["omitted"] = f"{omitted} {OMITTED}"
    notes: list[str] = []
    builder = RecordingBuilder(
        output,
        tree,
        source,
        started_at=wall_start(start // 1000, f"{source.file}: goal {goal.index}", notes),
        attachments=attachments,
        metadata=metadata,
        tick_gap_ns=tick_gap_ns,
    )
    builder.warnings.extend(notes)
    try:
        if began:
            count = builder.begin_mid_run(began)
            builder.warnings.append(f"goal {goal.index}: {mid_run} ({count} nodes not IDLE)")
        for entry, uid in goal.entries:
            builder.logged(entry.t_ns - start, uid, entry.prev, entry.status)
    except BaseException:
        builder.close()
        output.unlink(missing_ok=True)
        raise
    builder.warnings.extend(warnings)
    if omitted:
        builder.warnings.append(f"goal {goal.index}: {omitted} {OMITTED}")
    if not goal.complete:
        builder.warnings.append(f"goal {goal.index}: {INCOMPLETE}")
    return builder.close()

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

import collections
import itertools
import os
import sys
import tempfile
from array import array
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from btlog.sources.btcpp_tree import tree_from_file, tree_from_log_xml
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    OmittedCount,
    RecordingBuilder,
    Source,
    SourceError,
    never_named,
    state_at_first_entry,
    wall_start,
)
from btlog.sources.name_matching import (
    Entry,
    check_names,
    logged_names,
    match_names_to,
    name_groups,
)
from btlog.sources.rosbag2 import Bag, open_bag
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
    message type has none) and statuses. The bag is read in passes, not held (a
    name-only log whose names the tree shares is read by ``match_names_to`` in passes
    of its own, which hold only the entries it has not decided yet)."""

    t_ns: int
    name: str
    uid: int | None
    prev: Status
    status: Status
    #: the number of the message that carried it (Nav2 publishes one a tick)
    message: int = 0


@dataclass
class BagLog:
    """What the first pass over ``/behavior_tree_log`` found (and the tree XML if the bag
    has it): counts, the names and (uid, name) pairs in order of first entry."""

    file: str
    messages: int = 0
    entries: int = 0
    tree_xml: bytes | None = None
    warnings: list[str] = field(default_factory=list)
    #: where the message definition came from: "bag", or the Nav2 releases of btlog's
    layout: str = ""
    #: the bag's storage files, in order
    files: list[str] = field(default_factory=list)
    #: the distinct (uid, name) pairs; None once an entry has no uid
    pairs: dict[tuple[int, str], None] | None = field(default_factory=dict)
    names: dict[str, None] = field(default_factory=dict)


@dataclass
class Goal:
    """One goal: its entries' count, first time, each node's previous status in its first
    entry, the changes the log leaves out and whether its result is missing."""

    index: int
    start_ns: int
    count: int = 0
    first: dict[int, Status] = field(default_factory=dict)
    omitted: OmittedCount = field(default_factory=OmittedCount)
    complete: bool = False


class GoalSplitter:
    """Splits the entries, as they are read, into goals: a goal starts when the root
    leaves IDLE after the previous goal's result, or while the log still has it running
    (that goal's end is missing). A root leaving IDLE within a goal (Nav2's RecoveryNode
    halts itself before it returns its result) does not start one. Entries before the
    first start form a goal of their own: the bag began during it."""

    def __init__(self, root: int) -> None:
        self.root = root
        self.root_status: Status = IDLE
        self.goals: list[Goal] = []

    def add(self, t_ns: int, uid: int, prev: Status, status: Status) -> None:
        """The next entry, as a uid of the tree."""
        goals = self.goals
        if uid == self.root and status is not IDLE and prev is IDLE:
            if not goals or goals[-1].complete or self.root_status is not IDLE:
                if goals:  # its count is kept; the statuses it was counted from are not
                    goals[-1].omitted.status.clear()
                goals.append(Goal(len(goals) + 1, t_ns))
        elif not goals:
            goals.append(Goal(1, t_ns))
        goal = goals[-1]
        goal.count += 1
        goal.first.setdefault(uid, prev)
        goal.omitted.add(uid, prev, status)
        if uid == self.root:
            self.root_status = status
            if status in (SUCCESS, FAILURE):
                goal.complete = True


def _status(text: str, where: str) -> Status:
    name = str(text).strip().upper()
    if name not in STATUS_NAMES:
        raise SourceError(f"{where}: unknown status {text!r}")
    return Status[name]


def _stamp_ns(stamp: object) -> int:
    return int(getattr(stamp, "sec", 0)) * 1_000_000_000 + int(getattr(stamp, "nanosec", 0))


def _check_topic(bag: Bag) -> None:
    topic = bag.topics.get(LOG_TOPIC)
    if topic is None:
        listed = ", ".join(sorted(bag.topics)) or "none"
        raise SourceError(f"{bag.path}: no {LOG_TOPIC} topic (topics: {listed})")
    if topic.type != LOG_TYPE or topic.serialization_format != "cdr":
        raise SourceError(
            f"{bag.path}: {LOG_TOPIC} has type {topic.type or '(none)'!r} "
            f"({topic.serialization_format}); expected {LOG_TYPE} (cdr)"
        )


def _read_xml(bag: Bag) -> bytes | None:
    """The bag's last tree XML message, if any (a pass over that topic only)."""
    xml = None
    for message in bag.messages({XML_TOPIC}):
        if message.type == XML_TYPE:
            xml = str(getattr(message.decoded, "data", "")).encode()
    return xml


def _scan(bag: Bag, splitter: GoalSplitter | None) -> BagLog:
    """The first pass: decode every entry of ``/behavior_tree_log`` (and the tree XML),
    keeping only counts, names and (uid, name) pairs, and feeding ``splitter`` the
    entries as uids while every entry has one; what the bag's damage cost is in the
    warnings."""
    log = BagLog(bag.path)
    pairs, names = log.pairs, log.names
    for message in bag.messages({LOG_TOPIC, XML_TOPIC}):
        if message.topic == XML_TOPIC:
            if message.type == XML_TYPE:
                log.tree_xml = str(getattr(message.decoded, "data", "")).encode()
            continue
        log.messages += 1
        where = f"{bag.path}: message {log.messages}"
        for entry in _entries(message.decoded, log.messages, where):
            log.entries += 1
            names[entry.name] = None
            if pairs is not None:
                if entry.uid is None:
                    pairs = log.pairs = None
                    splitter = None
                    continue
                pairs[(entry.uid, entry.name)] = None
                if splitter is not None:
                    splitter.add(entry.t_ns, entry.uid, entry.prev, entry.status)
    log.layout = bag.used[LOG_TOPIC].origin if LOG_TOPIC in bag.used else ""
    log.files = list(bag.files)
    return log


def _log_entries(bag: Bag) -> Iterator[LogEntry]:
    """The entries of ``/behavior_tree_log``, decoded anew (a further pass)."""
    for number, message in enumerate(bag.messages({LOG_TOPIC}), 1):
        yield from _entries(message.decoded, number, f"{bag.path}: message {number}")


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


def bag_tree(
    file: str,
    tree_xml: bytes | None,
    tree_file: str | os.PathLike | None,
    registry: Registry | None,
) -> Tree:
    """The tree of the run: ``tree_file`` (checked against the bag's XML when it has
    one), else the bag's own tree XML."""
    if tree_xml is not None:
        own = tree_from_log_xml(tree_xml, f"{file} ({XML_TOPIC})", registry)
        return own if tree_file is None else tree_from_file(tree_file, own, registry)
    if tree_file is None:
        raise SourceError(f"{file}: the bag holds no tree; give the tree file with --tree")
    try:
        return load_tree(tree_file, registry, accept_unknown=True)
    except TreeError as error:
        raise SourceError(str(error)) from None


def check_uids(pairs: Iterable[tuple[int, str]], tree: Tree, where: str) -> None:
    """``SourceError`` for the first (uid, name) of the log the tree's node of that uid
    does not have."""
    for uid, name in pairs:
        node = tree.nodes.get(uid)
        # BT.CPP names a nameless node by its ID (btlog's description); '' is older
        if node is None or name not in logged_names(node) | {node.name}:
            there = "no such node" if node is None else f"it is {node.name!r}"
            raise SourceError(
                f"{where}: the log's node {name!r} has uid {uid}, but in the "
                f"tree {there}; --tree is not the tree that ran"
            )


#: How a pass gives each entry its uid: by the entry's own uid (None), by name (each
#: unique in the tree: the name's nodes), or ``match_names_to``'s uid of each entry in
#: order, in a file (``array("q")`` bytes).
Uids = dict[str, list[int]] | Path | None
#: Uids read back from their file this many at a time.
UID_BLOCK = 1 << 16


class _Named:
    """The log's entries as ``match_names_to`` reads them, decoded anew each pass."""

    def __init__(self, bag: Bag) -> None:
        self.bag = bag

    def __iter__(self) -> Iterator[Entry]:
        return (Entry(e.name, e.prev, e.status, e.message) for e in _log_entries(self.bag))


def _name_uids(bag: Bag, log: BagLog, tree: Tree, folder: Path) -> Uids:
    """How a name-only log's entries map to the tree: by name when each is unique in the
    tree; else by ``match_names_to``, the uids written to a file in ``folder``."""
    groups = name_groups(tree)
    check_names(log.names, groups, log.file)
    if all(len(groups[name]) == 1 for name in log.names):
        return groups
    path = folder / "uids"
    with open(path, "wb") as out:
        match_names_to(_Named(bag), tree, log.file, out)
    return path


def _read_uids(path: Path) -> Iterator[int]:
    """The uids of a file of ``array("q")`` bytes, read a block at a time."""
    with open(path, "rb") as stream:
        while block := stream.read(UID_BLOCK * 8):
            yield from array("q", block)


def _with_uids(bag: Bag, uids: Uids) -> Iterator[tuple[LogEntry, int]]:
    """A pass over the log's entries, each with its uid in the tree."""
    entries = _log_entries(bag)
    if uids is None:
        return ((e, e.uid or 0) for e in entries)
    if isinstance(uids, dict):
        return ((e, uids[e.name][0]) for e in entries)
    return zip(entries, _read_uids(uids), strict=False)


def import_bag(
    path: str | os.PathLike,
    output: str | os.PathLike,
    tree_file: str | os.PathLike | None = None,
    registry: Registry | None = None,
    goal: int | None = None,
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS,
) -> list[BuildResult]:
    """Import every goal of the bag (or goal number ``goal``) as recordings: ``output``
    for one goal, else ``OUT-goalN.mcap`` beside it. The bag is read in passes (its tree
    XML, then the log to check it and split the goals, then each goal's entries into its
    recording), so memory does not grow with the log."""
    with open_bag(path) as bag, tempfile.TemporaryDirectory(prefix="btlog-") as folder:
        _check_topic(bag)
        opened = len(bag.warnings)
        tree: Tree | None = None
        tree_error: SourceError | None = None
        try:
            tree = bag_tree(bag.path, _read_xml(bag), tree_file, registry)
        except SourceError as error:  # raised after the log's own faults, as it reads
            tree_error = error
        mark = len(bag.warnings)
        splitter = GoalSplitter(tree.root.uid) if tree is not None else None
        log = _scan(bag, splitter)
        log.warnings = bag.warnings[:opened] + bag.warnings[mark:]
        if not log.entries:
            raise SourceError(f"{log.file}: {LOG_TOPIC} holds no status changes")
        if tree_error is not None or tree is None:
            raise tree_error or SourceError(f"{log.file}: the tree could not be read")
        uids: Uids = None
        matched_by = "uid"
        if log.pairs is not None:
            check_uids(log.pairs, tree, log.file)
        else:
            matched_by = "name"
            uids = _name_uids(bag, log, tree, Path(folder))
            splitter = GoalSplitter(tree.root.uid)
            for entry, uid in _with_uids(bag, uids):
                splitter.add(entry.t_ns, uid, entry.prev, entry.status)
        assert splitter is not None
        goals = splitter.goals
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
        entries = _with_uids(bag, uids)
        for item in goals:
            if item.index > chosen[-1].index:
                break
            part = itertools.islice(entries, item.count)
            if item not in chosen:
                collections.deque(part, maxlen=0)
                continue
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
            results.append(
                _build(item, part, tree, source, target, attachments, tick_gap_ns, log.warnings)
            )
        return results


def _build(
    goal: Goal,
    entries: Iterable[tuple[LogEntry, int]],
    tree: Tree,
    source: Source,
    output: Path,
    attachments: list[tuple[str, bytes]],
    tick_gap_ns: int,
    warnings: list[str],
) -> BuildResult:
    start = goal.start_ns
    first = goal.first
    began = state_at_first_entry(tree, first)
    unnamed = never_named(tree, first, began)
    # a log that begins mid-run infers the never-named ancestors too (MID_RUN says so)
    mid_run = MID_RUN if any(s is not IDLE for s in first.values()) else f"{unnamed}: {NEVER_NAMED}"
    metadata = {} if goal.complete else {"incomplete": INCOMPLETE}
    if began:
        metadata["mid_run"] = mid_run
    omitted = goal.omitted.count
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
        for entry, uid in entries:
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

"""Match a log whose entries name their nodes (no uids) to the tree's nodes.

Nav2 releases before Jazzy log ``node_name`` only, and names are not unique: Nav2's
default trees give a RecoveryNode the name of the action it recovers
("ComputePathToPose", "FollowPath"), and BT.CPP names every unnamed node by its type
("Sequence"). Each entry of a shared name is given to one of the nodes of that name so
that the log is a sequence of transitions BehaviorTree.CPP could have made:

- **chain**: an entry's previous status is the node's status (what the node's earlier
  entries left; a node's first entry tells the state the log began in). A log that
  leaves out resets to IDLE (fewer than one per ``SILENT_RESETS`` completions: Nav2
  with ``bt_log_idle_transitions`` false) may start a completed node from IDLE;
- **structure**, as BT.CPP changes statuses: a node leaves IDLE or completes only
  within its parent's tick, so when it does while its parent is not RUNNING (IDLE: a
  PipelineSequence sets its own status after ticking its children, while most controls
  set RUNNING first; or completed: ticked again), the parent changes status before any
  node outside the parent's subtree changes, and in the same tick (``Entry.group``: Nav2
  publishes a tick's entries in one message); and a node completes or resets to IDLE
  once its children are IDLE (BT.CPP resets a node's children before the node
  completes or halts; ``LEAVES_CHILDREN`` are the exceptions); a Sequence, Fallback,
  Switch... (``ONE_RUNNING``: all but the parallel controls) has one child RUNNING at
  a time;
- **order**, weaker: a Sequence, Fallback, Parallel... (``IN_ORDER``) ticks its
  children from the first and leaves their results in place, so a child of one leaves
  IDLE once its previous sibling has the result that moves the control on (SUCCESS in
  a Sequence, FAILURE in a Fallback), and an IfThenElse's branch once its condition
  chose it (not so a Switch, which runs one case, a RecoveryNode, which resets its
  first child before its recovery runs, or a control with a child BT.CPP 4 may skip).

Every reading is scored by its violations: chain first, then structure, then order,
then the nodes it assumes were not IDLE when the log began (fewest first: a log that
starts with the tree is read so). The best reading is found by dynamic programming over
the entries (``_Matcher``), in time linear in the log. Two readings with the same best
score are truly ambiguous, unless they make the same transitions in each tick in
another order (then BT.CPP's order is kept: the earlier entry to the node first in the
tree); otherwise the match is refused, naming the names whose entries could not be
told apart. More than ``MAX_READINGS`` readings alive at once are refused too.

The log is read as it comes (``match_names_to``: a pass for its names, then one or two
readings), and a choice is written out and let go as soon as every reading still
followed makes it (their common ``_Path``): later entries cannot change it, and two
readings can differ only after it, so memory grows with the log's ambiguity, not its
length.

Tested on Nav2's default trees exported as Humble bags (exact), and on random BT.CPP 4
trees whose every node is unnamed, the worst case (``tests/test_name_matching.py``): of
300, 195 read exactly, 7 with two same-tick transitions in another order, 98 refused,
none wrong.
"""

from __future__ import annotations

import itertools
from array import array
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from io import BytesIO
from typing import BinaryIO

from btlog.sources.builder import SourceError
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from btlog.tree.model import Node, Tree
from btlog.tree.registry import V3_ALIASES

#: A node of a shared name whose status the log has not told yet.
UNKNOWN = -1
#: Weights of the score's parts: chain violations, then structure, then order, then
#: assumptions about the start.
_CHAIN, _STRUCTURE, _ORDER, _ASSUMED = 1 << 96, 1 << 64, 1 << 32, 1
#: Controls (BT.CPP 3 and 4, Nav2) that tick their children from the first, and the
#: result the previous child must have before the next one is ticked.
_AFTER_SUCCESS = (int(SUCCESS),)
_AFTER_FAILURE = (int(FAILURE),)
_AFTER_ANY = (int(RUNNING), int(SUCCESS), int(FAILURE))
IN_ORDER: dict[str, tuple[int, ...]] = {
    "Sequence": _AFTER_SUCCESS,
    "SequenceWithMemory": _AFTER_SUCCESS,
    "SequenceStar": _AFTER_SUCCESS,
    "ReactiveSequence": _AFTER_SUCCESS,
    "Fallback": _AFTER_FAILURE,
    "ReactiveFallback": _AFTER_FAILURE,
    "Parallel": _AFTER_ANY,
    "ParallelAll": _AFTER_ANY,
    "PipelineSequence": (int(RUNNING), int(SUCCESS)),
}
#: Controls whose first child decides the branch: its result before each other child.
BRANCHES = {
    "IfThenElse": (_AFTER_SUCCESS, _AFTER_FAILURE),
    "WhileDoElse": (_AFTER_SUCCESS, _AFTER_FAILURE),
}
#: Controls (BT.CPP 3 and 4, Nav2) that never have two children RUNNING at once.
ONE_RUNNING = frozenset(
    {
        *IN_ORDER.keys() - {"Parallel", "ParallelAll", "PipelineSequence"},
        *BRANCHES,
        *(f"Switch{n}" for n in range(2, 7)),
        "RecoveryNode",
        "RoundRobin",
    }
)
#: Nodes that may complete with a child not IDLE: BT.CPP 4's IfThenElse leaves its
#: failed condition so when it has no else branch, a SequenceWithMemory its succeeded
#: children when it fails; Nav2's RateController resets its child after it completes.
LEAVES_CHILDREN = frozenset({"IfThenElse", "SequenceWithMemory", "SequenceStar", "RateController"})
#: A log with fewer resets to IDLE than one per this many completions leaves them out.
SILENT_RESETS = 10
#: A reading more structure violations than this behind the best one is dropped.
MARGIN = 2
#: At most this many readings are followed at once; more, and the log is refused.
MAX_READINGS = 1024
#: The readings' common choices are looked for once this many entries (at least, and
#: twice as many as after the last look) are not yet decided.
COMMIT_EVERY = 4096


@dataclass(frozen=True, slots=True)
class Entry:
    """What a name-only log says: a node's name, its previous and new status, and the
    tick (or message) it came in, ``group``."""

    name: str
    prev: Status
    status: Status
    group: int = 0


def _may_skip(node: Node) -> bool:
    """Whether BT.CPP 4 may skip the node (a ``_skipIf``/``_while`` precondition, a
    Precondition decorator): a skipped child leaves no entry, so its control's order
    tells nothing."""
    return node.type == "Precondition" or not {"_skipIf", "_while"}.isdisjoint(node.attributes)


class _Path:
    """A reading, as a linked list of the choices made for entries of shared names."""

    __slots__ = ("index", "tail", "uid")

    def __init__(self, index: int, uid: int, tail: _Path | None) -> None:
        self.index, self.uid, self.tail = index, uid, tail


def _differ(a: _Path | None, b: _Path | None) -> list[tuple[int, int, int]]:
    """Where two readings of the same entries give an entry to different nodes:
    ``(entry index, node in a, node in b)``. Every reading has a ``_Path`` for each
    entry of a shared name, so the two are walked in step, down to their common part."""
    found = []
    while a is not b and a is not None and b is not None:
        if a.uid != b.uid:
            found.append((a.index, a.uid, b.uid))
        a, b = a.tail, b.tail
    return found


def logged_names(node: Node) -> set[str]:
    """The names BT.CPP logs a node by: its name, or, nameless, its registration ID as
    the XML wrote it (BT.CPP 3's ``SequenceStar``, btlog's ``SequenceWithMemory``)."""
    names = {node.description}
    if node.name in ("", node.type):
        names |= {alias for alias, target in V3_ALIASES.items() if target == node.type}
    return names


def match_names(
    entries: Sequence[Entry], tree: Tree, where: str, every: int = COMMIT_EVERY
) -> list[int]:
    """The uid of each entry (see the module docstring); ``SourceError`` naming the file
    when a name is not in the tree, or when shared names cannot be told apart. ``every``:
    as for ``match_names_to``."""
    out = BytesIO()
    match_names_to(entries, tree, where, out, every)
    uids = array("q")
    uids.frombytes(out.getvalue())
    return uids.tolist()


def match_names_to(
    entries: Iterable[Entry], tree: Tree, where: str, out: BinaryIO, every: int = COMMIT_EVERY
) -> int:
    """``match_names`` streamed: ``entries`` is read in passes (two to three; a list, or
    an iterable that reads the log anew each time), and the uids are written to ``out``
    (from its start, as ``array("q")`` bytes) as soon as every reading still followed
    agrees on them (looked for once ``every`` entries are undecided), so memory grows
    with the log's ambiguity, not its length. Returns the most entries held at once
    (undecided)."""
    groups = name_groups(tree)
    shared: set[str] = set()
    initial: dict[int, int] = {}  # a unique name's node: its previous status at first
    resets = completions = 0
    for entry in entries:
        candidates = groups.get(entry.name)
        if candidates is None:
            check_names((entry.name,), groups, where)
            continue
        if len(candidates) > 1:
            shared.add(entry.name)
        elif candidates[0] not in initial:
            initial[candidates[0]] = int(entry.prev)
        resets += entry.status == IDLE
        completions += entry.status in (SUCCESS, FAILURE)
    # a log that leaves out resets to IDLE (Nav2's bt_log_idle_transitions false):
    # a completed node's next entry starts from IDLE, and completing nodes may keep
    # completed children
    silent_resets = completions > 0 and resets * SILENT_RESETS < completions
    out.seek(0)
    out.truncate()
    if not shared:
        sink = _Sink(out)
        for entry in entries:
            sink.add(groups[entry.name][0])
        sink.flush()
        return 0
    matcher = _Matcher(entries, tree, groups, shared, where, initial, silent_resets, every)
    matcher.run(out)
    return matcher.most_held


class _Sink:
    """Uids written to a binary file in blocks, as ``array("q")`` bytes."""

    def __init__(self, out: BinaryIO) -> None:
        self.out, self.block = out, array("q")

    def add(self, uid: int) -> None:
        """One more uid."""
        self.block.append(uid)
        if len(self.block) >= 8192:
            self.flush()

    def flush(self) -> None:
        """Write the uids held."""
        self.out.write(self.block.tobytes())
        del self.block[:]


def name_groups(tree: Tree) -> dict[str, list[int]]:
    """The uids of the tree's nodes by each name BT.CPP logs them by."""
    groups: dict[str, list[int]] = {}
    for node in tree:
        for name in logged_names(node):
            groups.setdefault(name, []).append(node.uid)
    return groups


def check_names(names: Iterable[str], groups: Mapping[str, list[int]], where: str) -> None:
    """``SourceError`` naming the file for the first of ``names`` the tree does not have."""
    for name in names:
        if name not in groups:
            raise SourceError(f"{where}: the log names node {name!r}, which the tree does not have")


class _Matcher:
    """The dynamic programme of ``match_names``. A reading's state: the statuses of the
    nodes of shared names (``UNKNOWN`` until their first entry), and a bit set of those
    nodes and their parents (the *watched* nodes) that *owe* a change (a child left IDLE
    or completed while they were not RUNNING: they are being ticked, so they change
    before any node outside their subtree does, within the tick). Readings that reach
    the same state are merged, keeping the best (``_merge``).

    The entries are read as they come (``entries`` is read once a pass); those not yet
    decided are held (``held``, from entry ``base`` on). Every so often the choices all
    readings share (their common ``_Path``, ``decided``) are written out and let go:
    no later step can change them, and readings differ only after them."""

    def __init__(
        self,
        entries: Iterable[Entry],
        tree: Tree,
        groups: dict[str, list[int]],
        shared: set[str],
        where: str,
        initial: Mapping[int, int],
        silent_resets: bool,
        every: int,
    ) -> None:
        self.entries, self.groups, self.where = entries, groups, where
        self.parent = {n.uid: (n.parent.uid if n.parent else 0) for n in tree}
        self.children = {n.uid: [c.uid for c in n.children] for n in tree}
        self.leaves_children = {n.uid for n in tree if n.type in LEAVES_CHILDREN}
        self.exclusive = {n.uid for n in tree if n.type in ONE_RUNNING}
        #: the sibling that must have run before a node, and the results it may have had
        self.earlier: dict[int, tuple[int, tuple[int, ...]]] = {}
        order = list(tree)
        skips: dict[int, bool] = {}  # a node BT.CPP may skip in the subtree
        for node in reversed(order):
            skips[node.uid] = _may_skip(node) or any(skips[c.uid] for c in node.children)
        for node in order:
            kids = self.children[node.uid]
            if skips[node.uid]:
                continue
            if node.type in IN_ORDER:
                for before, after in itertools.pairwise(kids):
                    self.earlier[after] = (before, IN_ORDER[node.type])
            elif node.type in BRANCHES:
                for branch, results in zip(kids[1:], BRANCHES[node.type], strict=False):
                    self.earlier[branch] = (kids[0], results)
        # the subtree of a node: the pre-order positions from its own to its last descendant
        self.first: dict[int, int] = {}
        self.last: dict[int, int] = {}
        for position, node in enumerate(order):
            self.first[node.uid] = position
        for node in reversed(order):
            kids = self.children[node.uid]
            self.last[node.uid] = self.last[kids[-1]] if kids else self.first[node.uid]
        ambiguous = sorted(uid for name in shared for uid in groups[name])
        self.a_index = {uid: i for i, uid in enumerate(ambiguous)}
        watched = sorted(set(ambiguous) | {self.parent[u] for u in ambiguous} - {0})
        self.bit = {uid: 1 << i for i, uid in enumerate(watched)}
        self.watched = watched
        # nodes of unique names: their status is the same in every reading; the log
        # says what it was at its start
        self.initial: dict[int, int] = {n.uid: int(IDLE) for n in tree}
        self.initial.update(initial)
        self.status = dict(self.initial)
        self.silent_resets = silent_resets
        self.held: list[Entry] = []
        self.base = 0
        self.decided: _Path | None = None
        self.most_held = 0
        self.every = every
        self.sink: _Sink | None = None

    # -- one step -------------------------------------------------------------------------
    def _of(self, uid: int, statuses: Sequence[int]) -> int:
        at = self.a_index.get(uid)
        return self.status[uid] if at is None else statuses[at]

    def _inside(self, uid: int, ancestor: int) -> bool:
        return self.first[ancestor] <= self.first[uid] <= self.last[ancestor]

    def _pin(self, statuses: list[int], uid: int, status: int) -> int:
        """Settle an UNKNOWN node's status since the start (in place): the cost of the
        assumption, and, for a node not IDLE, its UNKNOWN ancestors' RUNNING (BT.CPP
        ticks a node only through running ancestors) counted alike."""
        cost = 0
        while True:
            at = self.a_index.get(uid)
            if at is None or statuses[at] != UNKNOWN:
                return cost
            statuses[at] = status
            if status == IDLE:
                return cost
            cost += _ASSUMED
            uid, status = self.parent[uid], int(RUNNING)

    def _apply(
        self, uid: int, entry: Entry, state: tuple[tuple[int, ...], int]
    ) -> list[tuple[int, tuple[tuple[int, ...], int]]]:
        """The cost of giving ``entry`` to ``uid`` in a reading, and its state after:
        one outcome, or two when the status of an UNKNOWN parent decides (RUNNING since
        the start, or IDLE and owing a change)."""
        statuses, owing = list(state[0]), state[1]
        prev, new = int(entry.prev), int(entry.status)
        cost = 0
        now = self._of(uid, statuses)
        if now == UNKNOWN:
            cost += self._pin(statuses, uid, prev)
        elif now != prev and not (self.silent_resets and prev == IDLE and now > RUNNING):
            cost += _CHAIN
        kids = self.children[uid]
        if new != RUNNING and kids and uid not in self.leaves_children:
            for child in kids:
                status = self._of(child, statuses)
                if status == UNKNOWN:  # it completes or resets: its children are IDLE
                    self._pin(statuses, child, int(IDLE))
                elif status == RUNNING or (status > IDLE and not self.silent_resets):
                    cost += _STRUCTURE
                    break
        parent_uid = self.parent[uid]
        if (
            new == RUNNING
            and prev != RUNNING
            and parent_uid in self.exclusive
            and any(self._of(c, statuses) == RUNNING for c in self.children[parent_uid])
        ):
            cost += _STRUCTURE
        if prev == IDLE and new != IDLE:
            earlier = self.earlier.get(uid)
            if earlier is not None and self._of(earlier[0], statuses) not in (
                UNKNOWN,
                *earlier[1],
            ):
                cost += _ORDER
        if owing:  # a node that owes a change and is left for one outside its subtree
            for watched in self.watched:
                mask = self.bit[watched]
                if owing & mask and not self._inside(uid, watched):
                    cost += _STRUCTURE
                    owing &= ~mask
        at = self.a_index.get(uid)
        if at is not None:
            statuses[at] = new
        owing &= ~self.bit.get(uid, 0)
        up = self.bit.get(parent_uid, 0)
        # A reset is not counted: BT.CPP resets a child left behind (``LEAVES_CHILDREN``)
        # when it halts the tree, whatever its parent's status.
        if not up or new == IDLE:
            return [(cost, (tuple(statuses), owing))]
        parent = self._of(parent_uid, statuses)
        if parent == UNKNOWN:  # running since the start, or starting now (owing)
            running = list(statuses)
            assumed = self._pin(running, parent_uid, int(RUNNING))
            self._pin(statuses, parent_uid, int(IDLE))
            return [
                (cost + assumed, (tuple(running), owing)),
                (cost, (tuple(statuses), owing | up)),
            ]
        # IDLE: ticking its first child; completed: ticked again
        if parent != RUNNING:
            owing |= up
        return [(cost, (tuple(statuses), owing))]

    def _prune(
        self, readings: dict[tuple, tuple[int, _Path | None, frozenset[str]]], entry: Entry
    ) -> dict[tuple, tuple[int, _Path | None, frozenset[str]]]:
        """The readings worth following: those at most ``MARGIN`` structure violations
        behind the best (and none with more chain violations). More than
        ``MAX_READINGS`` left: the log is refused (the best could not be told from the
        others in bounded time)."""
        best = min(cost for cost, _path, _unclear in readings.values())
        bound = best - best % _STRUCTURE + (MARGIN + 1) * _STRUCTURE
        kept = {k: v for k, v in readings.items() if v[0] < bound}
        if len(kept) > MAX_READINGS:
            raise SourceError(
                f"{self.where}: the log has no uids, and it fits more than {MAX_READINGS} "
                f"readings of its shared names (at an entry of {entry.name!r}); name the "
                "nodes apart in the tree, or record with uids (Nav2 Jazzy and later)"
            )
        return kept

    def _doubts(self, a: _Path | None, b: _Path | None) -> tuple[set[str], bool]:
        """The names of the entries two equally good readings disagree on (all held:
        readings differ only after their decided part), and whether ``a`` is the
        one to keep. Two readings that make the same transitions in each tick, in another
        order, leave no doubt (a control and its child both leaving IDLE: which came
        first changes no state between ticks); the kept one has BT.CPP's order: a
        control's RUNNING before its descendant's (it sets RUNNING before it ticks a
        child), a descendant's result or reset before its ancestor's, else the node
        first in the tree first."""
        differ = _differ(a, b)
        if not differ:
            return set(), False
        held, base = self.held, self.base
        mine = sorted(
            (held[i - base].group, x, held[i - base].prev, held[i - base].status)
            for i, x, _ in differ
        )
        theirs = sorted(
            (held[i - base].group, y, held[i - base].prev, held[i - base].status)
            for i, _, y in differ
        )
        if mine != theirs:
            return {held[i - base].name for i, _x, _y in differ}, False
        first, x, y = differ[-1]
        entry = held[first - base]
        if entry.prev == IDLE and entry.status == RUNNING:  # a control sets RUNNING first
            return set(), self.first[x] < self.first[y]
        # a node completes or resets after its children (and a Parallel's in order)
        if self._inside(x, y) or self._inside(y, x):
            return set(), self.first[x] > self.first[y]
        return set(), self.first[x] < self.first[y]

    def run(self, out: BinaryIO) -> None:
        """Write the uid of each entry to ``out`` (truncated first, ``array("q")``
        bytes); ``SourceError`` when the best reading is not unique.
        A log whose nodes of unique names all start IDLE is first read as starting
        with the tree (every node IDLE); if no reading of it then fits the chain, or the
        log begins mid-run, the nodes of shared names start *unknown* (what their first
        entry says, each non-IDLE start counted)."""
        readings = None
        if all(status == IDLE for status in self.initial.values()):
            readings = self._read(int(IDLE), out)
            if min(cost for cost, _path, _unclear in readings.values()) >= _CHAIN:
                readings = None
        if readings is None:
            readings = self._read(UNKNOWN, out)
        best = min(cost for cost, _path, _unclear in readings.values())
        ends = [(path, unclear) for cost, path, unclear in readings.values() if cost == best]
        path, unclear = ends[0]
        doubts = set(unclear)
        for other, other_unclear in ends[1:]:
            differ, better = self._doubts(other, path)
            doubts |= other_unclear | differ
            path = other if better else path
        if doubts:
            listed = ", ".join(repr(n) for n in sorted(doubts))
            raise SourceError(
                f"{self.where}: the log has no uids, and its entries named {listed} fit "
                "several nodes of that name equally well (the tree's structure cannot "
                "tell them apart)"
            )
        self.most_held = max(self.most_held, len(self.held))
        self._decide(path, len(self.held))
        assert self.sink is not None
        self.sink.flush()

    def _decide(self, path: _Path | None, count: int) -> None:
        """Write the uids of the first ``count`` held entries, ``path`` being the
        readings' common choice for the last of them that has one, and let them go."""
        assert self.sink is not None
        chosen: dict[int, int] = {}
        node = path
        while node is not None and node is not self.decided:
            chosen[node.index] = node.uid
            node = node.tail
        for index, entry in enumerate(self.held[:count], self.base):
            self.sink.add(chosen.get(index, self.groups[entry.name][0]))
        del self.held[:count]
        self.base += count
        if path is not None:
            path.tail = None  # nothing behind the decided part is looked at again
            self.decided = path

    def _commit(self, readings: dict[tuple, tuple[int, _Path | None, frozenset[str]]]) -> None:
        """Decide the choices all ``readings`` share (their paths' common node)."""
        paths = {id(p): p for _cost, p, _unclear in readings.values()}
        while len(paths) > 1:
            paths = {id(p.tail): p.tail for p in paths.values() if p is not None}
        (common,) = paths.values()
        if common is not None and common is not self.decided:
            self._decide(common, common.index + 1 - self.base)

    def _read(
        self, start: int, out: BinaryIO
    ) -> dict[tuple, tuple[int, _Path | None, frozenset[str]]]:
        """The best readings of the log, the nodes of shared names starting ``start``
        (the uids decided on the way written to ``out``, from its start)."""
        out.seek(0)
        out.truncate()
        self.sink = _Sink(out)
        self.held, self.base, self.decided = [], 0, None
        self.status = dict(self.initial)
        statuses = [start] * len(self.a_index)
        assumed = 0
        for uid, status in self.initial.items():  # running ancestors of unique names
            if status != IDLE and uid not in self.a_index:
                assumed += self._pin(statuses, self.parent[uid], int(RUNNING))
        # state -> (cost, reading, entry indexes found ambiguous)
        readings: dict[tuple, tuple[int, _Path | None, frozenset[str]]] = {
            (tuple(statuses), 0): (assumed, None, frozenset())
        }
        group: int | None = None
        look = self.every
        for index, entry in enumerate(self.entries):
            if len(self.held) >= look:
                self.most_held = max(self.most_held, len(self.held))
                self._commit(readings)
                look = max(self.every, 2 * len(self.held))
            self.held.append(entry)
            if group is None:
                group = entry.group
            elif entry.group != group:  # a new tick: every change owed is a violation
                group = entry.group
                if any(owing for _statuses, owing in readings):
                    readings = self._tick_ends(readings)
            candidates = self.groups[entry.name]
            if len(candidates) == 1:
                uid = candidates[0]
                watched = uid in self.bit or self.parent[uid] in self.bit
                if not watched and not any(owing for _statuses, owing in readings):
                    self.status[uid] = int(entry.status)
                    continue
            following: dict[tuple, tuple[int, _Path | None, frozenset[str]]] = {}
            for state, (cost, path, unclear) in readings.items():
                for uid in candidates:
                    chosen = path if len(candidates) == 1 else _Path(index, uid, path)
                    for step, after in self._apply(uid, entry, state):
                        self._merge(following, after, cost + step, chosen, unclear)
            if len(candidates) == 1:
                self.status[candidates[0]] = int(entry.status)
            readings = self._prune(following, entry)
        if any(owing for _statuses, owing in readings):
            readings = self._tick_ends(readings)
        return readings

    def _tick_ends(
        self, readings: dict[tuple, tuple[int, _Path | None, frozenset[str]]]
    ) -> dict[tuple, tuple[int, _Path | None, frozenset[str]]]:
        """The readings once a tick is over: each change still owed is a violation."""
        following: dict[tuple, tuple[int, _Path | None, frozenset[str]]] = {}
        for (statuses, owing), (cost, path, unclear) in readings.items():
            total = cost + owing.bit_count() * _STRUCTURE
            self._merge(following, (statuses, 0), total, path, unclear)
        return following

    def _merge(
        self,
        readings: dict[tuple, tuple[int, _Path | None, frozenset[str]]],
        state: tuple,
        cost: int,
        path: _Path | None,
        unclear: frozenset[str],
    ) -> None:
        """Keep the better of two readings that reach the same state; two equally good
        ones that differ are a doubt (``_doubts``) from then on."""
        known = readings.get(state)
        if known is None or cost < known[0]:
            readings[state] = (cost, path, unclear)
        elif cost == known[0] and known[1] is not path:
            doubts, better = self._doubts(path, known[1])
            both = frozenset(unclear | known[2] | doubts)
            readings[state] = (cost, path if better else known[1], both)

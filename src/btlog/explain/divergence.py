"""Divergence between two behaviours: where does what one run did differ from another?

A behaviour is its list of executed actions (each activation of an execution node, in
event order). The tree's subgoals cut it into short pieces; for each subgoal the two
action sequences are compared with the O(NP) algorithm (``btlog.algorithms``): what is
outside the longest common subsequence is divergent, shown with its immediate parent
as in the paper's Fig. 14 (section 7.2.1). Actions compare by description ``d(n)``, so
the same step in two versions of a tree matches even when its uid moved. Where the
behaviours come from is ``btlog.checks.behaviours`` (a recording, or a tree run
with every leaf succeeding: running trees is not the explanations' job); the text is
``btlog.render``.
See docs/design.md, "Divergence".
"""

from __future__ import annotations

import json
import re
from array import array
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, overload

from btlog.algorithms.sequence_diff import Comparison, TooCostly, compare
from btlog.events import StatusChange, TreeMutation
from btlog.explain.hierarchy import subgoal_of
from btlog.state import StateProjection
from btlog.status import FAILURE, IDLE, SKIPPED, SUCCESS
from btlog.tree.model import Node, Tree

__all__ = [
    "ActionList",
    "Cut",
    "Divergence",
    "ExecutedAction",
    "Move",
    "Row",
    "Rows",
    "SubgoalDivergence",
    "actions_from_events",
    "compare_subgoal",
    "diverge",
    "iter_json",
    "to_json",
]


@dataclass(frozen=True)
class ExecutedAction:
    """One activation of an execution node.

    ``description`` is d(n); ``parent`` is d(parent) (the immediate parent, shown beside a
    divergent action); ``subgoal`` is d(its subgoal: ``hierarchy.subgoal_node``), or
    d(root) when the node has none. ``result`` is how the activation ended
    (SUCCESS/FAILURE), or None when it was halted or the behaviour stopped first.
    """

    seq: int
    uid: int
    description: str
    type: str
    kind: str
    parent: str
    parent_uid: int | None
    subgoal: str
    result: str | None = None

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {
            "seq": self.seq,
            "uid": self.uid,
            "action": self.description,
            "type": self.type,
            "kind": self.kind,
            "parent": self.parent,
            "parent_uid": self.parent_uid,
            "subgoal": self.subgoal,
            "result": self.result,
        }


def _action(seq: int, node: Node, tree: Tree) -> ExecutedAction:
    """The executed action of ``node`` starting at event ``seq``."""
    subgoal = subgoal_of(node, tree)
    parent = node.parent
    return ExecutedAction(
        seq=seq,
        uid=node.uid,
        description=node.description,
        type=node.type,
        kind=node.kind,
        parent=parent.description if parent else "",
        parent_uid=parent.uid if parent else None,
        subgoal=subgoal.description,
    )


_RESULTS = (None, SUCCESS.name, FAILURE.name)


class ActionList(Sequence[ExecutedAction]):
    """Executed actions stored compactly (about 13 bytes each): the event seq, the index
    of what the action is (an ``ExecutedAction`` with no seq nor result, kept once in
    ``kinds``, a table shared by the lists cut from this one) and the result, in arrays;
    an ``ExecutedAction`` is made when one is looked at, so a day-long run fits."""

    def __init__(self, kinds: list[ExecutedAction] | None = None) -> None:
        self.kinds: list[ExecutedAction] = [] if kinds is None else kinds
        self.seqs = array("q")
        self.kind_of = array("i")
        self.results = array("b")

    def __len__(self) -> int:
        return len(self.seqs)

    @overload
    def __getitem__(self, index: int) -> ExecutedAction: ...
    @overload
    def __getitem__(self, index: slice) -> list[ExecutedAction]: ...
    def __getitem__(self, index: int | slice) -> ExecutedAction | list[ExecutedAction]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        kind = self.kinds[self.kind_of[index]]
        return replace(kind, seq=self.seqs[index], result=_RESULTS[self.results[index]])

    def append(self, seq: int, kind: int) -> None:
        """Add an action of kind ``kinds[kind]`` starting at ``seq`` (no result yet)."""
        self.seqs.append(seq)
        self.kind_of.append(kind)
        self.results.append(0)

    def descriptions(self) -> list[str]:
        """d(n) of every action, in order (the strings are shared, not copied)."""
        kinds = self.kinds
        return [kinds[k].description for k in self.kind_of]

    def subgoals(self) -> dict[str, ActionList]:
        """The actions cut by subgoal, in order of first appearance."""
        groups: dict[str, ActionList] = {}
        for index, kind in enumerate(self.kind_of):
            name = self.kinds[kind].subgoal
            group = groups.get(name)
            if group is None:
                group = groups[name] = ActionList(self.kinds)
            group.seqs.append(self.seqs[index])
            group.kind_of.append(kind)
            group.results.append(self.results[index])
        return groups


def actions_from_events(tree: Tree, events: Iterable) -> ActionList:
    """The executed actions of a run of ``tree`` (the tree at the start) given its events
    (folded once: an iterator streams).

    The events are folded through a ``StateProjection`` so that the tree's shape follows
    recorded mutations; an activation is an execution node's transition out of IDLE.
    """
    projection = StateProjection(tree)
    actions = ActionList()
    kinds: dict[ExecutedAction, int] = {}
    known: dict[int, int] = {}  # uid -> kind while the tree's shape has not changed
    open_: dict[int, int] = {}
    for event in events:
        projection.apply(event)
        if type(event) is not StatusChange:
            if type(event) is TreeMutation:
                known.clear()
            continue
        kind = known.get(event.uid)
        if kind is None:
            node = projection.tree.nodes.get(event.uid)
            if node is None or not node.is_execution:
                continue
            found = _action(0, node, projection.tree)
            kind = kinds.setdefault(found, len(kinds))
            if kind == len(actions.kinds):
                actions.kinds.append(found)
            known[event.uid] = kind
        if event.prev is IDLE and event.status not in (IDLE, SKIPPED):
            open_[event.uid] = len(actions)
            actions.append(event.seq, kind)
        if event.status in (SUCCESS, FAILURE) and event.uid in open_:
            actions.results[open_.pop(event.uid)] = 1 if event.status is SUCCESS else 2
        elif event.status is IDLE:
            open_.pop(event.uid, None)
    return actions


# -- the comparison ------------------------------------------------------------------------
@dataclass(frozen=True)
class Row:
    """One row of a side-by-side alignment: ``op`` is "equal" (both sides), "only_a" or
    "only_b" (a divergent action, present on one side only)."""

    op: str
    a: ExecutedAction | None
    b: ExecutedAction | None
    a_index: int | None = None
    b_index: int | None = None

    @property
    def action(self) -> ExecutedAction:
        """The row's action: A's, or B's when only B has it."""
        found = self.a if self.a is not None else self.b
        if found is None:
            raise ValueError("a row with no action on either side")
        return found

    @property
    def divergent(self) -> bool:
        """True when the action is on one side only."""
        return self.op != "equal"

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {
            "op": self.op,
            "a": self.a.to_json() if self.a else None,
            "b": self.b.to_json() if self.b else None,
        }


@dataclass(frozen=True)
class Move:
    """An action that B does at another place than A: ``direction`` "later" or "earlier",
    ``past`` the common actions it moved past."""

    action: str
    direction: str
    past: tuple[str, ...]

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {"action": self.action, "direction": self.direction, "past": list(self.past)}


#: At most this many actions (both sides) after a subgoal's first divergence are aligned
#: whole, and the O(NP) search keeps at most this many path nodes (about 90 bytes each).
ALIGNED_LIMIT = 2_000_000
#: Past ``ALIGNED_LIMIT``, only this many actions of each side after the first divergence
#: are aligned (at most about 3 million path nodes whatever they are).
WINDOW = 1000


@dataclass(frozen=True)
class Cut:
    """What a subgoal's comparison left out: the last ``a`` actions of A and ``b`` of B,
    past the ``WINDOW`` aligned after the first divergence (see ``compare_subgoal``)."""

    a: int
    b: int

    def to_json(self) -> dict:
        """JSON-ready form (with the window)."""
        return {"window": WINDOW, "a": self.a, "b": self.b}

    def text(self) -> str:
        """E.g. ``compared 1000 actions of each side past the first divergence; the next
        5 of A and 7 of B are not compared``."""
        return (
            f"compared {WINDOW} actions of each side past the first divergence; the next "
            f"{self.a} of A and {self.b} of B are not compared"
        )


@dataclass(frozen=True)
class SubgoalDivergence:
    """The comparison of one subgoal's actions in behaviours A and B."""

    subgoal: str
    a_actions: Sequence[ExecutedAction]
    b_actions: Sequence[ExecutedAction]
    #: the actions after the common ``prefix`` compared (``compare_subgoal``)
    comparison: Comparison
    #: how many first actions both sides share (equal rows, not held by ``comparison``)
    prefix: int = 0
    #: the actions left out of the alignment when what follows the prefix was too long
    cut: Cut | None = None

    @property
    def rows(self) -> Rows:
        """The side-by-side alignment, one ``Row`` per aligned pair (made when looked at)."""
        return Rows(self.prefix, self.comparison, self.a_actions, self.b_actions)

    @property
    def lcs_length(self) -> int:
        """The length of ``lcs`` (without building it)."""
        return self.prefix + self.comparison.lcs_length

    @property
    def edit_distance(self) -> int:
        """Insertions plus deletions turning A's action descriptions into B's."""
        return self.comparison.edit_distance

    @property
    def lcs(self) -> tuple[str, ...]:
        """A longest common subsequence of the action descriptions."""
        shared = [self.a_actions[i].description for i in range(self.prefix)]
        return (*shared, *self.comparison.lcs)

    @property
    def diverges(self) -> bool:
        """True when the two sequences differ."""
        return self.edit_distance > 0

    @property
    def only_a(self) -> list[ExecutedAction]:
        """Divergent actions of A (not in the LCS), in order."""
        return [row.action for row in self.rows if row.op == "only_a"]

    @property
    def only_b(self) -> list[ExecutedAction]:
        """Divergent actions of B (not in the LCS), in order."""
        return [row.action for row in self.rows if row.op == "only_b"]

    @property
    def moves(self) -> list[Move]:
        """Actions divergent on both sides: the same action at another place in B.

        The n-th divergent occurrence in A of a description is paired with its n-th
        divergent occurrence in B; the actions both agree on between the two places are
        what it moved past (for two swapped actions: the other one).
        """
        pending: dict[str, list[int]] = {}
        for position, row in enumerate(self.rows):
            if row.op == "only_a":
                pending.setdefault(row.action.description, []).append(position)
        moves = []
        for position, row in enumerate(self.rows):
            starts = pending.get(row.action.description) if row.op == "only_b" else None
            if starts:
                start = starts.pop(0)
                low, high = sorted((start, position))
                past = tuple(
                    r.action.description for r in self.rows[low + 1 : high] if r.op == "equal"
                )
                moves.append(
                    Move(row.action.description, "later" if start < position else "earlier", past)
                )
        return moves

    @property
    def moved(self) -> list[str]:
        """Descriptions of the moved actions (see ``moves``)."""
        return list(dict.fromkeys(move.action for move in self.moves))

    def to_json(self, streamed: bool = False) -> dict:
        """JSON-ready form; ``streamed`` leaves placeholders for ``lcs`` and ``rows``
        (``iter_json`` writes them one at a time)."""
        listed = [] if streamed else list(_divergent_items(self))
        return {
            "subgoal": self.subgoal,
            "edit_distance": self.edit_distance,
            "lcs": _placeholder("lcs") if streamed else list(self.lcs),
            "lcs_length": self.lcs_length,
            "a_count": len(self.a_actions),
            "b_count": len(self.b_actions),
            "divergent": _placeholder("divergent") if streamed else listed,
            "moved": [m.to_json() for m in self.moves],
            "rows": _placeholder("rows") if streamed else [row.to_json() for row in self.rows],
            **({} if self.cut is None else {"cut": self.cut.to_json()}),
        }


def _divergent_items(found: SubgoalDivergence) -> Iterator[dict]:
    """The divergent actions of ``found`` as JSON: A's, then B's."""
    yield from (_divergent_json(row) for row in found.rows if row.op == "only_a")
    yield from (_divergent_json(row) for row in found.rows if row.op == "only_b")


def _divergent_json(row: Row) -> dict:
    side, index = ("a", row.a_index) if row.a else ("b", row.b_index)
    action = row.action
    return {
        "side": side,
        "index": index,
        "action": action.description,
        "parent": action.parent,
        "seq": action.seq,
        "uid": action.uid,
    }


@dataclass(frozen=True)
class Divergence:
    """Behaviours A and B compared subgoal by subgoal (in order of first appearance)."""

    a_label: str
    b_label: str
    subgoals: tuple[SubgoalDivergence, ...]

    @property
    def edit_distance(self) -> int:
        """The sum of the subgoals' edit distances."""
        return sum(s.edit_distance for s in self.subgoals)

    @property
    def identical(self) -> bool:
        """True when no subgoal diverges."""
        return self.edit_distance == 0

    @property
    def divergent_subgoals(self) -> list[SubgoalDivergence]:
        """The subgoals whose action sequences differ."""
        return [s for s in self.subgoals if s.diverges]

    def subgoal(self, description: str) -> SubgoalDivergence:
        """The comparison of one subgoal (KeyError if neither behaviour has it)."""
        for found in self.subgoals:
            if found.subgoal == description:
                return found
        raise KeyError(description)


def _group(actions: Sequence[ExecutedAction]) -> Mapping[str, Sequence[ExecutedAction]]:
    if isinstance(actions, ActionList):
        return actions.subgoals()
    groups: dict[str, list[ExecutedAction]] = {}
    for action in actions:
        groups.setdefault(action.subgoal, []).append(action)
    return groups


_OPS = {"equal": "equal", "delete": "only_a", "insert": "only_b"}


class Rows(Sequence[Row]):
    """The rows of a subgoal's alignment, each made from its aligned pair when looked at
    (a day-long run's rows are never all held at once)."""

    def __init__(
        self,
        prefix: int,
        comparison: Comparison,
        a: Sequence[ExecutedAction],
        b: Sequence[ExecutedAction],
    ) -> None:
        self._prefix, self._ops, self._a, self._b = prefix, comparison.alignment.ops, a, b

    def __len__(self) -> int:
        return self._prefix + len(self._ops)

    @overload
    def __getitem__(self, index: int) -> Row: ...
    @overload
    def __getitem__(self, index: slice) -> list[Row]: ...
    def __getitem__(self, index: int | slice) -> Row | list[Row]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        if index < 0:
            index += len(self)
        prefix = self._prefix
        if 0 <= index < prefix:
            return Row("equal", self._a[index], self._b[index], index, index)
        pair = self._ops[index - prefix]
        i = None if pair.a_index is None else pair.a_index + prefix
        j = None if pair.b_index is None else pair.b_index + prefix
        left = self._a[i] if i is not None else None
        right = self._b[j] if j is not None else None
        return Row(_OPS[pair.op], left, right, i, j)

    def __iter__(self) -> Iterator[Row]:
        return (self[i] for i in range(len(self)))


def _descriptions(actions: Sequence[ExecutedAction]) -> list[str]:
    if isinstance(actions, ActionList):
        return actions.descriptions()
    return [x.description for x in actions]


def compare_subgoal(
    subgoal: str,
    a: Sequence[ExecutedAction],
    b: Sequence[ExecutedAction],
    limit: int | None = None,
) -> SubgoalDivergence:
    """Compare one subgoal's actions of A and B by description: the common prefix is
    walked first (side by side, as equal rows: the O(NP) search would take the same
    snake), then what follows is compared with the O(NP) algorithm — whole when at most
    ``limit`` actions (``ALIGNED_LIMIT`` by default) follow and the search keeps at most
    ``limit`` path nodes, else a ``WINDOW`` of each side (``cut`` says what is left)."""
    left, right = _descriptions(a), _descriptions(b)
    prefix, shortest = 0, min(len(left), len(right))
    while prefix < shortest and left[prefix] == right[prefix]:
        prefix += 1
    rest_a, rest_b = len(left) - prefix, len(right) - prefix
    cut = None
    try:
        limit = ALIGNED_LIMIT if limit is None else limit
        if rest_a + rest_b > limit:
            raise TooCostly(f"more than {limit} actions after the first divergence")
        comparison = compare(left[prefix:], right[prefix:], budget=limit)
    except TooCostly:
        end_a, end_b = prefix + min(rest_a, WINDOW), prefix + min(rest_b, WINDOW)
        comparison = compare(left[prefix:end_a], right[prefix:end_b])
        if end_a < len(left) or end_b < len(right):
            cut = Cut(len(left) - end_a, len(right) - end_b)
    del left, right
    keep_a = a if isinstance(a, ActionList) else tuple(a)
    keep_b = b if isinstance(b, ActionList) else tuple(b)
    return SubgoalDivergence(subgoal, keep_a, keep_b, comparison, prefix, cut)


def diverge(
    a_actions: Sequence[ExecutedAction],
    b_actions: Sequence[ExecutedAction],
    a_label: str = "A",
    b_label: str = "B",
) -> Divergence:
    """Compare two behaviours subgoal by subgoal.

    Subgoals come in order of first appearance in A, then those only B has. A subgoal
    only one behaviour reached is compared with an empty sequence.
    """
    groups_a, groups_b = _group(a_actions), _group(b_actions)
    names = list(dict.fromkeys([*groups_a, *groups_b]))
    left = ALIGNED_LIMIT  # shared by the subgoals: what all their alignments may hold
    subgoals = []
    for name in names:
        found = compare_subgoal(name, groups_a.get(name, []), groups_b.get(name, []), left)
        left = max(0, left - len(found.comparison.alignment))
        subgoals.append(found)
    return Divergence(a_label, b_label, tuple(subgoals))


def to_json(divergence: Divergence, streamed: bool = False) -> dict:
    """The divergence as a JSON-ready dict (``btlog diff --json``; ``streamed``: see
    ``iter_json``)."""
    return {
        "a": divergence.a_label,
        "b": divergence.b_label,
        "edit_distance": divergence.edit_distance,
        "identical": divergence.identical,
        "subgoals": [s.to_json(streamed) for s in divergence.subgoals],
    }


def _placeholder(name: str) -> str:
    return f"\0{name}\0"


#: Where a streamed list stands in ``json.dumps(..., indent=2)`` of ``to_json``: inside a
#: subgoal (depth 3), its items at depth 4.
_ITEM_INDENT = " " * 8


def _json_list(items: Iterator[Any]) -> Iterator[str]:
    """A list as ``json.dumps(indent=2)`` writes it at a subgoal's key, item by item."""
    first = True
    for item in items:
        text = json.dumps(item, indent=2).replace("\n", "\n" + _ITEM_INDENT)
        yield ("[\n" if first else ",\n") + _ITEM_INDENT + text
        first = False
    yield "[]" if first else "\n" + _ITEM_INDENT[:-2] + "]"


def _lcs_items(found: SubgoalDivergence) -> Iterator[str]:
    """``found.lcs`` one description at a time."""
    yield from (found.a_actions[i].description for i in range(found.prefix))
    yield from found.comparison.lcs


def iter_json(divergence: Divergence) -> Iterator[str]:
    """The text of ``json.dumps(to_json(divergence), indent=2)`` in pieces: the LCS, the
    divergent actions and the rows of each subgoal are written one at a time (a day-long
    run's are never held)."""
    text = json.dumps(to_json(divergence, streamed=True), indent=2)
    lists = {
        "lcs": iter([_lcs_items(found) for found in divergence.subgoals]),
        "divergent": iter([_divergent_items(found) for found in divergence.subgoals]),
        "rows": iter([(row.to_json() for row in found.rows) for found in divergence.subgoals]),
    }
    tokens = {json.dumps(_placeholder(name)): name for name in lists}
    pattern = "(" + "|".join(re.escape(token) for token in tokens) + ")"
    for index, piece in enumerate(re.split(pattern, text)):
        if index % 2:
            yield from _json_list(next(lists[tokens[piece]]))
        else:
            yield piece

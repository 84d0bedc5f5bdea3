"""The tree model: the structure of a behavior tree as plain data.

A tree is what the XML describes once subtrees are expanded: nodes with a registration
type, an instance name, a kind (control, decorator, subtree, action, condition), their
ports as written, and their children. UIDs follow BehaviorTree.CPP v4 (DFS pre-order from
1, a subtree's nodes right after its SubTree node), so that btlog's logs line up with
BT.CPP's own.

The model holds no behaviour and no run-time status. The executor builds behaviours
from it; the explanation algorithms read it beside a state; the recorder writes it as
the ``/btlog/tree`` message and the reader rebuilds it from that message. Dynamic
insertion (the paper's Algorithm 9) is a change of this model, described by a
``TreeMutation`` event so that a replay can apply it too.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass, field
from typing import Any, TypeVar, cast

from btlog.limits import MAX_DEPTH

T = TypeVar("T")

CONTROL = "control"
DECORATOR = "decorator"
SUBTREE = "subtree"
ACTION = "action"
CONDITION = "condition"
KINDS = (CONTROL, DECORATOR, SUBTREE, ACTION, CONDITION)
EXECUTION_KINDS = (ACTION, CONDITION)

INPUT = "input"
OUTPUT = "output"
INOUT = "inout"


@dataclass(frozen=True)
class Port:
    """One port of a node instance: its value as written and its direction."""

    value: str
    direction: str = INPUT

    @property
    def key(self) -> str | None:
        """The blackboard key when the value is a ``{key}`` reference, else None."""
        return blackboard_key(self.value)


def blackboard_key(value: str) -> str | None:
    """Return the key of a ``{key}`` reference (BT.CPP's isBlackboardPointer), else None."""
    text = value.strip()
    if len(text) >= 3 and text[0] == "{" and text[-1] == "}":
        return text[1:-1].strip()
    return None


@dataclass(eq=False)
class Node:
    """One node of a tree, as loaded; identity is the object (uids are unique per tree)."""

    uid: int
    type: str
    name: str
    kind: str
    ports: dict[str, Port] = field(default_factory=dict)
    attributes: dict[str, str] = field(default_factory=dict)
    children: list[Node] = field(default_factory=list)
    parent: Node | None = None
    path: str = ""
    scope: str = ""
    file: str = ""
    line: int = 0
    added_seq: int | None = None

    @property
    def description(self) -> str:
        """d(n) of the paper: the name, or the registration type when the name is empty."""
        return self.name or self.type

    @property
    def is_execution(self) -> bool:
        """True for actions and conditions (the paper's execution nodes)."""
        return self.kind in EXECUTION_KINDS

    @property
    def index(self) -> int:
        """Position among the parent's children (0 for the root)."""
        return 0 if self.parent is None else self.parent.children.index(self)

    @property
    def depth(self) -> int:
        """Distance from the root (the root has depth 0)."""
        depth, node = 0, self.parent
        while node is not None:
            depth, node = depth + 1, node.parent
        return depth

    def ancestors(self) -> Iterator[Node]:
        """The parent, its parent, … up to the root."""
        node = self.parent
        while node is not None:
            yield node
            node = node.parent

    def walk(self) -> Iterator[Node]:
        """This node and its descendants in depth-first pre-order."""
        stack = [self]
        while stack:
            node = stack.pop()
            yield node
            stack.extend(reversed(node.children))

    def describe(self, idx: int | None = None) -> dict:
        """The node as a JSON-ready dict (the ``/btlog/tree`` node record); ``idx``, its
        position among its siblings, is looked up when not given."""
        return {
            "uid": self.uid,
            "parent_uid": None if self.parent is None else self.parent.uid,
            "idx": self.index if idx is None else idx,
            "kind": self.kind,
            "type": self.type,
            "name": self.name,
            "path": self.path,
            "scope": self.scope,
            "ports": {
                k: {"value": p.value, "direction": p.direction} for k, p in self.ports.items()
            },
            "attributes": dict(self.attributes),
            "file": self.file,
            "line": self.line,
        }

    def __repr__(self) -> str:
        return f"<Node {self.uid} {self.type} {self.name!r}>"


def node_from_description(record: dict) -> Node:
    """Rebuild a parentless, childless node from its ``describe()`` record."""
    return Node(
        uid=record["uid"],
        type=record["type"],
        name=record["name"],
        kind=record["kind"],
        ports={
            k: Port(p["value"], p.get("direction", INPUT))
            for k, p in record.get("ports", {}).items()
        },
        attributes=dict(record.get("attributes", {})),
        path=record.get("path", ""),
        scope=record.get("scope", ""),
        file=record.get("file", ""),
        line=record.get("line", 0),
    )


class TreeDescriptionError(ValueError):
    """A ``/btlog/tree`` message that does not describe one tree; one line."""


def _check_uids(records: list[dict]) -> None:
    """Every uid a distinct positive 32-bit integer; every parent uid one of them."""
    seen: set[int] = set()
    for record in records:
        uid = record["uid"]
        if not isinstance(uid, int) or isinstance(uid, bool) or not 0 < uid < 2**31:
            raise TreeDescriptionError(f"uid {uid!r} is not an integer from 1 to 2**31-1")
        if uid in seen:
            raise TreeDescriptionError(f"uid {uid} is used by two nodes")
        seen.add(uid)
    for record in records:
        parent = record["parent_uid"]
        if parent is not None and parent not in seen:
            raise TreeDescriptionError(f"node {record['uid']}'s parent uid {parent!r} is unknown")


def link_nodes(records: list[dict]) -> list[Node]:
    """Rebuild nodes from records and link parents and children; returns them in order."""
    nodes = [node_from_description(r) for r in records]
    by_uid = {n.uid: n for n in nodes}
    for node, record in sorted(zip(nodes, records, strict=True), key=lambda p: p[1]["idx"]):
        parent_uid = record["parent_uid"]
        if parent_uid is not None and parent_uid in by_uid:
            node.parent = by_uid[parent_uid]
            node.parent.children.append(node)
    return nodes


@dataclass(eq=False)
class Tree:
    """A loaded tree: the root of the main tree, every node by uid, and where it came from."""

    root: Node
    name: str = "MainTree"
    format: int = 4
    files: list[str] = field(default_factory=list)
    nodes: dict[int, Node] = field(default_factory=dict)
    #: what the loader noticed and accepted (a nodes model the XML contradicts, a node
    #: run as a pass-through, …), one line each; not recorded
    warnings: list[str] = field(default_factory=list)
    #: the declared type of each port of each node type used (type ID -> port -> type,
    #: e.g. ``int``), from btlog's registry and the nodes models; not recorded
    port_types: dict[str, dict[str, str]] = field(default_factory=dict)
    #: why ``name`` is the main tree: "--main-tree", "main_tree" (main_tree_to_execute),
    #: "only" (the only tree) or "uncalled" (the only tree no other tree calls)
    main_choice: str = ""
    #: values that depend only on the tree's nodes (``shaped``), emptied by an insertion
    _shaped: dict[Hashable, Any] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if not self.nodes:
            self.nodes = {n.uid: n for n in self.root.walk()}

    def shaped(self, key: Hashable, compute: Callable[[], T]) -> T:
        """``compute()`` once for this shape of the tree: a value that depends only on its
        nodes (the steps below a goal, the nodes of a kind), kept under ``key`` until a
        node is inserted. Callers must not change what it returns."""
        if key not in self._shaped:
            self._shaped[key] = compute()
        return cast(T, self._shaped[key])

    def __iter__(self) -> Iterator[Node]:
        return self.root.walk()

    def __len__(self) -> int:
        return len(self.nodes)

    def node(self, uid: int) -> Node:
        """The node with this uid (KeyError if there is none)."""
        return self.nodes[uid]

    @property
    def next_uid(self) -> int:
        """The first uid not used yet (fresh uids for inserted nodes start here)."""
        return max(self.nodes) + 1

    def lookup(self, key: str, leaves_only: bool = False) -> list[Node]:
        """The nodes a key (of outcomes, expectations, --fail, --node) names: by path,
        else by name, else nameless nodes by type (several when the key is ambiguous).

        ``leaves_only`` looks among execution nodes only, as outcomes do: there "detect
        chuck" is the nameless leaf of that type, not a Sequence named so."""
        nodes = [n for n in self if n.is_execution] if leaves_only else list(self)
        for matches in (
            [n for n in nodes if n.path == key],
            [n for n in nodes if n.name == key],
            [n for n in nodes if not n.name and n.type == key],
        ):
            if matches:
                return matches
        return []

    def lookup_one(self, key: str) -> Node:
        """The one node a key names; LookupError when it names none or several."""
        found = self.lookup(key)
        if not found:
            raise LookupError(f"node {key!r} matches no node of the tree")
        if len(found) > 1:
            paths = ", ".join(repr(n.path) for n in found[:3])
            raise LookupError(f"node {key!r} matches {len(found)} nodes; use a path (e.g. {paths})")
        return found[0]

    def describe(self) -> dict:
        """The tree as the JSON-ready ``/btlog/tree`` message."""
        return {
            "tree_name": self.name,
            "format": self.format,
            "nodes": [node.describe(idx) for node, idx in self.indexed()],
        }

    def indexed(self) -> Iterator[tuple[Node, int]]:
        """Every node with its position among its siblings, in depth-first pre-order
        (linear: no sibling lists are searched)."""
        stack = [(self.root, 0)]
        while stack:
            node, idx = stack.pop()
            yield node, idx
            stack.extend((child, i) for i, child in reversed(list(enumerate(node.children))))

    @classmethod
    def from_description(cls, message: dict) -> Tree:
        """Rebuild a tree from its ``/btlog/tree`` message, which may come from a crafted
        file: ``TreeDescriptionError`` unless every uid is a distinct integer, one node is
        the root, every parent exists and every node hangs from the root, at most
        ``MAX_DEPTH`` levels down."""
        records = message["nodes"]
        _check_uids(records)
        nodes = link_nodes(records)
        roots = [n for n in nodes if n.parent is None]
        if len(roots) != 1:
            raise TreeDescriptionError(f"{len(roots)} nodes have no parent (one root expected)")
        reached = 0
        stack = [(roots[0], 0)]
        while stack:
            node, depth = stack.pop()
            reached += 1
            if depth > MAX_DEPTH:
                raise TreeDescriptionError(f"node {node.uid} is deeper than {MAX_DEPTH} levels")
            stack.extend((child, depth + 1) for child in node.children)
        if reached != len(nodes):
            raise TreeDescriptionError(f"{len(nodes) - reached} nodes do not hang from the root")
        name, format_ = message.get("tree_name", "MainTree"), message.get("format", 4)
        return cls(root=roots[0], name=name, format=format_)

    def copy_nodes(self) -> Tree:
        """A tree of copies of the nodes (same uids, fields and shape) with this tree's
        name and format: what ``from_description(describe())`` gives, without the round
        trip through dicts and its checks (this tree passed them)."""
        copies: dict[int, Node] = {}
        for node in self.root.walk():
            copy = _copy_node(node, node.uid)
            copy.added_seq = node.added_seq
            if node.parent is not None:
                copy.parent = copies[node.parent.uid]
                copy.parent.children.append(copy)
            copies[node.uid] = copy
        return Tree(root=copies[self.root.uid], name=self.name, format=self.format, nodes=copies)

    def copy_subtree(self, node: Node, first_uid: int) -> Node:
        """A deep copy of ``node``'s subtree with fresh uids from ``first_uid``, parentless."""
        uid = first_uid

        def clone(original: Node) -> Node:
            nonlocal uid
            copy = _copy_node(original, uid)
            uid += 1
            for child in original.children:
                child_copy = clone(child)
                child_copy.parent = copy
                copy.children.append(child_copy)
            return copy

        return clone(node)

    def insert_after(self, parent: Node, after: Node | None, subtree: Node, seq: int | None) -> int:
        """Insert ``subtree`` (fresh uids) as a child of ``parent`` right after ``after``.

        Returns the index the subtree was inserted at. ``after=None`` inserts first.
        """
        index = 0 if after is None else parent.children.index(after) + 1
        subtree.parent = parent
        parent.children.insert(index, subtree)
        self._shaped.clear()
        self._register_inserted(subtree, parent.scope, seq)
        return index

    def remove(self, node: Node) -> None:
        """Take ``node``'s subtree out of the tree (a py_trees ``prune_subtree``)."""
        if node.parent is None:
            raise ValueError("cannot remove the root of a tree")
        node.parent.children.remove(node)
        node.parent = None
        for removed in node.walk():
            self.nodes.pop(removed.uid, None)

    def _register_inserted(self, node: Node, scope: str, seq: int | None) -> None:
        """Give an inserted node (and its subtree) its scope, a unique path and its seq."""
        if node.uid in self.nodes:
            raise ValueError(f"uid {node.uid} is already used in the tree")
        node.added_seq = seq
        node.scope = scope
        node.path = (f"{scope}/" if scope else "") + f"{node.description}::{node.uid}"
        self.nodes[node.uid] = node
        inner = node.path if node.kind == SUBTREE else scope
        for child in node.children:
            self._register_inserted(child, inner, seq)


def _copy_node(node: Node, uid: int) -> Node:
    """``node`` alone (no parent, no children, no ``added_seq``) under ``uid``."""
    return Node(
        uid=uid,
        type=node.type,
        name=node.name,
        kind=node.kind,
        ports=dict(node.ports),
        attributes=dict(node.attributes),
        path=node.path,
        scope=node.scope,
        file=node.file,
        line=node.line,
    )

"""The blackboard: key–value entries in scopes, one scope per subtree instance.

As in BT.CPP v4, every SubTree gets its own blackboard. A key remapped by the SubTree
(``port="{outer}"``) reads and writes the parent's entry ``outer``; with ``_autoremap``
any key that is not private (``_key``) and not local resolves in the parent; ``@key``
always means the root blackboard. Every write is reported, with the scope that really
holds the entry and the node that wrote it, to the executor's event feed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from btlog.tree.model import SUBTREE, Node, blackboard_key

#: Marks a removed entry in the write feed (UnsetBlackboard).
UNSET = object()

WriteSink = Callable[[str, str, Any, int | None], None]


class Blackboard:
    """One scope of entries; ``scope`` is the subtree path ("" for the main tree)."""

    def __init__(
        self,
        scope: str = "",
        parent: Blackboard | None = None,
        remap: dict[str, str] | None = None,
        autoremap: bool = False,
    ) -> None:
        self.scope = scope
        self.parent = parent
        self.remap = remap or {}
        self.autoremap = autoremap
        self.entries: dict[str, Any] = {}
        #: how many times each entry was written (BT.CPP's ``sequence_id``, which
        #: WasEntryUpdated, SkipUnlessUpdated and WaitValueUpdate compare)
        self.versions: dict[str, int] = {}
        #: keys a node's port names (``{key}``) that have no value yet: BT.CPP creates
        #: such entries, empty, when it creates the tree, so a script may assign them
        #: with ``=``
        self.declared_keys: set[str] = set()
        self.on_write: WriteSink | None = None
        self.root: Blackboard = self if parent is None else parent.root

    def _resolve(self, key: str) -> tuple[Blackboard, str, bool]:
        """Follow ``@``, remaps and autoremap: the board and key that hold ``key``, and
        whether the entry exists (if not, the board is where BT.CPP would create it)."""
        board = self
        while True:
            if key.startswith("@"):
                board, key = board.root, key[1:]
            if key in board.entries:
                return board, key, True
            if key in board.remap and board.parent is not None:
                key, board = board.remap[key], board.parent
            elif board.autoremap and board.parent is not None and not key.startswith("_"):
                board = board.parent
            else:
                return board, key, False

    def locate(self, key: str) -> tuple[str, str, bool]:
        """The scope and key that hold ``key`` as this board sees it, and whether the
        entry exists (see ``_resolve``)."""
        board, resolved, found = self._resolve(key)
        return board.scope, resolved, found

    def exists(self, key: str) -> bool:
        """True when the key resolves to an entry."""
        return self._resolve(key)[2]

    def get(self, key: str) -> Any:
        """The value of ``key``; KeyError when it does not exist."""
        board, resolved, found = self._resolve(key)
        if not found:
            raise KeyError(key)
        return board.entries[resolved]

    def set(self, key: str, value: Any, writer: int | None = None) -> None:
        """Write ``key`` (creating it where BT.CPP would) and report the write."""
        board, resolved, _ = self._resolve(key)
        board.entries[resolved] = value
        board.versions[resolved] = board.versions.get(resolved, 0) + 1
        sink = self.root.on_write
        if sink is not None:
            sink(board.scope, resolved, value, writer)

    def unset(self, key: str, writer: int | None = None) -> None:
        """Remove ``key`` if it exists, and report the removal."""
        board, resolved, found = self._resolve(key)
        if not found:
            return
        del board.entries[resolved]
        board.versions.pop(resolved, None)
        sink = self.root.on_write
        if sink is not None:
            sink(board.scope, resolved, UNSET, writer)

    def declare(self, key: str) -> None:
        """Create the entry ``key`` empty, where BT.CPP creates it for a port at tree
        creation (through remaps), unless it exists."""
        board, resolved, found = self._resolve(key)
        if not found:
            board.declared_keys.add(resolved)

    def declared(self, key: str) -> bool:
        """True when ``key`` resolves to an entry created empty (``declare``)."""
        board, resolved, found = self._resolve(key)
        return found or resolved in board.declared_keys

    def preset(self, key: str, value: Any) -> None:
        """Write ``key`` in this very scope before the run starts, unreported (the executor
        reports it when the run begins): a SubTree's literal, an entry the host sets."""
        self.entries[key] = value
        self.versions[key] = self.versions.get(key, 0) + 1

    def version(self, key: str) -> int | None:
        """How many times ``key`` was written (None when it does not exist)."""
        board, resolved, found = self._resolve(key)
        return board.versions.get(resolved, 0) if found else None

    def view(self, writer: int | None) -> BoundBlackboard:
        """This blackboard as a node sees it (writes are reported with the node's uid)."""
        return BoundBlackboard(self, writer)


def subtree_remapping(node: Node) -> tuple[dict[str, str], bool, list[tuple[str, str]]]:
    """How a SubTree node maps its blackboard onto its parent's: the remapped keys
    (inner → outer), whether it autoremaps, and the ports given literal values (name,
    value as written), which become the inner board's own entries."""
    remap: dict[str, str] = {}
    literals: list[tuple[str, str]] = []
    for name, port in node.ports.items():
        key = blackboard_key(port.value)
        if key == "=" or (key is None and port.value.strip() == "="):
            remap[name] = name
        elif key is not None:
            remap[name] = key
        else:
            literals.append((name, port.value))
    autoremap = node.attributes.get("_autoremap", "false").strip().lower() == "true"
    return remap, autoremap, literals


def board_of(node: Node, entries: dict[str, dict[str, Any]]) -> Blackboard:
    """The blackboard ``node`` sees, rebuilt from the tree's SubTrees and a run's entries
    per scope (a ``State``'s ``blackboard``): what a key resolves to at that moment."""
    board = Blackboard("")
    board.entries = entries.get("", {})
    chain = [a for a in node.ancestors() if a.kind == SUBTREE]
    for subtree in reversed(chain):
        if subtree.attributes.get("shared_blackboard") == "true" or not subtree.children:
            continue
        remap, autoremap, _ = subtree_remapping(subtree)
        scope = subtree.children[0].scope
        board = Blackboard(scope, board, remap, autoremap)
        board.entries = entries.get(scope, {})
    return board


class BoundBlackboard:
    """A blackboard seen by one node: the script environment and the leaves' view."""

    __slots__ = ("board", "writer")

    def __init__(self, board: Blackboard, writer: int | None) -> None:
        self.board = board
        self.writer = writer

    def get(self, key: str) -> Any:
        """The value of ``key`` (KeyError when missing)."""
        return self.board.get(key)

    def exists(self, key: str) -> bool:
        """True when ``key`` resolves to an entry."""
        return self.board.exists(key)

    def declared(self, key: str) -> bool:
        """True when ``key`` resolves to an entry, set or created empty by a port."""
        return self.board.declared(key)

    def set(self, key: str, value: Any) -> None:
        """Write ``key`` as this node."""
        self.board.set(key, value, self.writer)

    def unset(self, key: str) -> None:
        """Remove ``key`` as this node."""
        self.board.unset(key, self.writer)

    def version(self, key: str) -> int | None:
        """How many times ``key`` was written (None when it does not exist)."""
        return self.board.version(key)


class EntryWatch:
    """Was an entry written since the last look? BT.CPP's check of an entry's
    ``sequence_id`` (WasEntryUpdated, SkipUnlessUpdated, WaitValueUpdate): ``raw`` names
    the entry as ``{key}`` or as the plain key; every write counts, the same value too."""

    __slots__ = ("key", "seen")

    def __init__(self, raw: str) -> None:
        key = blackboard_key(raw)
        self.key = raw if key is None else key
        self.seen = 0

    def updated(self, board: BoundBlackboard) -> bool:
        """True when the entry exists and was written since the last call that saw it."""
        version = board.version(self.key)
        if version is None:
            return False
        previous, self.seen = self.seen, version
        return previous != version

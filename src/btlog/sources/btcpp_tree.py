"""The tree of an imported BT.CPP run: from the XML BT.CPP wrote, or the user's file.

BT.CPP's loggers and Groot2 publisher embed ``WriteTreeToXML(tree, true, true)``: each
subtree instance as its own ``<BehaviorTree _fullpath=…>``, every node with its ``_uid``,
and a ``<TreeNodesModel>`` of every type used. btlog loads it with unknown types accepted
(their kind from that model), checks that its own uids are BT.CPP's, and drops the
``_uid``/``_fullpath`` bookkeeping so the tree equals the one loaded from the user's file.
A ``--tree`` given by the user must match the log's tree uid by uid (type and name).
"""

from __future__ import annotations

import os

from btlog.sources.builder import SourceError
from btlog.tree.loader import TreeError, load_tree, load_tree_text, parse_xml
from btlog.tree.model import Tree
from btlog.tree.registry import Registry

BOOKKEEPING = ("_uid", "_fullpath")


def tree_from_log_xml(xml: bytes, where: str, registry: Registry | None = None) -> Tree:
    """The tree of XML written by BT.CPP's ``WriteTreeToXML``; ``where`` names the source."""
    try:
        root = parse_xml(xml, where)
        first = next((c for c in root if c.tag == "BehaviorTree"), None)
        main = first.get("ID") if first is not None else None
        tree = load_tree_text(xml, registry, main, file=where, accept_unknown=True)
    except TreeError as error:
        raise SourceError(f"the tree in the log: {error}") from None
    for node in tree:
        written = node.attributes.get("_uid")
        if written is not None and written.strip() != str(node.uid):
            raise SourceError(
                f"{where}: BT.CPP numbered node {node.path!r} {written}, btlog numbers it "
                f"{node.uid}; the log's uids cannot be trusted"
            )
        for key in BOOKKEEPING:
            node.attributes.pop(key, None)
    return tree


def tree_from_file(path: str | os.PathLike, log_tree: Tree, registry: Registry | None) -> Tree:
    """The user's tree file for a log (``--tree``), checked against the log's own tree."""
    try:
        tree = load_tree(path, registry, accept_unknown=True)
    except TreeError as error:
        raise SourceError(str(error)) from None
    check_same_tree(tree, log_tree, os.fspath(path))
    for node in tree:  # BT.CPP's manifests are the authority on kinds
        node.kind = log_tree.nodes[node.uid].kind
    return tree


def check_same_tree(tree: Tree, log_tree: Tree, where: str) -> None:
    """Raise ``SourceError`` unless ``tree`` has the log's nodes: same uids, types, names."""
    if len(tree) != len(log_tree):
        raise SourceError(
            f"{where}: the tree has {len(tree)} nodes, the log's tree {len(log_tree)}; "
            "not the tree of this log"
        )
    for node in log_tree:
        mine = tree.nodes.get(node.uid)
        if mine is None or (mine.type, mine.name) != (node.type, node.name):
            found = "nothing" if mine is None else f"{mine.type} {mine.name!r}"
            raise SourceError(
                f"{where}: uid {node.uid} is {found} in the tree but {node.type} "
                f"{node.name!r} in the log; not the tree of this log"
            )

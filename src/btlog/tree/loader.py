"""Load BehaviorTree.CPP XML (v4, and v3 where no format is given) into a ``Tree``.

The loader follows BT.CPP's own parser: the main tree is ``main_tree_to_execute`` of the
first document (or the only tree), ``<include path=…>`` is resolved against the including
file, ``<SubTree>`` nodes are expanded in place with a new blackboard scope, and UIDs are
assigned in depth-first pre-order from 1 with each subtree's nodes right after its SubTree
node. v3 rules apply when the root has no ``BTCPP_format``: a SubTree's instance name is
forced to its ID and its remapping ``a="b"`` names the parent key ``b`` directly.

Imported runs (``btlog import``, ``btlog attach``) come from robots whose node types btlog
has no implementation of: ``accept_unknown=True`` accepts any type, its kind taken from
the ``<TreeNodesModel>`` (the tree's own, or one read by ``load_nodes_model``), else from
a generic tag (``<Control ID=…>``) or its children. The XML BT.CPP writes for its loggers
and Groot2 (``WriteTreeToXML``) is read too: each subtree instance is its own
``<BehaviorTree _fullpath=…>``, matched to its ``<SubTree _fullpath=…>``, and a SubTree's
name is the last part of that path.

XML is untrusted input (``btlog.tree.xml_source``): every error is a ``TreeError`` naming
the file, the line and what is wrong. The jobs are split: ``xml_source`` reads and parses,
``documents`` gathers definitions, includes and node models, ``builder`` builds the nodes.
"""

from __future__ import annotations

import os
from pathlib import Path

from btlog.tree.builder import TreeBuilder
from btlog.tree.documents import Documents
from btlog.tree.model import Tree
from btlog.tree.registry import Registry
from btlog.tree.xml_source import TreeError, parse_xml, read_xml_file

__all__ = ["TreeError", "load_nodes_model", "load_tree", "load_tree_text", "parse_xml"]


def _load(
    data: bytes,
    file: str,
    folder: Path,
    registry: Registry | None,
    main_tree: str | None,
    accept_unknown: bool,
) -> Tree:
    documents = Documents((registry or Registry()).copy())
    documents.read(data, file, folder)
    main = documents.main_tree(main_tree)
    return TreeBuilder(documents, accept_unknown).build(main)


def load_tree(
    source: str | os.PathLike,
    registry: Registry | None = None,
    main_tree: str | None = None,
    accept_unknown: bool = False,
) -> Tree:
    """Load a tree from an XML file (its includes resolved against its folder);
    ``accept_unknown`` accepts node types btlog has no implementation of (imports)."""
    data = read_xml_file(source)
    return _load(data, str(source), Path(source).parent, registry, main_tree, accept_unknown)


def load_tree_text(
    text: str | bytes,
    registry: Registry | None = None,
    main_tree: str | None = None,
    file: str = "<string>",
    base_dir: str | os.PathLike = ".",
    accept_unknown: bool = False,
) -> Tree:
    """Load a tree from XML text; includes resolve against ``base_dir``."""
    data = text.encode() if isinstance(text, str) else text
    return _load(data, file, Path(base_dir), registry, main_tree, accept_unknown)


def load_nodes_model(source: str | os.PathLike, registry: Registry | None = None) -> Registry:
    """A copy of ``registry`` with the declarations of the ``<TreeNodesModel>`` in the XML
    file ``source`` (e.g. BT.CPP's ``writeTreeNodesModelXML``); other elements are ignored."""
    file = str(source)
    root = parse_xml(read_xml_file(source), file)
    documents = Documents((registry or Registry()).copy())
    models = [c for c in root if c.tag == "TreeNodesModel"]
    if root.tag != "root" or not models:
        raise TreeError("no <TreeNodesModel> under <root>", file, root.sourceline)
    for element in models:
        documents.read_model(element, file)
    return documents.registry

"""Load BehaviorTree.CPP XML (v4, and v3 where no format is given) into a ``Tree``.

The loader follows BT.CPP's own parser: files are registered as a program registers them
(the tree file, then ``--trees`` files and folders), the main tree is ``--main-tree``, else
``main_tree_to_execute`` of the first document, else the only tree (else the one tree no
other tree calls), ``<include path=…>`` is resolved against the including
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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from btlog.tree.builder import TreeBuilder
from btlog.tree.documents import Documents
from btlog.tree.model import Tree
from btlog.tree.registry import Registry
from btlog.tree.xml_source import TreeError, parse_xml, read_xml_file

__all__ = [
    "TreeError",
    "TreeSource",
    "load_nodes_model",
    "load_tree",
    "load_tree_text",
    "parse_xml",
    "tree_files",
]


def _load(
    data: bytes,
    file: str,
    folder: Path,
    registry: Registry | None,
    main_tree: str | None,
    accept_unknown: bool,
    trees: Sequence[str | os.PathLike] = (),
) -> Tree:
    documents = Documents((registry or Registry()).copy())
    documents.read(data, file, folder)
    for path, in_folder in tree_files(trees):
        documents.read_file(path, only_trees=in_folder)
    main, choice = documents.main_tree(main_tree)
    tree = TreeBuilder(documents, accept_unknown).build(main)
    tree.main_choice = choice
    tree.warnings = [*documents.warnings, *tree.warnings]
    return tree


def tree_files(trees: Sequence[str | os.PathLike]) -> list[tuple[Path, bool]]:
    """The files ``--trees`` names, each with whether it was found in a folder: a file as
    it is, a folder as its ``*.xml`` files in name order (not its subfolders)."""
    files: list[tuple[Path, bool]] = []
    for entry in trees:
        path = Path(entry)
        if path.is_dir():
            files += [(p, True) for p in sorted(path.glob("*.xml")) if p.is_file()]
        elif path.exists():
            files.append((path, False))
        else:
            raise TreeError("--trees: no such file or folder", str(entry))
    return files


@dataclass(frozen=True)
class TreeSource(os.PathLike):
    """A tree file with the files registered beside it and the tree to create
    (``--trees``, ``--main-tree``): a path wherever a tree file is expected, which
    ``load_tree`` loads with both."""

    path: str
    main_tree: str | None = None
    trees: tuple[str, ...] = ()

    def __fspath__(self) -> str:
        return self.path

    def __str__(self) -> str:
        return self.path


def load_tree(
    source: str | os.PathLike,
    registry: Registry | None = None,
    main_tree: str | None = None,
    accept_unknown: bool = False,
    trees: Sequence[str | os.PathLike] = (),
) -> Tree:
    """Load a tree from an XML file (its includes resolved against its folder), as a BT.CPP
    program registers it, then the files and folders of ``trees`` (``--trees``), and
    creates ``main_tree`` (``--main-tree``; see ``Documents.main_tree``);
    ``accept_unknown`` accepts node types btlog has no implementation of (imports). A
    ``TreeSource`` brings its own ``main_tree`` and ``trees``."""
    if isinstance(source, TreeSource):
        main_tree = main_tree or source.main_tree
        trees = (*source.trees, *trees)
        source = source.path
    data = read_xml_file(source)
    return _load(data, str(source), Path(source).parent, registry, main_tree, accept_unknown, trees)


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

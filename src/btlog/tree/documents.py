"""The documents of a tree: ``<root>`` files, their ``<include>``s, the ``<BehaviorTree>``
definitions they hold and the node types their ``<TreeNodesModel>`` declares.

An include is resolved against the including file's folder, at most
``MAX_INCLUDE_DEPTH`` deep and never in a cycle. BT.CPP-written XML (``WriteTreeToXML``)
repeats a subtree once per instance, each with its ``_fullpath``: the first definition of
an ID is the definition, every instance is kept by its full path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from btlog import limits
from btlog.tree.model import ACTION, CONDITION, CONTROL, DECORATOR, SUBTREE
from btlog.tree.registry import NodeType, PortSpec, Registry
from btlog.tree.xml_source import TreeError, parse_xml, read_xml_file
from btlog.tree.xml_syntax import XmlElement

MAX_INCLUDE_DEPTH = 16
SUBTREE_TAGS = ("SubTree", "SubTreePlus")
MODEL_KINDS = {
    "Action": ACTION,
    "Condition": CONDITION,
    "Control": CONTROL,
    "Decorator": DECORATOR,
    "SubTree": SUBTREE,
}
MODEL_PORT_TAGS = {
    "input_port": "input",
    "output_port": "output",
    "inout_port": "inout",
    "bidirectional_port": "inout",  # Nav2's nav2_tree_nodes.xml spelling
}


@dataclass(frozen=True)
class Definition:
    """A ``<BehaviorTree>`` element and the file it is in."""

    element: XmlElement
    file: str

    def root_element(self) -> XmlElement:
        """The tree's one node element."""
        return self.element.children[0]

    def calls(self) -> list[str]:
        """The IDs of the subtrees this tree's ``<SubTree>`` nodes call, in order."""
        return [
            e.get("ID", "") for e in self.element.iter() if e.tag in SUBTREE_TAGS and e.get("ID")
        ]


@dataclass
class Document:
    """One ``<root>`` file: its format (None when not given) and main tree."""

    file: str
    root: XmlElement
    format: int | None
    main: str | None
    #: read from ``--trees`` (itself or through its includes), not from the tree file
    registered: bool = False


@dataclass
class Documents:
    """Everything read from a file and its includes; ``registry`` gains the declared types."""

    registry: Registry
    documents: list[Document] = field(default_factory=list)
    definitions: dict[str, Definition] = field(default_factory=dict)
    #: subtree instances of BT.CPP-written XML, by their ``_fullpath``
    instances: dict[str, Definition] = field(default_factory=dict)
    #: what was accepted with a remark (see ``Tree.warnings``)
    warnings: list[str] = field(default_factory=list)
    _registering: bool = False

    def files(self, used: set[str]) -> list[str]:
        """The files of the tree: the tree file and its includes, and the registered
        files (``--trees``) that hold a tree of ``used`` files."""
        return [d.file for d in self.documents if not d.registered or d.file in used]

    def read_file(self, path: Path, only_trees: bool = False) -> None:
        """Read a file as BT.CPP's ``registerBehaviorTreeFromFile`` does (its includes
        against its folder); a file already read is skipped. ``only_trees`` (a file found
        in a folder) skips quietly an XML file whose top element is not ``<root>``."""
        resolved = str(path.resolve())
        if any(str(Path(d.file).resolve()) == resolved for d in self.documents):
            return
        root = parse_xml(read_xml_file(path), str(path))
        if only_trees and root.tag != "root":
            return
        self._registering = True
        try:
            self._read_root(root, str(path), path.parent)
        finally:
            self._registering = False

    def read(
        self, data: bytes, file: str, folder: Path, depth: int = 0, seen: tuple[str, ...] = ()
    ) -> None:
        """Read the document ``data`` (from ``file``) and, recursively, what it includes."""
        self._read_root(parse_xml(data, file), file, folder, depth, seen)

    def _read_root(
        self,
        root: XmlElement,
        file: str,
        folder: Path,
        depth: int = 0,
        seen: tuple[str, ...] = (),
    ) -> None:
        if root.tag != "root":
            raise TreeError(
                f"the top element must be <root>, not <{root.tag}>", file, root.sourceline
            )
        fmt = root.get("BTCPP_format")
        if fmt is not None and fmt.strip() not in ("3", "4"):
            raise TreeError(f"unsupported BTCPP_format {fmt!r} (3 or 4)", file, root.sourceline)
        self.documents.append(
            Document(
                file,
                root,
                int(fmt) if fmt else None,
                root.get("main_tree_to_execute"),
                self._registering,
            )
        )
        children = root.children
        for element in children:
            if element.tag == "BehaviorTree":
                self._define(element, file, len(children))
            elif element.tag == "TreeNodesModel":
                self.read_model(element, file)
            elif element.tag == "include":
                self._include(element, file, folder, depth, (*seen, file))
            else:  # BT.CPP reads only these three and ignores the rest
                self.warnings.append(
                    f"{file}:{element.sourceline}: <{element.tag}> under <root> is ignored "
                    "(BT.CPP reads only <BehaviorTree>, <include> and <TreeNodesModel>)"
                )

    def main_tree(self, requested: str | None) -> tuple[str, str]:
        """The ID of the tree to build and why it is the one, as a BT.CPP program chooses
        (``createTree(ID)``): ``requested`` (``--main-tree``), else the first document's
        ``main_tree_to_execute``, else the only tree; with several trees and none named,
        the one no other tree calls (preferring the first file's), else an error naming
        the candidates."""
        first = self.documents[0]
        file, line = first.file, first.root.sourceline
        if not self.definitions:
            raise TreeError("no <BehaviorTree> is defined", file, line)
        main, reason = (requested, "--main-tree") if requested else (first.main, "main_tree")
        if main is not None:
            if main not in self.definitions:
                known = ", ".join(repr(t) for t in self.definitions)
                raise TreeError(f"main tree {main!r} is not defined (trees: {known})", file, line)
            return main, reason
        if len(self.definitions) == 1:
            return next(iter(self.definitions)), "only"
        called = {c for d in self.definitions.values() for c in d.calls()}
        roots = [t for t in self.definitions if t not in called]
        mine = [t for t in roots if self.definitions[t].file == first.file]
        for candidates in (mine, roots):
            if len(candidates) == 1:
                return candidates[0], "uncalled"
        names = ", ".join(repr(t) for t in (roots or self.definitions))
        which = "no other tree calls" if roots else "defined (each is called by another)"
        raise TreeError(
            f"{len(self.definitions)} trees and no main_tree_to_execute; the trees {which}: "
            f"{names}; choose one with --main-tree ID",
            file,
            line,
        )

    def _define(self, element: XmlElement, file: str, siblings: int) -> None:
        tree_id = element.get("ID")
        if tree_id is None:
            if siblings > 1:
                raise TreeError(
                    "<BehaviorTree> needs an ID when <root> has several children",
                    file,
                    element.sourceline,
                )
            tree_id = f"BehaviorTree_{len(self.definitions)}"
        fullpath = element.get("_fullpath")
        if fullpath is not None and fullpath not in self.instances:
            self.instances[fullpath] = Definition(element, file)
            if tree_id in self.definitions:
                return  # another instance of a subtree, in BT.CPP-written XML
        if tree_id in self.definitions:
            raise TreeError(f"tree {tree_id!r} is defined twice", file, element.sourceline)
        nodes = element.children
        if len(nodes) != 1:
            raise TreeError(
                f"<BehaviorTree ID={tree_id!r}> must have exactly one child, found {len(nodes)}",
                file,
                element.sourceline,
            )
        self.definitions[tree_id] = Definition(element, file)

    def _include(
        self, element: XmlElement, file: str, folder: Path, depth: int, seen: tuple[str, ...]
    ) -> None:
        target = element.get("path")
        if not target:
            raise TreeError("<include> needs a path attribute", file, element.sourceline)
        if element.get("ros_pkg"):
            raise TreeError(
                "<include ros_pkg=…> needs ROS, which btlog does not use", file, element.sourceline
            )
        path = (folder / target).resolve()
        if depth >= MAX_INCLUDE_DEPTH or str(path) in {str(Path(s).resolve()) for s in seen}:
            raise TreeError(
                f"include cycle or nesting too deep at {target!r}", file, element.sourceline
            )
        try:
            data = limits.read_bounded(path)
        except OSError as error:
            raise TreeError(
                f"cannot read included file {target!r}: {error.strerror}", file, element.sourceline
            ) from None
        except limits.LimitError as error:
            raise TreeError(
                f"included file {target!r}: {error}", file, element.sourceline
            ) from None
        self.read(data, str(path), path.parent, depth + 1, seen)

    def read_model(self, element: XmlElement, file: str) -> None:
        """Register the node types a ``<TreeNodesModel>`` declares (a type btlog implements
        keeps its implementation; a SubTree's model gives its ports)."""
        for entry in element:
            kind = MODEL_KINDS.get(entry.tag)
            type_id = entry.get("ID")
            if kind is None or not type_id:
                raise TreeError(
                    f"<{entry.tag}> in <TreeNodesModel> needs a known tag and an ID",
                    file,
                    entry.sourceline,
                )
            ports = _model_ports(entry, type_id, file)
            existing = self.registry.get(type_id)
            if kind == SUBTREE:
                self.registry.register(NodeType(type_id, SUBTREE, ports, declared_only=True))
            elif existing is None or existing.declared_only:
                children = {CONTROL: (1, None), DECORATOR: (1, 1)}.get(kind, (0, 0))
                self.registry.register(
                    NodeType(type_id, kind, ports, children=children, declared_only=True)
                )


def _model_ports(entry: XmlElement, type_id: str, file: str) -> dict[str, PortSpec]:
    ports = {}
    for port in entry:
        if port.tag == "MetadataFields":
            continue
        direction = MODEL_PORT_TAGS.get(port.tag)
        name = port.get("name")
        if direction is None or not name:
            raise TreeError(
                f"unexpected <{port.tag}> in the model of {type_id!r}", file, port.sourceline
            )
        ports[name] = PortSpec(
            direction, port.get("type") or "str", port.get("default"), (port.text or "").strip()
        )
    return ports

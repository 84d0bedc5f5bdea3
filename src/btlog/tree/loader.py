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
a generic tag (``<Control ID=…>``) or its children (none: action, one: decorator, more:
control). The XML BT.CPP writes for its loggers and Groot2 (``WriteTreeToXML``) is read
too: each subtree instance is its own ``<BehaviorTree _fullpath=…>``, matched to its
``<SubTree _fullpath=…>``, and a SubTree's name is the last part of that path.

XML is untrusted input: entities are not resolved, DTDs and network access are refused,
files are bounded in size (checked before reading), the tree is bounded in nodes and depth
once its SubTrees are expanded (checked before expanding them), and every error names the
file, the line and what is wrong. The bounds are in ``btlog.limits``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from lxml import etree

from btlog import limits
from btlog.tree.model import (
    ACTION,
    CONDITION,
    CONTROL,
    DECORATOR,
    SUBTREE,
    Node,
    Port,
    Tree,
    blackboard_key,
)
from btlog.tree.registry import (
    POSTCONDITIONS,
    PRECONDITIONS,
    RESERVED,
    NodeType,
    PortSpec,
    Registry,
    leaf_kind,
)

MAX_INCLUDE_DEPTH = 16
GENERIC_TAGS = {
    "Action": ACTION,
    "Condition": CONDITION,
    "Control": CONTROL,
    "Decorator": DECORATOR,
}
SUBTREE_TAGS = ("SubTree", "SubTreePlus")
V3_IGNORED = frozenset({"__shared_blackboard", "__autoremap", "_description"})
MODEL_KINDS = {
    "Action": ACTION,
    "Condition": CONDITION,
    "Control": CONTROL,
    "Decorator": DECORATOR,
    "SubTree": SUBTREE,
}
#: Built-in nodes whose port holds a script, checked when the tree is loaded.
SCRIPT_PORTS = {"Script": "code", "ScriptCondition": "code", "Precondition": "if"}
MODEL_PORT_TAGS = {
    "input_port": "input",
    "output_port": "output",
    "inout_port": "inout",
    "bidirectional_port": "inout",  # Nav2's nav2_tree_nodes.xml spelling
}


class TreeError(ValueError):
    """A tree that cannot be loaded; ``str()`` is one line naming file, line and problem."""

    def __init__(self, message: str, file: str = "", line: int | None = None) -> None:
        self.file, self.line, self.problem = file, line, message
        where = file + (f":{line}" if line else "") if file else ""
        super().__init__(f"{where}: {message}" if where else message)


@dataclass
class _Definition:
    element: etree._Element
    file: str


@dataclass
class _Document:
    file: str
    root: etree._Element
    format: int | None
    main: str | None
    definitions: dict[str, _Definition] = field(default_factory=dict)


def _parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_comments=True,
        remove_pis=True,
    )


def parse_xml(data: bytes, file: str) -> etree._Element:
    """Parse untrusted XML bytes safely; a DTD or entity declaration is refused, and so
    is a file over the size limit or an element with too many attributes."""
    limit = limits.current().max_file_bytes
    if len(data) > limit:
        raise TreeError(f"file is larger than {limit} bytes (--max-file-size)", file)
    try:
        document = etree.fromstring(data, _parser()).getroottree()
    except etree.XMLSyntaxError as error:
        line = error.lineno if error.lineno else None
        message = error.msg if hasattr(error, "msg") and error.msg else str(error)
        raise TreeError(f"malformed XML: {message}", file, line) from None
    if document.docinfo.doctype or document.docinfo.internalDTD is not None:
        raise TreeError("DOCTYPE declarations are not allowed", file, 1)
    root = document.getroot()
    for element in root.iter():
        # lxml reads an element's attribute values in quadratic time: bound their count.
        if len(element.attrib) > limits.MAX_ATTRIBUTES:
            raise TreeError(
                f"an element has more than {limits.MAX_ATTRIBUTES} attributes",
                file,
                element.sourceline,
            )
    return root


def _read_bytes(source: str | os.PathLike) -> bytes:
    try:
        return limits.read_bounded(source)
    except OSError as error:
        raise TreeError(f"cannot read the file: {error.strerror}", str(source)) from None
    except limits.LimitError as error:
        raise TreeError(str(error), str(source)) from None


def load_tree(
    source: str | os.PathLike,
    registry: Registry | None = None,
    main_tree: str | None = None,
    accept_unknown: bool = False,
) -> Tree:
    """Load a tree from an XML file (its includes resolved against its folder);
    ``accept_unknown`` accepts node types btlog has no implementation of (imports)."""
    data = _read_bytes(source)
    loader = _Loader(registry or Registry(), accept_unknown)
    return loader.load(data, str(source), Path(source).parent, main_tree)


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
    loader = _Loader(registry or Registry(), accept_unknown)
    return loader.load(data, file, Path(base_dir), main_tree)


def load_nodes_model(source: str | os.PathLike, registry: Registry | None = None) -> Registry:
    """A copy of ``registry`` with the declarations of the ``<TreeNodesModel>`` in the XML
    file ``source`` (e.g. BT.CPP's ``writeTreeNodesModelXML``); other elements are ignored."""
    file = str(source)
    root = parse_xml(_read_bytes(source), file)
    loader = _Loader(registry or Registry(), accept_unknown=True)
    models = [c for c in root if c.tag == "TreeNodesModel"]
    if root.tag != "root" or not models:
        raise TreeError("no <TreeNodesModel> under <root>", file, root.sourceline)
    for element in models:
        loader._read_model(element, file)
    return loader.registry


class _Loader:
    def __init__(self, registry: Registry, accept_unknown: bool = False) -> None:
        self.registry = registry.copy()
        self.accept_unknown = accept_unknown
        self.documents: list[_Document] = []
        self.definitions: dict[str, _Definition] = {}
        #: subtree instances of BT.CPP-written XML, by their ``_fullpath``
        self.instances: dict[str, _Definition] = {}
        self.format = 4
        self.uid = 0
        self.max_nodes = limits.MAX_NODES
        self.tree: Tree | None = None

    # -- documents ---------------------------------------------------------------------
    def load(self, data: bytes, file: str, folder: Path, main_tree: str | None) -> Tree:
        self._read_document(data, file, folder, depth=0, seen=())
        first = self.documents[0]
        self.format = first.format or 3
        main = main_tree or first.main
        if not self.definitions:
            raise TreeError("no <BehaviorTree> is defined", file, first.root.sourceline)
        if main is None:
            if len(self.definitions) != 1:
                raise TreeError(
                    "several <BehaviorTree> and no main_tree_to_execute",
                    file,
                    first.root.sourceline,
                )
            main = next(iter(self.definitions))
        if main not in self.definitions:
            raise TreeError(f"main tree {main!r} is not defined", file, first.root.sourceline)
        definition = self.definitions[main]
        self.max_nodes = limits.current().max_nodes
        if _expanded_size(self.definitions, main, self.max_nodes) > self.max_nodes:
            raise TreeError(
                f"tree {main!r} expands to more than {self.max_nodes} nodes once its "
                "SubTrees are expanded (--max-nodes)",
                definition.file,
                definition.element.sourceline,
            )
        root = self._build_tree_root(
            main, definition, parent=None, scope="", prefix="", ancestors=(main,), depth=0
        )
        return Tree(
            root=root, name=main, format=self.format, files=[d.file for d in self.documents]
        )

    def _read_document(
        self, data: bytes, file: str, folder: Path, depth: int, seen: tuple[str, ...]
    ) -> None:
        root = parse_xml(data, file)
        if root.tag != "root":
            raise TreeError(
                f"the top element must be <root>, not <{root.tag}>", file, root.sourceline
            )
        fmt = root.get("BTCPP_format")
        if fmt is not None and fmt.strip() not in ("3", "4"):
            raise TreeError(f"unsupported BTCPP_format {fmt!r} (3 or 4)", file, root.sourceline)
        document = _Document(
            file, root, int(fmt) if fmt else None, root.get("main_tree_to_execute")
        )
        self.documents.append(document)
        children = [c for c in root if isinstance(c.tag, str)]
        for element in children:
            if element.tag == "BehaviorTree":
                self._define(element, file, len(children))
            elif element.tag == "TreeNodesModel":
                self._read_model(element, file)
            elif element.tag == "include":
                self._include(element, file, folder, depth, (*seen, file))
            else:
                raise TreeError(
                    f"unexpected element <{element.tag}> under <root>", file, element.sourceline
                )

    def _define(self, element: etree._Element, file: str, siblings: int) -> None:
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
            self.instances[fullpath] = _Definition(element, file)
            if tree_id in self.definitions:
                return  # another instance of a subtree, in BT.CPP-written XML
        if tree_id in self.definitions:
            raise TreeError(f"tree {tree_id!r} is defined twice", file, element.sourceline)
        nodes = [c for c in element if isinstance(c.tag, str)]
        if len(nodes) != 1:
            raise TreeError(
                f"<BehaviorTree ID={tree_id!r}> must have exactly one child, found {len(nodes)}",
                file,
                element.sourceline,
            )
        self.definitions[tree_id] = _Definition(element, file)

    def _include(
        self, element: etree._Element, file: str, folder: Path, depth: int, seen: tuple[str, ...]
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
        self._read_document(data, str(path), path.parent, depth + 1, seen)

    def _read_model(self, element: etree._Element, file: str) -> None:
        for entry in element:
            if not isinstance(entry.tag, str):
                continue
            kind = MODEL_KINDS.get(entry.tag)
            type_id = entry.get("ID")
            if kind is None or not type_id:
                raise TreeError(
                    f"<{entry.tag}> in <TreeNodesModel> needs a known tag and an ID",
                    file,
                    entry.sourceline,
                )
            ports = {}
            for port in entry:
                if not isinstance(port.tag, str):
                    continue
                if port.tag == "MetadataFields":
                    continue
                direction = MODEL_PORT_TAGS.get(port.tag)
                if direction is None or not port.get("name"):
                    raise TreeError(
                        f"unexpected <{port.tag}> in the model of {type_id!r}",
                        file,
                        port.sourceline,
                    )
                ports[port.get("name")] = PortSpec(
                    direction,
                    port.get("type") or "str",
                    port.get("default"),
                    (port.text or "").strip(),
                )
            existing = self.registry.get(type_id)
            if kind == SUBTREE:
                self.registry.register(NodeType(type_id, SUBTREE, ports, declared_only=True))
            elif existing is None or existing.declared_only:
                children = {CONTROL: (1, None), DECORATOR: (1, 1)}.get(kind, (0, 0))
                self.registry.register(
                    NodeType(type_id, kind, ports, children=children, declared_only=True)
                )

    # -- nodes -------------------------------------------------------------------------
    def _next_uid(self, file: str, line: int, depth: int) -> int:
        if depth > limits.MAX_DEPTH:
            raise TreeError(
                f"the tree is deeper than {limits.MAX_DEPTH} levels once its SubTrees are expanded",
                file,
                line,
            )
        if self.uid >= self.max_nodes:
            raise TreeError(f"the tree has more than {self.max_nodes} nodes (--max-nodes)", file)
        self.uid += 1
        return self.uid

    def _build_tree_root(
        self,
        tree_id: str,
        definition: _Definition,
        parent: Node | None,
        scope: str,
        prefix: str,
        ancestors: tuple[str, ...],
        depth: int,
    ) -> Node:
        element = next(c for c in definition.element if isinstance(c.tag, str))
        return self._build(element, definition.file, parent, scope, prefix, ancestors, depth)

    def _build(
        self,
        element: etree._Element,
        file: str,
        parent: Node | None,
        scope: str,
        prefix: str,
        ancestors: tuple[str, ...],
        depth: int,
    ) -> Node:
        line = element.sourceline or 0
        tag = element.tag
        children = [c for c in element if isinstance(c.tag, str)]
        if tag in SUBTREE_TAGS:
            return self._build_subtree(element, file, parent, scope, prefix, ancestors, depth)
        if tag in GENERIC_TAGS:
            type_id = element.get("ID")
            if not type_id:
                raise TreeError(f"<{tag}> needs an ID attribute", file, line)
        else:
            type_id = tag
            if element.get("ID") is not None:
                raise TreeError(
                    f"<{tag}> must not have an ID attribute (use <Action ID=…>)", file, line
                )
        node_type = self.registry.get(type_id)
        strict = node_type is not None and not self.accept_unknown
        if node_type is None and self.accept_unknown:
            node_type = _imported_type(type_id, tag, len(children))
        elif node_type is None:
            if children:
                raise TreeError(f"unknown node type {type_id!r} with children", file, line)
            node_type = NodeType(type_id, leaf_kind(tag))
        elif node_type.declared_only and node_type.kind in (CONTROL, DECORATOR):
            if self.accept_unknown:
                node_type = _imported_type(type_id, tag, len(children), node_type)
            else:
                raise TreeError(
                    f"node type {type_id!r} is declared in <TreeNodesModel> but btlog "
                    "has no implementation of it",
                    file,
                    line,
                )
        if node_type.kind == SUBTREE:
            raise TreeError(f"{type_id!r} is a subtree; use <SubTree ID={type_id!r}/>", file, line)
        type_id = node_type.id
        low, high = node_type.children
        if len(children) < low or (high is not None and len(children) > high):
            expected = (
                str(low)
                if low == high
                else f"at least {low}"
                if high is None
                else f"{low} to {high}"
            )
            raise TreeError(
                f"{type_id} must have {expected} children, found {len(children)}", file, line
            )
        uid = self._next_uid(file, line, depth)
        name = element.get("name", type_id)
        node = Node(
            uid=uid,
            type=type_id,
            name=name,
            kind=node_type.kind,
            parent=parent,
            scope=scope,
            file=file,
            line=line,
        )
        node.path = prefix + name + (f"::{uid}" if name == type_id else "")
        node.ports, node.attributes = self._ports(element, node_type, strict, file, line)
        for child in children:
            node.children.append(
                self._build(child, file, node, scope, prefix, ancestors, depth + 1)
            )
        return node

    def _ports(
        self, element: etree._Element, node_type: NodeType, strict: bool, file: str, line: int
    ) -> tuple[dict[str, Port], dict[str, str]]:
        """Ports as written plus declared defaults; a known type's unknown port is an error
        (a type declared only by an empty model entry accepts any port)."""
        ports: dict[str, Port] = {}
        attributes: dict[str, str] = {}
        strict = strict and (bool(node_type.ports) or not node_type.declared_only)
        for attribute, value in element.attrib.items():
            if attribute in ("name", "ID"):
                continue
            if _special_attribute(attribute, value, attributes, file, line):
                continue
            if strict and attribute not in node_type.ports:
                raise TreeError(f"{node_type.id} has no port {attribute!r}", file, line)
            spec = node_type.ports.get(attribute)
            if spec is not None and not self.accept_unknown and blackboard_key(value) is None:
                _check_literal(value, spec, attribute, node_type.id, file, line)
            ports[attribute] = Port(value, node_type.port_direction(attribute))
        for port_name, spec in node_type.ports.items():
            if port_name not in ports and spec.default is not None:
                ports[port_name] = Port(spec.default, spec.direction)
        script_port = SCRIPT_PORTS.get(node_type.id) if strict else None
        if script_port in ports and blackboard_key(ports[script_port].value) is None:
            _check_script(ports[script_port].value, script_port, file, line)
        return ports, attributes

    def _build_subtree(
        self,
        element: etree._Element,
        file: str,
        parent: Node | None,
        scope: str,
        prefix: str,
        ancestors: tuple[str, ...],
        depth: int,
    ) -> Node:
        line = element.sourceline or 0
        subtree_id = element.get("ID")
        if not subtree_id:
            raise TreeError("<SubTree> needs an ID attribute", file, line)
        if [c for c in element if isinstance(c.tag, str)]:
            raise TreeError(f"<SubTree ID={subtree_id!r}> must not have children", file, line)
        if subtree_id not in self.definitions:
            raise TreeError(f"subtree {subtree_id!r} is not defined", file, line)
        if subtree_id in ancestors:
            chain = " -> ".join((*ancestors[ancestors.index(subtree_id) :], subtree_id))
            raise TreeError(f"subtree cycle: {chain}", file, line)
        v3_plain = self.format == 3 and element.tag == "SubTree"
        uid = self._next_uid(file, line, depth)
        fullpath = element.get("_fullpath")
        given_name = element.get("name") or _name_from_fullpath(fullpath, subtree_id, uid)
        name = subtree_id if v3_plain else given_name or subtree_id
        node = Node(
            uid=uid,
            type="SubTree",
            name=name,
            kind=SUBTREE,
            parent=parent,
            scope=scope,
            file=file,
            line=line,
        )
        node.path = prefix + name + (f"::{uid}" if name == subtree_id and not v3_plain else "")
        attributes = {"subtree_id": subtree_id}
        ports: dict[str, Port] = {}
        for attribute, value in element.attrib.items():
            if attribute in ("ID", "name") or attribute in V3_IGNORED:
                continue
            if attribute == "_autoremap":
                attributes["_autoremap"] = value
                continue
            if _special_attribute(attribute, value, attributes, file, line):
                continue
            if v3_plain and blackboard_key(value) is None:
                value = "{" + value + "}"
            ports[attribute] = Port(value)
        if element.get("__autoremap") is not None:
            attributes["_autoremap"] = element.get("__autoremap")
        if v3_plain and element.get("__shared_blackboard", "false").lower() == "true":
            attributes["shared_blackboard"] = "true"
        self._apply_subtree_model(subtree_id, ports, attributes, file, line)
        node.ports, node.attributes = ports, attributes
        shared = attributes.get("shared_blackboard") == "true"
        if v3_plain:
            inner = scope if shared else (f"{scope}/" if scope else "") + subtree_id
        else:
            given = given_name
            inner = (f"{scope}/" if scope else "") + (given if given else f"{subtree_id}::{uid}")
        definition = (
            self.instances.get(fullpath or "")
            or self.instances.get((fullpath or "").removesuffix(f"::{uid}"))
            or self.definitions[subtree_id]
        )
        child = self._build_tree_root(
            subtree_id,
            definition,
            node,
            inner,
            inner + "/",
            (*ancestors, subtree_id),
            depth + 1,
        )
        node.children.append(child)
        return node

    def _apply_subtree_model(
        self,
        subtree_id: str,
        ports: dict[str, Port],
        attributes: dict[str, str],
        file: str,
        line: int,
    ) -> None:
        model = self.registry.get(subtree_id)
        if model is None or model.kind != SUBTREE:
            return
        autoremap = attributes.get("_autoremap", "false").lower() == "true"
        for port_name, spec in model.ports.items():
            if port_name in ports:
                continue
            if spec.default is not None:
                ports[port_name] = Port(spec.default, spec.direction)
            elif not autoremap:
                raise TreeError(
                    f"subtree {subtree_id!r}: port {port_name!r} is neither "
                    "remapped nor given a default",
                    file,
                    line,
                )


def _imported_type(
    type_id: str, tag: str, children: int, declared: NodeType | None = None
) -> NodeType:
    """The type of a node btlog cannot run, in an imported tree: kind from its declaration,
    a generic tag, or its children; any number of children."""
    if declared is not None:
        kind = declared.kind
    elif tag in GENERIC_TAGS:
        kind = GENERIC_TAGS[tag]
    elif children:
        kind = DECORATOR if children == 1 else CONTROL
    else:
        kind = leaf_kind(tag)
    ports = declared.ports if declared is not None else {}
    bounds = (0, None) if kind in (CONTROL, DECORATOR) else (0, 0)
    return NodeType(type_id, kind, ports, children=bounds, declared_only=True)


def _name_from_fullpath(fullpath: str | None, subtree_id: str, uid: int) -> str | None:
    """A SubTree's instance name from BT.CPP's ``_fullpath`` (None when it was unnamed)."""
    if not fullpath:
        return None
    last = fullpath.rsplit("/", 1)[-1]
    return None if last == f"{subtree_id}::{uid}" else last


def _expanded_size(definitions: dict[str, _Definition], main: str, cap: int) -> int:
    """How many nodes tree ``main`` has once every SubTree is expanded (capped just above
    ``cap``), counted per definition without expanding anything, so that a SubTree bomb
    of a few KB is refused at once. Cycles count nothing here (the build reports them)."""
    own: dict[str, int] = {}
    calls: dict[str, list[str]] = {}
    for tree_id, definition in definitions.items():
        elements = [e for e in definition.element.iter() if isinstance(e.tag, str)][1:]
        own[tree_id] = len(elements)
        calls[tree_id] = [
            e.get("ID", "")
            for e in elements
            if e.tag in SUBTREE_TAGS and e.get("ID", "") in definitions
        ]
    sizes: dict[str, int] = {}
    path = {main}
    stack = [(main, iter(calls[main]))]
    while stack:  # depth-first, post-order, without recursion
        tree_id, pending = stack[-1]
        called = next((c for c in pending if c not in sizes and c not in path), None)
        if called is not None:
            path.add(called)
            stack.append((called, iter(calls[called])))
            continue
        stack.pop()
        path.discard(tree_id)
        total = own[tree_id] + sum(sizes.get(c, 0) for c in calls[tree_id])
        sizes[tree_id] = min(total, cap + 1)
    return sizes[main]


def _special_attribute(
    attribute: str, value: str, attributes: dict[str, str], file: str, line: int
) -> bool:
    """Keep a reserved or ``_``-prefixed attribute (checking pre/post-condition scripts)
    and return True; return False for a port, after checking that its name is valid."""
    if attribute in RESERVED or attribute.startswith("_"):
        if attribute in PRECONDITIONS or attribute in POSTCONDITIONS:
            _check_script(value, attribute, file, line)
        attributes[attribute] = value
        return True
    if not _allowed_port_name(attribute):
        raise TreeError(f"{attribute!r} is not a valid port name", file, line)
    return False


_FORBIDDEN_PORT_CHARS = set(" \t\n\r<>&\"'/\\:*?|.")


def _allowed_port_name(name: str) -> bool:
    return bool(name) and name[0].isalpha() and not (set(name) & _FORBIDDEN_PORT_CHARS)


def _check_literal(
    value: str, spec: PortSpec, port: str, type_id: str, file: str, line: int
) -> None:
    from btlog.tree.ports import PortValueError, convert

    try:
        convert(value, spec.type)
    except PortValueError as error:
        raise TreeError(
            f"{type_id}: bad value {value!r} for port {port!r}: {error}", file, line
        ) from None


def _check_script(code: str, attribute: str, file: str, line: int) -> None:
    from btlog.tree.script import ScriptError, compile_script

    try:
        compile_script(code)
    except ScriptError as error:
        raise TreeError(f"{attribute}: {error}", file, line) from None

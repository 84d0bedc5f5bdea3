"""Build the ``Tree`` of one main tree from its documents' definitions.

``<SubTree>`` nodes are expanded in place with a new blackboard scope, and UIDs are
assigned in depth-first pre-order from 1 with each subtree's nodes right after its SubTree
node. v3 rules apply when the first document has no ``BTCPP_format``: a SubTree's
instance name is forced to its ID and its remapping ``a="b"`` names the parent key ``b``.
With ``accept_unknown`` (imported runs) a type btlog cannot run takes its kind from its
declaration, a generic tag (``<Control ID=…>``) or its children (none: action, one:
decorator, more: control). The tree is bounded in nodes and depth once its SubTrees are
expanded, checked before expanding them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from btlog import limits
from btlog.tree.declared import DeclaredTypes
from btlog.tree.descriptions import DESCRIPTION
from btlog.tree.documents import SUBTREE_TAGS, Definition, Documents
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
    leaf_kind,
)
from btlog.tree.xml_source import TreeError
from btlog.tree.xml_syntax import XmlElement

GENERIC_TAGS = {
    "Action": ACTION,
    "Condition": CONDITION,
    "Control": CONTROL,
    "Decorator": DECORATOR,
}
V3_IGNORED = frozenset({"__shared_blackboard", "__autoremap", "_description"})
#: Built-in nodes whose port holds a script, checked when the tree is loaded.
SCRIPT_PORTS = {"Script": "code", "ScriptCondition": "code", "Precondition": "if"}


@dataclass(frozen=True)
class BuildContext:
    """Where an element is built: its file, parent node, blackboard scope, path prefix,
    the subtree IDs it is inside of (to refuse cycles) and its depth."""

    file: str
    parent: Node | None = None
    scope: str = ""
    prefix: str = ""
    ancestors: tuple[str, ...] = ()
    depth: int = 0


class TreeBuilder:
    """Builds nodes from the definitions of ``documents``, numbering them as it goes."""

    def __init__(self, documents: Documents, accept_unknown: bool = False) -> None:
        self.documents = documents
        self.registry = documents.registry
        self.accept_unknown = accept_unknown
        first = documents.documents[0]
        self.format = first.format or 3
        self.uid = 0
        self.max_nodes = limits.MAX_NODES
        self.declared = DeclaredTypes()
        self.port_types: dict[str, dict[str, str]] = {}

    def build(self, main: str) -> Tree:
        """The tree ``main`` with every SubTree expanded; refused before building when it
        would have more than ``--max-nodes`` nodes."""
        definition = self.documents.definitions[main]
        self.max_nodes = limits.current().max_nodes
        if _expanded_size(self.documents.definitions, main, self.max_nodes) > self.max_nodes:
            raise TreeError(
                f"tree {main!r} expands to more than {self.max_nodes} nodes once its "
                "SubTrees are expanded (--max-nodes)",
                definition.file,
                definition.element.sourceline,
            )
        context = BuildContext(definition.file, ancestors=(main,))
        root = self._build(definition.root_element(), context)
        _describe_by_tree(root, definition)
        files = self.documents.files({node.file for node in root.walk()})
        tree = Tree(root=root, name=main, format=self.format, files=files)
        tree.warnings = list(self.declared.warnings.values())
        tree.port_types = self.port_types
        return tree

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

    def _build(self, element: XmlElement, context: BuildContext) -> Node:
        file, line, tag = context.file, element.sourceline or 0, element.tag
        if tag in SUBTREE_TAGS:
            return self._build_subtree(element, context)
        children = element.children
        node_type, strict = self._node_type(element, len(children), file, line)
        uid = self._next_uid(file, line, context.depth)
        type_id = node_type.id
        if node_type.ports and type_id not in self.port_types:
            self.port_types[type_id] = {n: spec.type for n, spec in node_type.ports.items()}
        name = element.get("name", type_id)
        node = Node(
            uid=uid,
            type=type_id,
            name=name,
            kind=node_type.kind,
            parent=context.parent,
            scope=context.scope,
            file=file,
            line=line,
        )
        node.path = context.prefix + name + (f"::{uid}" if name == type_id else "")
        node.ports, node.attributes = self._ports(element, node_type, strict, file, line)
        inner = replace(context, parent=node, depth=context.depth + 1)
        for child in children:
            node.children.append(self._build(child, inner))
        return node

    def _node_type(
        self, element: XmlElement, children: int, file: str, line: int
    ) -> tuple[NodeType, bool]:
        """The element's node type, and whether its ports are checked against it."""
        tag = element.tag
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
        where = f"{file}:{line}"
        if node_type is None and self.accept_unknown:
            node_type = _imported_type(type_id, tag, children)
        elif node_type is None and tag in ("Control", "Decorator"):
            declared = NodeType(type_id, GENERIC_TAGS[tag], declared_only=True)
            node_type = self.declared.resolve(declared, children, where)
        elif node_type is None:
            if children:
                raise TreeError(
                    f"unknown node type {type_id!r} with children: BT.CPP would need the "
                    "code that registers it (a plugin, or the program's registerNodeType); "
                    "declared in a <TreeNodesModel> (the tree's, or --nodes-model) it runs "
                    "as a pass-through",
                    file,
                    line,
                )
            node_type = NodeType(type_id, leaf_kind(tag))
        elif node_type.declared_only and self.accept_unknown:
            if node_type.kind in (CONTROL, DECORATOR):
                node_type = _imported_type(type_id, tag, children, node_type)
        elif node_type.declared_only:
            node_type = self.declared.resolve(node_type, children, where)
        if node_type.kind == SUBTREE:
            raise TreeError(f"{type_id!r} is a subtree; use <SubTree ID={type_id!r}/>", file, line)
        low, high = node_type.children
        if children < low or (high is not None and children > high):
            expected = (
                str(low)
                if low == high
                else f"at least {low}"
                if high is None
                else f"{low} to {high}"
            )
            raise TreeError(
                f"{node_type.id} must have {expected} children, found {children}", file, line
            )
        return node_type, strict

    def _ports(
        self, element: XmlElement, node_type: NodeType, strict: bool, file: str, line: int
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
                self._unknown_port(node_type, attribute, file, line)
            spec = node_type.ports.get(attribute)
            if spec is not None and not self.accept_unknown and blackboard_key(value) is None:
                problem = _literal_problem(value, spec)
                if problem is not None and node_type.declared_only:
                    self.declared.bad_literal(node_type.id, attribute, problem, f"{file}:{line}")
                elif problem is not None:
                    raise TreeError(
                        f"{node_type.id}: bad value {value!r} for port {attribute!r}: {problem}",
                        file,
                        line,
                    )
            ports[attribute] = Port(value, node_type.port_direction(attribute))
        for port_name, spec in node_type.ports.items():
            if port_name not in ports and spec.default is not None:
                ports[port_name] = Port(spec.default, spec.direction)
        script_port = SCRIPT_PORTS.get(node_type.id) if strict else None
        if script_port in ports and blackboard_key(ports[script_port].value) is None:
            _check_script(ports[script_port].value, script_port, file, line)
        return ports, attributes

    def _unknown_port(self, node_type: NodeType, port: str, file: str, line: int) -> None:
        """A port the type does not declare: refused for BT.CPP's own types (BT.CPP
        refuses it too), warned about for a model's types and plugin types (the XML wins)."""
        if node_type.declared_only or node_type.plugin:
            note = (
                "in the nodes model"
                if node_type.declared_only
                else "in btlog's implementation (a plugin's ports differ between versions)"
            )
            self.declared.unknown_port(node_type.id, port, f"{file}:{line}", note)
            return
        known = ", ".join(node_type.ports) or "none"
        raise TreeError(
            f"{node_type.id} has no port {port!r} (its ports: {known}); BT.CPP refuses it too",
            file,
            line,
        )

    def _build_subtree(self, element: XmlElement, context: BuildContext) -> Node:
        file, line = context.file, element.sourceline or 0
        subtree_id = element.get("ID")
        if not subtree_id:
            raise TreeError("<SubTree> needs an ID attribute", file, line)
        if element.children:
            raise TreeError(f"<SubTree ID={subtree_id!r}> must not have children", file, line)
        if subtree_id not in self.documents.definitions:
            raise TreeError(
                f"subtree {subtree_id!r} is not defined: BT.CPP would need the file that "
                "defines it registered too (--trees FILE or FOLDER) or <include>d",
                file,
                line,
            )
        ancestors = context.ancestors
        if subtree_id in ancestors:
            chain = " -> ".join((*ancestors[ancestors.index(subtree_id) :], subtree_id))
            raise TreeError(f"subtree cycle: {chain}", file, line)
        v3_plain = self.format == 3 and element.tag == "SubTree"
        uid = self._next_uid(file, line, context.depth)
        fullpath = element.get("_fullpath")
        given_name = element.get("name") or _name_from_fullpath(fullpath, subtree_id, uid)
        name = subtree_id if v3_plain else given_name or subtree_id
        node = Node(
            uid=uid,
            type="SubTree",
            name=name,
            kind=SUBTREE,
            parent=context.parent,
            scope=context.scope,
            file=file,
            line=line,
        )
        node.path = (
            context.prefix + name + (f"::{uid}" if name == subtree_id and not v3_plain else "")
        )
        node.ports, node.attributes = self._subtree_ports(element, subtree_id, v3_plain, file, line)
        scope = context.scope
        if v3_plain:
            shared = node.attributes.get("shared_blackboard") == "true"
            inner = scope if shared else (f"{scope}/" if scope else "") + subtree_id
        else:
            own = given_name if given_name else f"{subtree_id}::{uid}"
            inner = (f"{scope}/" if scope else "") + own
        instances = self.documents.instances
        definition: Definition = (
            instances.get(fullpath or "")
            or instances.get((fullpath or "").removesuffix(f"::{uid}"))
            or self.documents.definitions[subtree_id]
        )
        inside = BuildContext(
            definition.file, node, inner, inner + "/", (*ancestors, subtree_id), context.depth + 1
        )
        node.children.append(self._build(definition.root_element(), inside))
        _describe_by_tree(node, definition)
        return node

    def _subtree_ports(
        self, element: XmlElement, subtree_id: str, v3_plain: bool, file: str, line: int
    ) -> tuple[dict[str, Port], dict[str, str]]:
        """A SubTree's remappings (v3: ``a="b"`` is the key ``{b}``) and attributes, with
        the defaults of the subtree's model."""
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
        autoremap = element.get("__autoremap")
        if autoremap is not None:
            attributes["_autoremap"] = autoremap
        if v3_plain and element.get("__shared_blackboard", "false").lower() == "true":
            attributes["shared_blackboard"] = "true"
        self._apply_subtree_model(subtree_id, ports, attributes, file, line)
        return ports, attributes

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


def _expanded_size(definitions: dict[str, Definition], main: str, cap: int) -> int:
    """How many nodes tree ``main`` has once every SubTree is expanded (capped just above
    ``cap``), counted per definition without expanding anything, so that a SubTree bomb
    of a few KB is refused at once. Cycles count nothing here (the build reports them)."""
    own: dict[str, int] = {}
    calls: dict[str, list[str]] = {}
    for tree_id, definition in definitions.items():
        own[tree_id] = sum(1 for _ in definition.element.iter()) - 1
        calls[tree_id] = [c for c in definition.calls() if c in definitions]
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


def _describe_by_tree(node: Node, definition: Definition) -> None:
    """A ``<BehaviorTree _description="…">`` describes the node that runs it (the main
    tree's root, or the SubTree node), unless that node has a description of its own."""
    described = definition.element.get(DESCRIPTION, "").strip()
    if described and not node.attributes.get(DESCRIPTION, "").strip():
        node.attributes[DESCRIPTION] = described


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


def _literal_problem(value: str, spec: PortSpec) -> str | None:
    """Why the port's type refuses the literal ``value`` (None when it takes it)."""
    from btlog.tree.ports import PortValueError, convert

    try:
        convert(value, spec.type)
    except PortValueError as error:
        return str(error)
    return None


def _check_script(code: str, attribute: str, file: str, line: int) -> None:
    from btlog.tree.script import ScriptError, compile_script

    try:
        compile_script(code)
    except ScriptError as error:
        raise TreeError(f"{attribute}: {error}", file, line) from None

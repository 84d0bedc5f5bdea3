"""A py_trees tree as a btlog tree: each behaviour a node the explanation algorithms read.

A behaviour's ``name`` is the node's name (on one line: a name broken over lines for
py_trees' dot graphs is joined with spaces, the original kept as ``py_trees_name``); a
composite or decorator named as its class, py_trees' default name, is nameless, as a
BT.CPP node with ``name=""`` (answers speak of what it serves, not of "sequence").
Its type is the py_trees class name, except for the composites and decorators that have
a BehaviorTree.CPP counterpart with the same semantics: those get that counterpart's
type (``SEMANTICS``), so the algorithms, which know BT.CPP's control flow by type
(``btlog.explain.flow``, ``btlog.explain.handlers``), read them as they are; the
py_trees class is kept in the attribute ``py_trees``. Parameters become the ports the
BT.CPP type has (``num_attempts`` of a Retry, ``num_cycles`` of a Repeat,
``success_count`` of a Parallel, ``msec`` of a Timeout). A composite or decorator
without a counterpart keeps its class as its type; for a decorator the algorithms then
take "the child's result is mine" (``btlog.explain.flow``'s rule for decorators without
one). Leaves are actions, except the blackboard checks of ``py_trees.behaviours``
(``CONDITION_CLASSES``) and any behaviour with a ``btlog_kind`` attribute of
``"condition"``.

Uids are given in depth-first pre-order from 1, as btlog's loader gives them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from btlog.tree.model import ACTION, CONDITION, CONTROL, DECORATOR, Node, Port, Tree

#: The attribute that keeps the py_trees class of a node.
CLASS_ATTRIBUTE = "py_trees"

#: py_trees leaves that check rather than act.
CONDITION_CLASSES = frozenset(
    {
        "CheckBlackboardVariableExists",
        "CheckBlackboardVariableValue",
        "CheckBlackboardVariableValues",
        "CompareBlackboardVariables",
        "BlackboardToStatus",
    }
)


def _memory(when: str, otherwise: str) -> Callable[[Any], tuple[str, dict[str, str]]]:
    """A composite whose BT.CPP type depends on its ``memory``."""

    def semantics(behaviour: Any) -> tuple[str, dict[str, str]]:
        return (when if behaviour.memory else otherwise), {}

    return semantics


def _parallel(behaviour: Any) -> tuple[str, dict[str, str]]:
    """Parallel: any failure fails it; the policy says how many successes it needs."""
    policy = behaviour.policy
    name = type(policy).__name__
    if name == "SuccessOnOne":
        needed = "1"
    elif name == "SuccessOnSelected":
        needed = str(len(getattr(policy, "children", []) or []))
    else:
        needed = "-1"  # every child (BT.CPP's -1)
    return "Parallel", {"success_count": needed, "failure_count": "1"}


def _fixed(type_id: str, **ports: Callable[[Any], Any]) -> Callable[[Any], Any]:
    def semantics(behaviour: Any) -> tuple[str, dict[str, str]]:
        return type_id, {port: str(read(behaviour)) for port, read in ports.items()}

    return semantics


#: py_trees class name -> how to give a behaviour of it a BT.CPP type and its ports.
SEMANTICS: dict[str, Callable[[Any], tuple[str, dict[str, str]]]] = {
    "Sequence": _memory("Sequence", "ReactiveSequence"),
    "Selector": _memory("Fallback", "ReactiveFallback"),
    "Parallel": _parallel,
    "Retry": _fixed("RetryUntilSuccessful", num_attempts=lambda b: b.num_failures),
    "Repeat": _fixed("Repeat", num_cycles=lambda b: b.num_success),
    "Inverter": _fixed("Inverter"),
    "FailureIsSuccess": _fixed("ForceSuccess"),
    "SuccessIsFailure": _fixed("ForceFailure"),
    "SuccessIsRunning": _fixed("KeepRunningUntilFailure"),
    "Timeout": _fixed("Timeout", msec=lambda b: round(float(b.duration) * 1000)),
}

#: The py_trees attributes kept as node attributes, when a behaviour has them.
KEPT = ("memory", "policy", "num_failures", "num_success", "duration")


def _kind(behaviour: Any, is_leaf: bool, class_name: str) -> str:
    if not is_leaf:
        return DECORATOR if hasattr(behaviour, "decorated") else CONTROL
    marked = getattr(behaviour, "btlog_kind", None)
    if marked in (ACTION, CONDITION):
        return str(marked)
    return CONDITION if class_name in CONDITION_CLASSES else ACTION


def node_of(behaviour: Any, uid: int) -> Node:
    """The parentless, childless node of one behaviour."""
    class_name = type(behaviour).__name__
    is_composite = bool(behaviour.children) or _is_composite(behaviour)
    kind = _kind(behaviour, not is_composite, class_name)
    semantics = SEMANTICS.get(class_name) if kind in (CONTROL, DECORATOR) else None
    type_id, ports = semantics(behaviour) if semantics is not None else (class_name, {})
    attributes = {CLASS_ATTRIBUTE: class_name}
    for key in KEPT if is_composite else ():
        if hasattr(behaviour, key):
            value = getattr(behaviour, key)
            attributes[key] = type(value).__name__ if key == "policy" else str(value)
    given = str(behaviour.name)
    name = " ".join(given.split())  # one line: py_trees' dot graphs break names
    if name == class_name and kind in (CONTROL, DECORATOR):
        name = ""  # py_trees' default name: a nameless helper, as name="" in BT.CPP's XML
    if name != given:
        attributes["py_trees_name"] = given
    return Node(
        uid=uid,
        type=type_id,
        name=name,
        kind=kind,
        ports={key: Port(value) for key, value in ports.items()},
        attributes=attributes,
        path=f"{name}::{uid}",
    )


def _is_composite(behaviour: Any) -> bool:
    """True for a composite with no children yet (it is still a control node)."""
    return any(cls.__name__ == "Composite" for cls in type(behaviour).__mro__)


def build_subtree(root: Any, first_uid: int) -> tuple[Node, list[tuple[Any, Node]]]:
    """The nodes of ``root``'s subtree, uids from ``first_uid`` in pre-order; also each
    behaviour with its node, in that order."""
    pairs: list[tuple[Any, Node]] = []
    uid = first_uid

    def build(behaviour: Any, parent: Node | None) -> Node:
        nonlocal uid
        node = node_of(behaviour, uid)
        uid += 1
        node.parent = parent
        pairs.append((behaviour, node))
        for child in behaviour.children:
            node.children.append(build(child, node))
        return node

    return build(root, None), pairs


def tree_of(root: Any, name: str = "") -> tuple[Tree, list[tuple[Any, Node]]]:
    """The btlog tree of the behaviour ``root`` (named ``name``, else the root's name),
    and each behaviour with its node, in pre-order."""
    node, pairs = build_subtree(root, 1)
    return Tree(root=node, name=name or str(root.name)), pairs


def behaviours(root: Any) -> Iterator[Any]:
    """Every behaviour of ``root``'s subtree in pre-order (py_trees' ``iterate`` is
    post-order)."""
    stack = [root]
    while stack:
        behaviour = stack.pop()
        yield behaviour
        stack.extend(reversed(behaviour.children))

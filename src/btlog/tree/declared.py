"""Node types btlog knows only from a declaration: what a simulated run does with them.

A ``<TreeNodesModel>`` (the tree's own, or ``--nodes-model``) or a generic tag
(``<Decorator ID="WaitForEvent">``) declares a type whose code is a plugin btlog does not
have. A leaf runs as a scripted leaf of the outcomes file; a decorator or control runs as a
*pass-through* — a decorator's result is its child's, a control runs its children as a
Sequence — with a warning naming the type. A model written for another version of the
plugins may disagree with the XML: the XML wins, with a warning (a type declared a leaf
that has children in the XML runs as a pass-through decorator or control; one declared a
decorator or control without children runs as a leaf; a port the model does not list is
kept). The warnings are collected once per type and problem, for ``Tree.warnings``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from btlog.tree.model import ACTION, CONTROL, DECORATOR
from btlog.tree.registry import NodeType

#: What a pass-through of each kind does, in the warnings.
PASS_THROUGH = {
    DECORATOR: "its child's result is its own",
    CONTROL: "its children run as a Sequence",
}


@dataclass
class DeclaredTypes:
    """Resolves declared types against the XML and gathers the warnings, once each."""

    warnings: dict[tuple[str, ...], str] = field(default_factory=dict)

    def resolve(self, declared: NodeType, children: int, where: str) -> NodeType:
        """The type a node of ``declared`` runs as, given its ``children`` in the XML;
        ``where`` is ``file:line`` of the first such node, for the warning."""
        kind = declared.kind
        if kind not in (CONTROL, DECORATOR) and children:
            kind = DECORATOR if children == 1 else CONTROL
            self._warn(
                (declared.id, "kind"),
                f"{where}: the nodes model declares {declared.id!r} {_a(declared.kind)}, but "
                f"the XML gives it {_children(children)} (the XML wins)",
            )
        elif kind in (CONTROL, DECORATOR) and not children:
            kind = ACTION
            self._warn(
                (declared.id, "kind"),
                f"{where}: the nodes model declares {declared.id!r} {_a(declared.kind)}, but "
                "the XML gives it no child: it runs as a scripted action (the XML wins)",
            )
        elif kind == DECORATOR and children > 1:
            kind = CONTROL
            self._warn(
                (declared.id, "kind"),
                f"{where}: the nodes model declares {declared.id!r} a decorator, but the XML "
                f"gives it {_children(children)} (the XML wins)",
            )
        if kind in PASS_THROUGH:
            self._warn(
                (declared.id, "pass-through"),
                f"{where}: {declared.id!r} is {_a(kind)} btlog has no code for (a plugin in "
                f"BT.CPP): it runs as a pass-through, {PASS_THROUGH[kind]}",
            )
        bounds = (children, children) if kind in PASS_THROUGH else (0, 0)
        return NodeType(declared.id, kind, declared.ports, children=bounds, declared_only=True)

    def unknown_port(self, type_id: str, port: str, where: str, version_note: str) -> None:
        """A port the XML gives and the declaration lacks: kept, with a warning."""
        self._warn(
            (type_id, "port", port),
            f"{where}: {type_id} has no port {port!r} {version_note}; the XML's value is "
            "kept (the XML wins)",
        )

    def bad_literal(self, type_id: str, port: str, problem: str, where: str) -> None:
        """A literal the declared port type does not accept: kept as written, warned."""
        self._warn(
            (type_id, "value", port),
            f"{where}: {type_id}: port {port!r}: {problem} for the type the nodes model "
            "declares; the XML's value is kept as written",
        )

    def _warn(self, key: tuple[str, ...], text: str) -> None:
        self.warnings.setdefault(key, text)


def _a(kind: str) -> str:
    return f"an {kind}" if kind[0] in "aeiou" else f"a {kind}"


def _children(count: int) -> str:
    return "1 child" if count == 1 else f"{count} children"

"""The import graph of src/btlog follows the data flow of docs/design.md, "Layout".

Every ``from btlog… import`` (at module level or inside a function) must point at a layer
listed before the importing module's own layer, or at its own layer. A cycle between two
layers, or an arrow up the data flow, fails with the offending imports named; so does a
circle of modules within a layer (imports made only for type checking count: a module
that needs another's type takes a Protocol instead).
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "btlog"

#: The layers in data-flow order (docs/design.md, "Layout"); a module imports only its own
#: layer and the layers before it.
LAYERS = [
    (
        "btlog.status",
        "btlog.limits",
        "btlog.errors",
        "btlog.schema",
        "btlog.documents",
        "btlog.outputs",
    ),
    ("btlog.algorithms",),
    ("btlog.tree",),
    ("btlog.events",),
    ("btlog.executor",),
    ("btlog.domains",),
    ("btlog.record",),
    ("btlog.state", "btlog.history"),
    ("btlog.replay",),
    ("btlog.explain",),
    ("btlog.render",),
    ("btlog.live_questions", "btlog.runner"),
    ("btlog.sources", "btlog.sinks", "btlog.fleet"),
    ("btlog.checks",),
    ("btlog.view", "btlog.testing", "btlog.cli"),
]


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _layer(module: str) -> int | None:
    for rank, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank
    return None  # the package itself (btlog.__version__) sits below everything


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("btlog"):
            found |= {f"{node.module}.{alias.name}" for alias in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("btlog")}
    return found


def test_every_module_has_a_layer() -> None:
    modules = [_module_name(p) for p in SRC.rglob("*.py")]
    assert modules, "no modules found"
    assert [m for m in modules if m != "btlog" and _layer(m) is None] == []


def test_no_import_points_up_the_data_flow() -> None:
    upward = []
    for path in sorted(SRC.rglob("*.py")):
        module = _module_name(path)
        own = _layer(module)
        for target in _imports(path):
            rank = _layer(target)
            if own is not None and rank is not None and rank > own:
                upward.append(f"{module} -> {target}")
    assert upward == []


def _module_graph() -> dict[str, set[str]]:
    """Each module's imports of other btlog modules (``from btlog.x import y`` is the
    module ``btlog.x.y`` when there is one, else ``btlog.x``), those made only for type
    checking too: a circle of types is a circle all the same."""
    paths = {_module_name(p): p for p in SRC.rglob("*.py")}
    graph = {}
    for module, path in paths.items():
        targets = set()
        for target in _imports(path):
            while target not in paths and "." in target:
                target = target.rsplit(".", 1)[0]
            if target in paths and target != module:
                targets.add(target)
        graph[module] = targets
    return graph


def test_no_module_imports_itself_round_a_circle() -> None:
    graph = _module_graph()
    circles = []
    for start in sorted(graph):
        seen, stack = set(), [(start, (start,))]
        while stack:
            module, path = stack.pop()
            for target in sorted(graph[module]):
                if target == start:
                    circles.append(" -> ".join((*path, start)))
                elif target not in seen:
                    seen.add(target)
                    stack.append((target, (*path, target)))
    assert circles == []

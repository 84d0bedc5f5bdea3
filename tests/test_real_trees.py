"""Your own corpus of public trees: with ``BTLOG_REAL_TREES=DIR``, every ``*.xml`` tree under
DIR is validated and run as ``btlog validate`` and ``btlog run --max-ticks 2000`` would, and
the counts are reported by project (skipped without the variable; never commit such trees).

A tree is an XML file holding ``<BehaviorTree``; a file holding only a ``<TreeNodesModel>``
is a nodes model, given as ``--nodes-model`` to the trees of its folder and the folders
below (the nearest one). A tree whose subtrees are defined in other files of its folder is
registered with the files that define them (``--trees``), as a program registers them
before ``createTree``. The project of a file is the first two parts of its path under
DIR (``navigation2/humble``).

The test fails when a refusal is not one line naming the file (and line, for XML errors)
or is not bad input (any other exception is a bug of btlog). ``BTLOG_REAL_TREES_REPORT=F``
also writes the report to F (Markdown).
"""

from __future__ import annotations

import os
import re
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

import pytest

from btlog.errors import one_line
from btlog.executor.behavior import NodeExecutionError
from btlog.runner import RunConfig, execute, prepare
from btlog.tree.loader import TreeError

REAL = os.environ.get("BTLOG_REAL_TREES")
MAX_TICKS = 2000
pytestmark = pytest.mark.skipif(not REAL, reason="set BTLOG_REAL_TREES=DIR to run")


@dataclass
class Outcome:
    """What became of one tree file."""

    project: str
    validated: bool = False
    ran: bool = False
    finished: bool = False
    refusal: str = ""
    folder: bool = False
    halted: bool = False
    bug: str = ""


def _kind(path: Path) -> str:
    head = path.read_bytes()[:2_000_000]
    if b"<BehaviorTree" in head:
        return "tree"
    return "model" if b"<TreeNodesModel" in head else "other"


def _nearest_model(tree: Path, models: list[Path], top: Path) -> Path | None:
    folder = tree.parent
    while True:
        here = sorted(m for m in models if m.parent == folder)
        if here:
            return here[0]
        if folder in (top, top.parent) or top not in folder.parents:
            return None
        folder = folder.parent


def _project(path: Path, top: Path) -> str:
    parts = path.relative_to(top).parts
    return "/".join(parts[:2]) if len(parts) > 2 else parts[0]


def _config(tree: Path, model: Path | None, trees: list[Path]) -> RunConfig:
    return RunConfig(
        tree=str(tree),
        nodes_model=str(model) if model else None,
        max_ticks=MAX_TICKS,
        trees=[str(t) for t in trees],
    )


MISSING = re.compile(r"subtree '([^']+)' is not defined")


def _defining(folder: Path, tree_id: str, skip: list[Path]) -> Path | None:
    """The first file of ``folder`` (name order) that defines tree ``tree_id``."""
    pattern = re.compile(rf"<BehaviorTree\s[^>]*\bID\s*=\s*[\"']{re.escape(tree_id)}[\"']")
    for path in sorted(folder.glob("*.xml")):
        if path not in skip and pattern.search(path.read_text(errors="replace")):
            return path
    return None


def _prepared(tree: Path, model: Path | None, outcome: Outcome) -> list[Path]:
    """The files to register with ``tree``: none, or the files of its folder defining the
    subtrees it calls (as a program registers them before ``createTree``)."""
    trees: list[Path] = []
    while True:
        try:
            prepare(_config(tree, model, trees))
            return trees
        except TreeError as error:
            missing = MISSING.search(error.problem)
            found = missing and _defining(tree.parent, missing.group(1), [tree, *trees])
            if not found:
                raise
            trees.append(found)
            outcome.folder = True  # its subtrees are in other files of its folder


def _try(tree: Path, model: Path | None, outcome: Outcome, scratch: Path) -> None:
    try:
        trees = _prepared(tree, model, outcome)
        outcome.validated = True
        result = execute(_config(tree, model, trees), scratch / "run.mcap")
        outcome.ran = True
        outcome.finished = result.final_status.completed
        outcome.halted = any("' was halted" in w for w in result.warnings)
    except (ValueError, OSError, NodeExecutionError) as error:
        outcome.refusal = one_line(error)
    except Exception as error:  # a bug of btlog: reported, and the test fails
        outcome.bug = f"{type(error).__name__}: {one_line(error)}"


def _refusal_problem(outcome: Outcome, tree: Path) -> str | None:
    """Why a refusal breaks the rule (one line, naming the file), or None."""
    text = outcome.refusal
    if "\n" in text:
        return "more than one line"
    if not any(part in text for part in (str(tree), tree.name)) and ".xml" not in text:
        return "names no file"
    return None


def _kind_of(refusal: str) -> str:
    """The refusal without its file and names, for counting kinds."""
    text = refusal.split(": ", 1)[1] if re.match(r"^\S+\.\w+(:\d+)?: ", refusal) else refusal
    text = re.sub(r"'[^']*'", "'X'", text)
    return re.sub(r"\d+", "N", text)[:110]


def _report(outcomes: dict[Path, Outcome]) -> str:
    by_project: dict[str, list[Outcome]] = defaultdict(list)
    for outcome in outcomes.values():
        by_project[outcome.project].append(outcome)
    lines = [
        "| project | trees | validated | run | finished | with their folder | halt warnings |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    totals = Counter()
    for project in sorted(by_project):
        items = by_project[project]
        row = Counter(
            trees=len(items),
            validated=sum(o.validated for o in items),
            run=sum(o.ran for o in items),
            finished=sum(o.finished for o in items),
            folder=sum(o.folder and o.validated for o in items),
            halted=sum(o.halted for o in items),
        )
        totals.update(row)
        lines.append(
            f"| {project} | {row['trees']} | {row['validated']} | {row['run']} | "
            f"{row['finished']} | {row['folder']} | {row['halted']} |"
        )
    lines.append(
        f"| **total** | **{totals['trees']}** | **{totals['validated']}** | **{totals['run']}** "
        f"| **{totals['finished']}** | **{totals['folder']}** | **{totals['halted']}** |"
    )
    kinds = Counter(_kind_of(o.refusal) for o in outcomes.values() if o.refusal)
    lines += ["", "| refusals | kind |", "|---:|---|"]
    lines += [f"| {count} | {kind} |" for kind, count in kinds.most_common()]
    return "\n".join(lines) + "\n"


def test_every_real_tree_validates_runs_or_is_refused_in_one_line(tmp_path: Path) -> None:
    top = Path(REAL or ".").resolve()
    files = sorted(p for p in top.rglob("*.xml") if p.is_file())
    kinds = {p: _kind(p) for p in files}
    models = [p for p, kind in kinds.items() if kind == "model"]
    outcomes: dict[Path, Outcome] = {}
    for tree in (p for p, kind in kinds.items() if kind == "tree"):
        outcome = outcomes[tree] = Outcome(_project(tree, top))
        _try(tree, _nearest_model(tree, models, top), outcome, tmp_path)
    report = _report(outcomes)
    print(f"\nbtlog on the trees under {top} (run --max-ticks {MAX_TICKS}):\n\n{report}")
    if os.environ.get("BTLOG_REAL_TREES_REPORT"):
        Path(os.environ["BTLOG_REAL_TREES_REPORT"]).write_text(report)
    broken = {
        tree: (problem, outcome.refusal)
        for tree, outcome in outcomes.items()
        if outcome.refusal and (problem := _refusal_problem(outcome, tree))
    }
    bugs = {tree: outcome.bug for tree, outcome in outcomes.items() if outcome.bug}
    assert outcomes, f"no tree files under {top}"
    assert not bugs, bugs
    assert not broken, broken

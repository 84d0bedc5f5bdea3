"""Re-running a stored run: its tree runs again with the recorded settings, and the two
behaviours are compared subgoal by subgoal (``btlog.explain.divergence``).

A re-run pins down what a run *does*; ``btlog check --rerun`` and the pytest plugin use it.
See docs/design.md, "Checks".
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from btlog.checks.behaviours import executed_actions
from btlog.checks.stored_run import CheckResult, final_status_of
from btlog.events import TickRecord
from btlog.explain.divergence import (
    Divergence,
    ExecutedAction,
    SubgoalDivergence,
    actions_from_events,
    diverge,
    to_json,
)
from btlog.record.reader import (
    Recording,
    UntidyRecording,
    open_recording,
    read_metadata,
    stream_events,
)
from btlog.render.divergence import move_text, render
from btlog.status import Status

__all__ = ["RerunError", "RerunReport", "project_of", "rerun", "subgoal_check", "tree_for_rerun"]


class RerunError(ValueError):
    """A run that cannot be re-run (its tree file is gone); one line."""


@dataclass
class RerunReport:
    """A stored run against a fresh run of its tree: the divergence of their actions,
    both final statuses, and the checks (final status, the run's extent, one per subgoal)."""

    run: str
    tree: str
    tree_changed: bool
    recorded_status: str
    rerun_status: str
    divergence: Divergence
    results: list[CheckResult]

    @property
    def ok(self) -> bool:
        """True when the re-run ended the same way and no subgoal diverges."""
        return all(result.ok for result in self.results)

    def render(self) -> str:
        """A readable report: the checks, and the side-by-side view of what differs."""
        return "\n".join(self.render_lines())

    def render_lines(self) -> list[str]:
        """The lines of ``render`` (a name holding a newline stays inside its line)."""
        changed = " (changed since the recording)" if self.tree_changed else ""
        lines = [f"re-run of {self.run} with {self.tree}{changed}"]
        for result in self.results:
            lines += result.report_lines()
        if not self.divergence.identical:
            lines += ["", *render(self.divergence, only_divergent=True).splitlines()]
        return lines

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {
            "run": self.run,
            "tree": self.tree,
            "tree_changed": self.tree_changed,
            "ok": self.ok,
            "recorded_status": self.recorded_status,
            "rerun_status": self.rerun_status,
            "checks": [result.to_json() for result in self.results],
            "divergence": to_json(self.divergence),
        }


def project_of(run_path: str | os.PathLike) -> Path:
    """The recording's project: the nearest folder at or above the recording that holds a
    ``pyproject.toml``, else the current directory."""
    folder = Path(run_path).resolve().parent
    for base in (folder, *folder.parents):
        if (base / "pyproject.toml").is_file():
            return base
    return Path.cwd()


def tree_for_rerun(
    run_path: str | os.PathLike, metadata: dict, tree: str | os.PathLike | None = None
) -> str:
    """The tree file to re-run: ``tree`` if given, else the recorded tree file as it was
    given, relative to the recording's project (``project_of``), then its recorded
    absolute path (the machine that recorded it)."""
    if tree:
        return os.fspath(tree)
    recorded = metadata.get("tree_file") or ""
    candidates = [project_of(run_path) / recorded] if recorded else []
    if metadata.get("tree_file_abs"):
        candidates.append(Path(metadata["tree_file_abs"]))
    for candidate in candidates:
        if candidate.is_file():
            return os.fspath(candidate)
    raise RerunError(
        f"{os.fspath(run_path)}: the recorded tree file {recorded!r} is not found in the "
        f"recording's project ({project_of(run_path)}) nor at its recorded absolute path; "
        "pass --tree TREE"
    )


def _sha256(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _action_text(action: ExecutedAction) -> str:
    return (
        f'"{action.description}" (in {action.parent})'
        if action.parent
        else f'"{action.description}"'
    )


def subgoal_check(found: SubgoalDivergence) -> CheckResult:
    """The check of one subgoal's actions: recorded (A) against re-run (B)."""
    what = f'actions of subgoal "{found.subgoal}"'
    expected = f"the {len(found.a_actions)} recorded actions"
    if not found.diverges:
        return CheckResult(True, what, expected, f"the same {len(found.b_actions)} actions")
    parts = [f"edit distance {found.edit_distance}, LCS length {found.lcs_length}"]
    parts += [move_text(move) for move in found.moves]
    moved = set(found.moved)
    only_a = [_action_text(a) for a in found.only_a if a.description not in moved]
    only_b = [_action_text(b) for b in found.only_b if b.description not in moved]
    if only_a:
        parts.append("only in the recording: " + ", ".join(only_a))
    if only_b:
        parts.append("only in the re-run: " + ", ".join(only_b))
    if found.cut is not None:
        parts.append(found.cut.text())
    return CheckResult(False, what, expected, "; ".join(parts))


def run_extent(recording: Recording) -> str:
    """``72.300 s, 724 ticks, 257 events``: what a re-run on the simulated clock must
    match exactly (a recording made by older code that differs is stale)."""
    end = max((tick.end_ns for tick in recording.ticks), default=0)
    ticks = max((tick.tick for tick in recording.ticks), default=0)
    return f"{end / 1e9:.3f} s, {ticks} ticks, {len(recording.events)} events"


@dataclass
class _Ticks:
    """What a run's tick records tell a re-run check, gathered as they stream by."""

    last: tuple[int, bool] = (-1, False)
    final_status: str = Status.IDLE.name
    end_ns: int = 0
    ticks: int = 0

    def add(self, batch: list[TickRecord]) -> None:
        """Take a batch of tick records (any order)."""
        for tick in batch:
            self.end_ns = max(self.end_ns, tick.end_ns)
            self.ticks = max(self.ticks, tick.tick)
            key = (tick.tick, tick.teardown)
            if not tick.teardown and key >= self.last:
                self.last, self.final_status = key, tick.root_status.name


@dataclass
class _Behaviour:
    """A run as a re-run check reads it: metadata, final status, extent, actions."""

    metadata: dict
    final_status: str
    extent: str
    actions: Sequence[ExecutedAction]


def _read_run(path: str | os.PathLike) -> _Behaviour:
    """Read a run for ``rerun`` front to back, holding only its executed actions (as
    arrays) and a summary of its ticks; an untidy file is read whole."""
    ticks = _Ticks()
    streamed = stream_events(path, ticks.add)
    if streamed is not None:
        count = 0
        tree, events = streamed

        def counted() -> Iterator[object]:
            nonlocal count
            for event in events:
                count += 1
                yield event

        try:
            actions = actions_from_events(tree, counted())
        except UntidyRecording:
            pass
        else:
            extent = f"{ticks.end_ns / 1e9:.3f} s, {ticks.ticks} ticks, {count} events"
            return _Behaviour(read_metadata(path), ticks.final_status, extent, actions)
    recording = open_recording(path)
    return _Behaviour(
        recording.metadata,
        final_status_of(recording),
        run_extent(recording),
        executed_actions(recording),
    )


def rerun(
    run_path: str | os.PathLike,
    tree: str | os.PathLike | None = None,
    keep: str | os.PathLike | None = None,
    main_tree: str | None = None,
    trees: list[str] | None = None,
) -> RerunReport:
    """Execute the run's tree again with its recorded settings and compare the behaviours.

    The tree is the recorded tree file as it is now, or ``tree``. The re-run uses the
    recorded domain, seed, outcomes, ``--fail`` specs and live questions, on the simulated
    clock, into a temporary file (or into ``keep``, which is left in place); ``main_tree``
    and ``trees``, when given, replace the recorded ``--main-tree`` and ``--trees``. Any divergent
    action, another final status or, for a run recorded on the simulated clock, another
    duration, tick count or event count (a recording made by older code) fails.
    """
    from btlog.runner import RunConfig, execute

    recorded = _read_run(run_path)
    tree_path = tree_for_rerun(run_path, recorded.metadata, tree)
    config = replace(RunConfig.from_metadata(recorded.metadata, tree=tree_path), realtime=False)
    if main_tree is not None:
        config.main_tree = main_tree
    if trees:
        config.trees = trees
    with tempfile.TemporaryDirectory(prefix="btlog-rerun-") as folder:
        result = execute(config, keep if keep is not None else Path(folder) / "rerun.mcap")
        again = _read_run(result.path)
    recorded_status = recorded.final_status
    divergence = diverge(
        recorded.actions,
        again.actions,
        f"{os.fspath(run_path)} (recorded)",
        f"{tree_path} (re-run)",
    )
    results = [
        CheckResult(
            recorded_status == result.final_status.name,
            "final status",
            recorded_status,
            result.final_status.name,
        )
    ]
    if recorded.metadata.get("clock") != "wall":  # on the simulated clock, the same run
        before, after = recorded.extent, again.extent
        results.append(CheckResult(before == after, "duration, ticks and events", before, after))
    results += [subgoal_check(found) for found in divergence.subgoals]
    changed = _sha256(tree_path) != recorded.metadata.get("tree_sha256")
    return RerunReport(
        os.fspath(run_path),
        tree_path,
        changed,
        recorded_status,
        result.final_status.name,
        divergence,
        results,
    )

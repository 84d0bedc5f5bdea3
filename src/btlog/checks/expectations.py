"""Regression checks on stored runs: expectations, re-recording, and re-running.

An expectations file pins down what a run *was*: its final status, answers to questions
and node statuses at moments (validated by ``schemas/expectations.schema.json``).
Checking replays the run to each moment and compares; re-recording writes the actual
values back, as snapshot-testing tools do. A re-run pins down what a run *does*: the
tree runs again with the recorded settings and the two behaviours are compared subgoal
by subgoal (``btlog.explain.divergence``). ``btlog check`` and the pytest plugin both
use these functions. See docs/design.md, "Checks".
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml
from jsonschema.exceptions import ValidationError

from btlog import documents
from btlog.errors import one_line
from btlog.explain.behaviours import executed_actions
from btlog.explain.divergence import (
    Divergence,
    ExecutedAction,
    SubgoalDivergence,
    diverge,
    to_json,
)
from btlog.explain.questions import UnknownQuestion, answer, parse_question
from btlog.record.reader import Recording, open_recording
from btlog.render.divergence import move_text, render
from btlog.state import State
from btlog.status import Status
from btlog.tree.model import Tree

__all__ = [
    "AnswerExpectation",
    "CheckResult",
    "ExpectationError",
    "Expectations",
    "RerunError",
    "RerunReport",
    "StatusExpectation",
    "StoredRun",
    "check_run",
    "final_status_of",
    "load_expectations",
    "parse_expectations",
    "record_expectations",
    "rerun",
    "write_expectations",
]


class ExpectationError(ValueError):
    """A bad expectations file or entry; one line naming the file and the entry."""


# -- expectations --------------------------------------------------------------------------
@dataclass(frozen=True)
class AnswerExpectation:
    """``answers[i]``: asked ``ask`` at moment ``at``, the answer must be ``answer``."""

    where: str
    at: str
    ask: str
    answer: str | None


@dataclass(frozen=True)
class StatusExpectation:
    """``statuses[i]``: at moment ``at``, node ``node`` must have status ``status``."""

    where: str
    at: str
    node: str
    status: str | None


@dataclass
class Expectations:
    """A parsed expectations file (``source`` names it in messages; ``data`` is the mapping
    as read, kept for re-recording)."""

    source: str
    final_status: str | None = None
    answers: list[AnswerExpectation] = field(default_factory=list)
    statuses: list[StatusExpectation] = field(default_factory=list)
    run: str | None = None
    rerun: bool = False
    data: dict = field(default_factory=dict)

    @property
    def count(self) -> int:
        """How many checks these expectations make (not counting a re-run)."""
        return (self.final_status is not None) + len(self.answers) + len(self.statuses)


def _text(value: Any) -> str | None:
    return None if value is None else str(value)


def _status(value: Any) -> str | None:
    return None if value is None else str(value).strip().upper()


def _filled_later(error: ValidationError) -> bool:
    """A missing expected value, which re-recording fills in."""
    if error.validator != "required" or not isinstance(error.instance, dict):
        return False
    required = error.validator_value if isinstance(error.validator_value, list) else []
    missing = set(required) - set(error.instance)
    return not missing.isdisjoint({"answer", "status"})


def parse_expectations(
    data: Any,
    source: str = "expectations",
    partial: bool = False,
    lines: dict[documents.KeyPath, int] | None = None,
) -> Expectations:
    """Expectations from a mapping (as in the YAML file), checked by its schema.

    ``partial`` accepts entries whose expected value is missing (``answer``, ``status``):
    re-recording fills them in. Raises ``ExpectationError`` naming ``source``, the line
    (when ``lines`` maps key paths to lines) and the entry.
    """
    found = documents.errors(data, "expectations")
    if partial:
        found = (error for error in found if not _filled_later(error))
    message = documents.complaint(found, source, lines)
    if message is not None:
        raise ExpectationError(message)
    data = data or {}
    answers = []
    for index, entry in enumerate(data.get("answers") or []):
        where = f"answers[{index}]"
        try:
            parse_question(str(entry["ask"]))
        except UnknownQuestion:
            line = (lines or {}).get(("answers", index))
            head = f"{source}:{line}" if line else source
            raise ExpectationError(f"{head}: {where}: unknown question {entry['ask']!r}") from None
        answers.append(
            AnswerExpectation(
                where, str(entry["at"]), str(entry["ask"]), _text(entry.get("answer"))
            )
        )
    statuses = [
        StatusExpectation(
            f"statuses[{index}]", str(entry["at"]), str(entry["node"]), _status(entry.get("status"))
        )
        for index, entry in enumerate(data.get("statuses") or [])
    ]
    return Expectations(
        source=source,
        final_status=_status(data.get("final_status")),
        answers=answers,
        statuses=statuses,
        run=_text(data.get("run")),
        rerun=data.get("rerun", False),
        data=data,
    )


def load_expectations(path: str | os.PathLike, partial: bool = False) -> Expectations:
    """Read and check an expectations file (YAML); ``ExpectationError`` in one line."""
    name = os.fspath(path)
    try:
        data, lines = documents.read(name, "expectations file")
    except documents.DocumentError as error:
        raise ExpectationError(str(error)) from None
    return parse_expectations(data, name, partial, lines)


def write_expectations(path: str | os.PathLike, data: dict) -> None:
    """Write an expectations mapping as YAML (keys in their given order)."""
    text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)
    Path(path).write_text(text, encoding="utf-8")


# -- a stored run, asked at moments --------------------------------------------------------
def final_status_of(recording: Recording) -> str:
    """How a recorded run ended: the root status of its last tick (IDLE if it never
    ticked; RUNNING if it was stopped or cut short while running)."""
    ticks = [t for t in recording.ticks if not t.teardown]  # the teardown's root is IDLE
    return ticks[-1].root_status.name if ticks else Status.IDLE.name


class StoredRun:
    """A recorded run opened for checks: the state, answers and statuses at moments, and
    the final status. Use as a context manager, or call ``close``."""

    def __init__(self, path: str | os.PathLike) -> None:
        from btlog.replay.database import open_runs

        self.path = os.fspath(path)
        self._recording: Recording | None = None
        self._database = open_runs(self.path)
        try:
            self._run = self._database.run(self.path)
        except BaseException:
            self._database.close()
            raise

    def __enter__(self) -> StoredRun:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Release the read model."""
        self._database.close()

    @property
    def recording(self) -> Recording:
        """The recording itself (read on first use)."""
        if self._recording is None:
            self._recording = open_recording(self.path)
        return self._recording

    def state_at(self, at: str) -> tuple[Tree, State]:
        """The tree and the state at moment ``at`` (any moment form)."""
        return self._run.state_at(str(at))

    def answer(self, at: str, question: str) -> str:
        """The answer to ``question`` at moment ``at``."""
        tree, state = self.state_at(at)
        return answer(tree, state, question, self._run.history()).text

    def status(self, at: str, node: str) -> str:
        """The status name of ``node`` (name, type or path) at moment ``at``."""
        tree, state = self.state_at(at)
        return state.status_of(tree.lookup_one(node).uid).name

    @property
    def final_status(self) -> str:
        """How the run ended: the root status of its last tick (as in the read model's
        ``runs.final_status``; IDLE when the run never ticked)."""
        return self._run.info.final_status or Status.IDLE.name

    @property
    def actions(self) -> list[ExecutedAction]:
        """The run's executed actions (see ``btlog.explain.divergence``)."""
        return executed_actions(self.recording)


# -- checking ------------------------------------------------------------------------------
@dataclass(frozen=True)
class CheckResult:
    """One check: ``what`` was checked, ``expected`` and ``actual`` (text), ``ok``;
    ``detail`` is an optional longer report (e.g. the side-by-side divergence)."""

    ok: bool
    what: str
    expected: str
    actual: str
    detail: str = ""

    def report(self) -> str:
        """Readable lines: a one-line verdict, then expected/actual on failure."""
        return "\n".join(self.report_lines())

    def report_lines(self) -> list[str]:
        """The lines of ``report`` (a name holding a newline stays inside its line)."""
        if self.ok:
            return [f"ok    {self.what}"]
        lines = [
            f"FAIL  {self.what}",
            f"        expected: {self.expected}",
            f"        actual:   {self.actual}",
        ]
        if self.detail:
            lines += ["        " + line if line else "" for line in self.detail.splitlines()]
        return lines

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {
            "ok": self.ok,
            "what": self.what,
            "expected": self.expected,
            "actual": self.actual,
            **({"detail": self.detail} if self.detail else {}),
        }


def _entry_error(source: str, where: str, error: Exception) -> ExpectationError:
    return ExpectationError(f"{source}: {where}: {one_line(error)}")


def check_final_status(run: StoredRun, expected: str) -> CheckResult:
    """The run's final status against ``expected``."""
    actual = run.final_status
    return CheckResult(actual == expected, "final status", expected, actual)


def check_answer(run: StoredRun, item: AnswerExpectation, source: str) -> CheckResult:
    """One ``answers`` entry; a bad moment or question raises ``ExpectationError``."""
    try:
        actual = run.answer(item.at, item.ask)
    except (ValueError, LookupError) as error:
        raise _entry_error(source, item.where, error) from None
    expected = (item.answer or "").strip()
    return CheckResult(
        actual.strip() == expected,
        f'{item.where}: answer at {item.at} to "{item.ask}"',
        expected,
        actual,
    )


def check_status(run: StoredRun, item: StatusExpectation, source: str) -> CheckResult:
    """One ``statuses`` entry; a bad moment or node raises ``ExpectationError``."""
    try:
        actual = run.status(item.at, item.node)
    except (ValueError, LookupError) as error:
        raise _entry_error(source, item.where, error) from None
    return CheckResult(
        actual == item.status,
        f'{item.where}: status of "{item.node}" at {item.at}',
        item.status or "",
        actual,
    )


def _as_expectations(
    expectations: Expectations | dict | str | os.PathLike, partial: bool = False
) -> Expectations:
    if isinstance(expectations, Expectations):
        return expectations
    if isinstance(expectations, dict):
        return parse_expectations(expectations, "expectations", partial)
    return load_expectations(expectations, partial)


def check_run(
    run_path: str | os.PathLike | StoredRun, expectations: Expectations | dict | str | os.PathLike
) -> list[CheckResult]:
    """Check a stored run against expectations (parsed, a mapping, or a file).

    One result per check, in file order: final status, answers, statuses. Bad entries
    (a moment outside the run, an ambiguous node) raise ``ExpectationError``.
    """
    expected = _as_expectations(expectations)
    if isinstance(run_path, StoredRun):
        return _check(run_path, expected)
    with StoredRun(run_path) as run:
        return _check(run, expected)


def _check(run: StoredRun, expected: Expectations) -> list[CheckResult]:
    results = []
    if expected.final_status is not None:
        results.append(check_final_status(run, expected.final_status))
    results += [check_answer(run, item, expected.source) for item in expected.answers]
    results += [check_status(run, item, expected.source) for item in expected.statuses]
    return results


def record_expectations(
    run_path: str | os.PathLike | StoredRun,
    existing: Expectations | dict | str | os.PathLike | None = None,
) -> dict:
    """The expectations mapping with every expected value replaced by the run's actual one
    (for re-recording). The final status is always recorded; entries keep their moments,
    questions and nodes, and other keys are kept as they are."""
    expected = _as_expectations(existing or {}, partial=True)
    if isinstance(run_path, StoredRun):
        return _record(run_path, expected)
    with StoredRun(run_path) as run:
        return _record(run, expected)


def _record(run: StoredRun, expected: Expectations) -> dict:
    data = dict(expected.data)
    recorded: dict[str, Any] = {}
    if "run" in data:
        recorded["run"] = data["run"]
    recorded["final_status"] = run.final_status
    if expected.answers:
        recorded["answers"] = [
            {
                "at": item.at,
                "ask": item.ask,
                "answer": check_answer(run, item, expected.source).actual,
            }
            for item in expected.answers
        ]
    if expected.statuses:
        recorded["statuses"] = [
            {
                "at": item.at,
                "node": item.node,
                "status": check_status(run, item, expected.source).actual,
            }
            for item in expected.statuses
        ]
    if "rerun" in data:
        recorded["rerun"] = data["rerun"]
    return recorded


# -- re-running ----------------------------------------------------------------------------
class RerunError(ValueError):
    """A run that cannot be re-run (its tree file is gone); one line."""


@dataclass
class RerunReport:
    """A stored run against a fresh run of its tree: the divergence of their actions,
    both final statuses, and the checks (final status, then one per subgoal)."""

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
    parts = [f"edit distance {found.edit_distance}, LCS length {len(found.lcs)}"]
    parts += [move_text(move) for move in found.moves]
    moved = set(found.moved)
    only_a = [_action_text(a) for a in found.only_a if a.description not in moved]
    only_b = [_action_text(b) for b in found.only_b if b.description not in moved]
    if only_a:
        parts.append("only in the recording: " + ", ".join(only_a))
    if only_b:
        parts.append("only in the re-run: " + ", ".join(only_b))
    return CheckResult(False, what, expected, "; ".join(parts))


def rerun(
    run_path: str | os.PathLike,
    tree: str | os.PathLike | None = None,
    keep: str | os.PathLike | None = None,
) -> RerunReport:
    """Execute the run's tree again with its recorded settings and compare the behaviours.

    The tree is the recorded tree file as it is now, or ``tree``. The re-run uses the
    recorded domain, seed, outcomes, ``--fail`` specs and live questions, on the simulated
    clock, into a temporary file (or into ``keep``, which is left in place). Any divergent
    action or another final status fails.
    """
    from btlog.runner import RunConfig, execute

    recorded = open_recording(run_path)
    tree_path = tree_for_rerun(run_path, recorded.metadata, tree)
    config = replace(RunConfig.from_metadata(recorded.metadata, tree=tree_path), realtime=False)
    with tempfile.TemporaryDirectory(prefix="btlog-rerun-") as folder:
        result = execute(config, keep if keep is not None else Path(folder) / "rerun.mcap")
        again = open_recording(result.path)
    recorded_status = final_status_of(recorded)
    divergence = diverge(
        executed_actions(recorded),
        executed_actions(again),
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

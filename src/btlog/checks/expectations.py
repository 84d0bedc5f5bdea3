"""Regression checks on stored runs by expectations files.

An expectations file pins down what a run *was*: its final status, answers to questions
and node statuses at moments (validated by ``schemas/expectations.schema.json``).
Checking replays the run to each moment and compares; re-recording writes the actual
values back, as snapshot-testing tools do. ``btlog check`` and the pytest plugin both
use these functions (re-running is ``btlog.checks.rerun``). See docs/design.md, "Checks".
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from jsonschema.exceptions import ValidationError

from btlog import documents
from btlog.checks.stored_run import CheckResult, StoredRun
from btlog.errors import one_line
from btlog.explain.questions import UnknownQuestion, parse_question

__all__ = [
    "AnswerExpectation",
    "ExpectationError",
    "Expectations",
    "StatusExpectation",
    "check_answer",
    "check_final_status",
    "check_run",
    "check_status",
    "load_expectations",
    "parse_expectations",
    "record_expectations",
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

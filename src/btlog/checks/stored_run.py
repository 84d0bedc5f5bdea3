"""A stored run opened for checks, and the result of one check.

``StoredRun`` answers what the checks ask of a recording: the state, an answer or a
node's status at a moment, the final status and the executed actions. ``CheckResult`` is
what every check returns (expectations and re-runs alike), with a readable report.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from btlog.checks.behaviours import executed_actions
from btlog.explain.divergence import ActionList
from btlog.explain.questions import answer
from btlog.record.reader import Recording, open_recording
from btlog.state import State
from btlog.status import Status
from btlog.tree.model import Tree


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
    def actions(self) -> ActionList:
        """The run's executed actions (see ``btlog.explain.divergence``)."""
        return executed_actions(self.recording)


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

"""The btlog pytest plugin: stored runs as test cases (registered as ``pytest11``: ``btlog``).

Three ways to use it:

1. **Expectation files become tests.** Every ``*.expect.yaml`` file under the paths pytest
   is given (or its ``testpaths``) is collected, like any test file, into one test item per
   entry: ``final_status``, ``answers[i]``, ``statuses[i]``, and ``rerun`` when the file
   says ``rerun: true``. The file names its recording with ``run:`` (relative to the
   file); without it, the recording beside it with the same stem is used
   (``kitting-1.expect.yaml`` → ``kitting-1.mcap``). A folder of runs with their
   expectation files is thereby a test suite.

2. **Fixtures for hand-written tests.** ``btlog_run(path)`` opens a stored run
   (``.answer(at, question)``, ``.status(at, node)``, ``.final_status``,
   ``.state_at(at)``, ``.actions``); ``btlog_expect(path, expectations)`` asserts that
   a run meets expectations (a mapping or a file), and with ``rerun=True`` that a re-run
   of its tree does not diverge. Relative paths are looked up beside the test file, then
   under the rootdir, then from the current folder.

3. **Re-recording, as snapshot tools do.** ``pytest --btlog-update`` writes the runs'
   actual values into the expectation files (collected files and files passed to
   ``btlog_expect``) instead of failing; review the change with your VCS. Only the
   selected entries are rewritten; comments in a rewritten file are not kept. Re-runs are
   still checked: they compare the tree with a recording, and nothing there is re-recorded.

The heavy modules are imported only when a run is opened, so having the plugin installed
costs a pytest session nothing.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import pytest

if TYPE_CHECKING:
    from _pytest._code.code import TerminalRepr, TracebackStyle

    from btlog.checks.expectations import Expectations
    from btlog.checks.stored_run import CheckResult, StoredRun

SUFFIX = ".expect.yaml"
UPDATE_OPTION = "--btlog-update"
_UPDATED = pytest.StashKey[list]()


class BtlogCheckFailed(AssertionError):
    """A failed check of a stored run; the message is the readable report."""


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--btlog-update``."""
    group = parser.getgroup("btlog", "regression tests on stored behavior-tree runs")
    group.addoption(
        UPDATE_OPTION,
        action="store_true",
        default=False,
        help="re-record btlog expectation files from the runs instead of failing",
    )


def pytest_configure(config: pytest.Config) -> None:
    """Prepare the list of re-recorded files."""
    config.stash[_UPDATED] = []


def pytest_collect_file(file_path: Path, parent: pytest.Collector) -> pytest.Collector | None:
    """Collect ``*.expect.yaml`` files as btlog expectation tests."""
    if file_path.name.endswith(SUFFIX):
        return ExpectFile.from_parent(parent, path=file_path)
    return None


def pytest_terminal_summary(
    terminalreporter: pytest.TerminalReporter, exitstatus: int, config: pytest.Config
) -> None:
    """Say which expectation files ``--btlog-update`` rewrote."""
    updated = config.stash.get(_UPDATED, [])
    if updated:
        terminalreporter.write_sep("-", f"btlog: re-recorded {len(updated)} expectation file(s)")
        for path in updated:
            terminalreporter.write_line(f"  {path}")


def _updating(config: pytest.Config) -> bool:
    return bool(config.getoption(UPDATE_OPTION, default=False))


def _updated(config: pytest.Config, path: Path) -> None:
    updated = config.stash.setdefault(_UPDATED, [])
    if str(path) not in updated:
        updated.append(str(path))


def _readable(error: BaseException) -> str | None:
    """The report of a btlog failure or bad input (one line), else None."""
    from btlog.checks.expectations import ExpectationError
    from btlog.checks.rerun import RerunError
    from btlog.record.reader import RecordingError

    if isinstance(error, BtlogCheckFailed):
        return str(error)
    if isinstance(error, ExpectationError | RecordingError | RerunError):
        return " ".join(str(error).split())
    return None


# -- expectation files -------------------------------------------------------------------
class ExpectFile(pytest.File):
    """An ``*.expect.yaml`` file: one item per expectation entry (and one for ``rerun``)."""

    def collect(self) -> Iterator[ExpectItem]:
        """The items of this file; a bad file is a collection error with one line."""
        from btlog.checks.expectations import ExpectationError, load_expectations

        try:
            self.expectations = load_expectations(self.path, partial=_updating(self.config))
        except ExpectationError as error:
            raise self.CollectError(str(error)) from None
        self._run: StoredRun | None = None
        self._changed = False
        expected = self.expectations
        if expected.final_status is not None or _updating(self.config):
            yield ExpectItem.from_parent(self, name="final_status", kind="final_status")
        for kind, entries in (("answers", expected.answers), ("statuses", expected.statuses)):
            for index, _entry in enumerate(entries):
                yield ExpectItem.from_parent(self, name=f"{kind}[{index}]", kind=kind, index=index)
        if expected.rerun:
            yield ExpectItem.from_parent(self, name="rerun", kind="rerun")

    @property
    def run_path(self) -> Path:
        """The recording: ``run:`` relative to this file, or the ``.mcap`` of the same stem."""
        if self.expectations.run:
            return self.path.parent / self.expectations.run
        return self.path.with_name(self.path.name[: -len(SUFFIX)] + ".mcap")

    def stored_run(self) -> StoredRun:
        """The recording opened once for all items of this file."""
        from btlog.checks.stored_run import StoredRun

        if self._run is None:
            self._run = StoredRun(self.run_path)
        return self._run

    def record(self, kind: str, index: int | None, actual: str) -> None:
        """Put an actual value into the file's data (``--btlog-update``)."""
        data = self.expectations.data
        if kind == "final_status":
            old, data["final_status"] = data.get("final_status"), actual
        else:
            key = "answer" if kind == "answers" else "status"
            entry = data[kind][index]
            old, entry[key] = entry.get(key), actual
        self._changed = self._changed or old != actual

    def teardown(self) -> None:
        """Close the run; write the file if ``--btlog-update`` changed it."""
        from btlog.checks.expectations import write_expectations

        if self._run is not None:
            self._run.close()
            self._run = None
        if self._changed:
            write_expectations(self.path, _ordered(self.expectations.data))
            _updated(self.config, self.path)
            self._changed = False


def _ordered(data: dict) -> dict:
    order = ("run", "final_status", "answers", "statuses", "rerun")
    return {key: data[key] for key in order if key in data}


class ExpectItem(pytest.Item):
    """One expectation of a file (``kind`` final_status, answers, statuses or rerun)."""

    def __init__(self, *, kind: str, index: int | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.kind = kind
        self.index = index

    def runtest(self) -> None:
        """Check the expectation; with ``--btlog-update``, re-record it instead."""
        if self.kind == "rerun":
            self._rerun()
            return
        result = self._result()
        if _updating(self.config):
            self.file.record(self.kind, self.index, result.actual)
        elif not result.ok:
            raise BtlogCheckFailed(result.report())

    @property
    def file(self) -> ExpectFile:
        """The expectations file this item comes from."""
        return cast(ExpectFile, self.parent)

    def _result(self) -> CheckResult:
        from btlog.checks import expectations as ex

        file = self.file
        index = self.index or 0
        run, expected = file.stored_run(), file.expectations
        if self.kind == "final_status":
            return ex.check_final_status(run, expected.final_status or "")
        if self.kind == "answers":
            return ex.check_answer(run, expected.answers[index], expected.source)
        return ex.check_status(run, expected.statuses[index], expected.source)

    def _rerun(self) -> None:
        from btlog.checks.rerun import rerun

        report = rerun(self.file.run_path)
        if not report.ok:
            raise BtlogCheckFailed(report.render())

    def repr_failure(
        self, excinfo: pytest.ExceptionInfo[BaseException], style: TracebackStyle | None = None
    ) -> str | TerminalRepr:
        """The readable report for btlog failures; pytest's own for anything else."""
        return _readable(excinfo.value) or super().repr_failure(excinfo, style=style)

    def reportinfo(self) -> tuple[Path, int | None, str]:
        """Where the item comes from, for pytest's reports."""
        return self.path, None, f"{self.path.name}::{self.name}"


# -- fixtures ------------------------------------------------------------------------------
def _resolve(request: pytest.FixtureRequest, path: str | os.PathLike) -> Path:
    """A path as given, looked up beside the test file, then under the rootdir."""
    given = Path(path)
    if given.is_absolute():
        return given
    for base in (request.path.parent, request.config.rootpath):
        if (base / given).exists():
            return base / given
    return given


@pytest.fixture
def btlog_run(
    request: pytest.FixtureRequest,
) -> Iterator[Callable[[str | os.PathLike], StoredRun]]:
    """A factory opening stored runs: ``run = btlog_run("recordings/kitting-1.mcap")``;
    then ``run.answer(at, question)``, ``run.status(at, node)``, ``run.final_status``,
    ``run.state_at(at)``, ``run.actions``. Runs are closed after the test."""
    from btlog.checks.stored_run import StoredRun

    opened: list[StoredRun] = []

    def open_run(path: str | os.PathLike) -> StoredRun:
        run = StoredRun(_resolve(request, path))
        opened.append(run)
        return run

    yield open_run
    for run in opened:
        run.close()


@pytest.fixture
def btlog_expect(request: pytest.FixtureRequest) -> Callable[..., list[CheckResult]]:
    """Assert that a stored run meets expectations:
    ``btlog_expect(run, expectations=None, rerun=False, tree=None)``, where
    ``expectations`` is a mapping or an expectations file. Fails the test with a
    readable report; with ``--btlog-update`` a file is re-recorded instead.
    Returns the check results."""
    from btlog.checks.rerun import rerun as rerun_run

    def expect(
        run_path: str | os.PathLike,
        expectations: dict | str | os.PathLike | None = None,
        rerun: bool = False,
        tree: str | os.PathLike | None = None,
    ) -> list[CheckResult]:
        path = _resolve(request, run_path)
        results: list[CheckResult] = []
        if expectations is not None:
            results = _expect(request, path, expectations)
        if rerun:
            report = rerun_run(path, _resolve(request, tree) if tree else None)
            results += report.results
            if not report.ok:
                pytest.fail(report.render(), pytrace=False)
        return results

    return expect


def _expect(
    request: pytest.FixtureRequest,
    path: Path,
    expectations: dict | str | os.PathLike | Expectations,
) -> list[CheckResult]:
    from btlog.checks import expectations as ex

    if not isinstance(expectations, dict | ex.Expectations):
        expectations = _resolve(request, expectations)
        if _updating(request.config):
            recorded = ex.record_expectations(path, expectations)
            if recorded != ex.load_expectations(expectations, partial=True).data:
                ex.write_expectations(expectations, recorded)
                _updated(request.config, expectations)
            return []
    results = ex.check_run(path, expectations)
    failed = [result for result in results if not result.ok]
    if failed:
        pytest.fail(
            f"{path}: {len(failed)} of {len(results)} checks failed\n"
            + "\n".join(result.report() for result in failed),
            pytrace=False,
        )
    return results

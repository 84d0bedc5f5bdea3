"""``btlog diff`` and ``btlog check``: divergence between behaviours, regression checks.

``diff A B`` prints, subgoal by subgoal, the actions of two behaviours side by side (a
behaviour is a recording, or a tree XML standing for its nominal sequence), with the
edit distance and LCS length of each subgoal and the divergent actions marked with their
immediate parents. It is a report: its exit code is 0 whatever it finds.

``check RUN… --expect F`` and ``check RUN… --rerun [--tree T]`` are checks: exit 1 when
any check of any run fails, 0 when all pass, 2 for bad input (one line on stderr).
"""

from __future__ import annotations

import json
import sys
from argparse import Namespace
from pathlib import Path

from rich.text import Text

from btlog.checks.behaviours import diff_paths
from btlog.checks.expectations import Expectations, check_run, load_expectations
from btlog.checks.rerun import RerunReport, rerun
from btlog.checks.stored_run import CheckResult
from btlog.errors import EXIT_CHECK_FAILED, EXIT_OK
from btlog.explain.divergence import iter_json
from btlog.render.divergence import iter_lines
from btlog.render.escape import safe
from btlog.render.terminal import make_console

_STYLES = {
    "title": "bold",
    "header": "bold",
    "row": "",
    "divergent": "bold blue",
    "blank": "",
    "summary": "bold",
}


def diff(args: Namespace) -> int:
    """``btlog diff A B``: the divergence of two runs, or of a run and a tree; as diff(1),
    exit 0 when they are the same and 1 when they diverge."""
    divergence = diff_paths(args.a, args.b, args.main_tree, args.trees)
    verdict = EXIT_OK if divergence.identical else EXIT_CHECK_FAILED
    if args.json:
        for piece in iter_json(divergence):
            sys.stdout.write(piece)
        sys.stdout.write("\n")
        return verdict
    console = make_console(args.plain)
    for text, kind in iter_lines(divergence):
        console.print(Text(text, style=_STYLES[kind]))
    return verdict


def _check_options(args: Namespace) -> Expectations | None:
    """Validate the option combination and read the expectations before any run."""
    if not args.expect and not args.rerun:
        raise ValueError("check needs --expect FILE or --rerun")
    if (args.tree or args.main_tree or args.trees) and not args.rerun:
        raise ValueError("--tree, --main-tree and --trees are only used with --rerun")
    return load_expectations(args.expect) if args.expect else None


def _check_one(
    path: str, expectations: Expectations | None, args: Namespace
) -> tuple[list[CheckResult], RerunReport | None]:
    results = check_run(path, expectations) if expectations is not None else []
    keep = _rerun_file(path, args) if args.rerun and getattr(args, "html", None) else None
    report = rerun(path, args.tree, keep, args.main_tree, args.trees) if args.rerun else None
    return results, report


def _rerun_file(path: str, args: Namespace) -> Path:
    """Where a re-run is kept for the HTML report: beside the report."""
    return Path(args.html).with_name(f"{Path(args.html).stem}-{Path(path).stem}-rerun.mcap")


def _write_html(args: Namespace, outcomes: list) -> None:
    """``--html``: the viewer of the first failing run (beside its re-run when there is
    one), with the check's report above it."""
    from btlog.cli.view import write_export

    for path, results, report in outcomes:
        if _passed(results, report):
            continue
        lines = [f"FAIL  {path}"] + [r.report() for r in results]
        if report is not None:
            lines.append(report.render())
        paths = [path] + ([str(_rerun_file(path, args))] if report is not None else [])
        write_export(paths, args.html, "\n".join(lines))
        print(f"report: {safe(args.html)}")
        return


def _passed(results: list[CheckResult], report: RerunReport | None) -> bool:
    return all(r.ok for r in results) and (report is None or report.ok)


def _print_run(
    path: str,
    expectations: Expectations | None,
    results: list[CheckResult],
    report: RerunReport | None,
) -> None:
    verdict = "PASS" if _passed(results, report) else "FAIL"
    print(f"{verdict}  {safe(path)}")
    if expectations is not None:
        failed = sum(not r.ok for r in results)
        print(f"  expectations {safe(expectations.source)}: {len(results)} checks, {failed} failed")
        for result in results:
            _print_lines(result.report_lines(), 4)
    if report is not None:
        _print_lines(report.render_lines(), 2)


def _print_lines(lines: list[str], spaces: int) -> None:
    """Print each line escaped (names inside may hold newlines), indented."""
    for line in lines:
        print(" " * spaces + safe(line) if line else "")


def check(args: Namespace) -> int:
    """``btlog check RUN… [--expect F] [--rerun [--tree T]]``: exit 1 if any check fails."""
    expectations = _check_options(args)
    outcomes = [(path, *_check_one(path, expectations, args)) for path in args.runs]
    failed = [path for path, results, report in outcomes if not _passed(results, report)]
    for path, _results, report in outcomes:
        if report is not None and report.tree_changed:
            print(
                f"btlog check: warning: {safe(path)}: re-run with {safe(report.tree)}, whose "
                "sha256 differs from the recorded tree's",
                file=sys.stderr,
            )
    if args.html:
        try:
            if failed:
                _write_html(args, outcomes)
        finally:
            for path in args.runs if args.rerun else ():
                kept = _rerun_file(path, args)
                for leftover in (kept, kept.with_name(kept.name + ".duckdb")):
                    leftover.unlink(missing_ok=True)
    if args.json:
        print(json.dumps(_json(outcomes, expectations, not failed), indent=2))
    else:
        for path, results, report in outcomes:
            _print_run(path, expectations, results, report)
        count = len(outcomes)
        print(
            f"{count} run{'s' if count != 1 else ''} checked: {count - len(failed)} passed, "
            f"{len(failed)} failed"
        )
    return EXIT_CHECK_FAILED if failed else EXIT_OK


def _json(
    outcomes: list[tuple[str, list[CheckResult], RerunReport | None]],
    expectations: Expectations | None,
    ok: bool,
) -> dict:
    runs = []
    for path, results, report in outcomes:
        entry: dict = {"run": path, "ok": _passed(results, report)}
        if expectations is not None:
            entry["expectations"] = {
                "file": expectations.source,
                "checks": [r.to_json() for r in results],
            }
        if report is not None:
            entry["rerun"] = report.to_json()
        runs.append(entry)
    return {"ok": ok, "runs": runs}

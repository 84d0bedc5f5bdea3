"""The ``btlog`` command line: parsing, dispatch, and the exit-code contract.

Exit codes: 0 ok, 1 a check failed, 2 bad input, 3 a bug in btlog. Bad input of any kind
(unreadable or invalid files, bad moments, unknown questions, bad SQL, bad trees) is
reported as one line on stderr, never a traceback; any other exception is a bug of btlog,
reported as one line saying so. ``BTLOG_DEBUG=1`` shows the traceback of either.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
from collections.abc import Callable, Sequence
from typing import NoReturn

from btlog import __version__
from btlog.cli.limit_flags import add_limit_flags, apply_limit_flags
from btlog.cli.tree_flags import add_tree_flags
from btlog.errors import EXIT_BAD_INPUT, EXIT_BUG, EXIT_OK, one_line
from btlog.limits import DEFAULT_QUERY_TIMEOUT, fit_address_space, out_of_memory
from btlog.render.escape import safe

#: Options whose value may be a negative moment (``--at -2s``, ``--ask "-2s=…"``).
MOMENT_OPTIONS = ("--at", "--from", "--to", "--ask")
_NEGATIVE = re.compile(r"^-[\d.]")


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit 2), like every other
    bad input, instead of the usage followed by the error."""

    def error(self, message: str) -> NoReturn:
        """Print ``btlog CMD: error: …`` on one line and exit 2."""
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {safe(message)} (see --help)\n")


def _add_moment(parser: argparse.ArgumentParser, required: bool = True) -> None:
    parser.add_argument(
        "--at",
        metavar="WHEN",
        required=required,
        default=None if required else "end",
        help="moment: 12.5s, 1500ms, -2s, tick:N, seq:N, end, "
        "or an ISO-8601 wall time" + ("" if required else " (default: end)"),
    )


def _add_descriptions(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--descriptions",
        metavar="FILE",
        help="YAML: node path, name or type -> the words answers use (e.g. "
        "'ComputePathToPose: plan a path to the goal')",
    )


def _add_nodes_model(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--nodes-model",
        metavar="FILE",
        help="XML with a <TreeNodesModel> giving your node types' kinds and ports "
        "(e.g. Nav2's nav2_tree_nodes.xml: its conditions then run as conditions)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command."""
    parser = OneLineParser(
        prog="btlog", description="Record behavior-tree runs and explain any moment of them."
    )
    parser.add_argument("--version", action="version", version=f"btlog {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = commands.add_parser(
        "run",
        help="execute a tree and record the run",
        description="Execute a tree and record every event to MCAP.",
    )
    run.add_argument("tree", metavar="TREE", help="BehaviorTree.CPP XML file")
    add_tree_flags(run)
    add_limit_flags(run)
    run.add_argument(
        "--domain", default="scripted", help="simulated domain: scripted (default), kitting, taxi"
    )
    run.add_argument("--outcomes", metavar="F", help="outcomes file (YAML or JSON)")
    _add_nodes_model(run)
    run.add_argument(
        "--fail",
        metavar="SPEC",
        action="append",
        default=[],
        help='fail a node\'s activation: "NAME" (first) or "NAME@N"',
    )
    run.add_argument(
        "--failure-rate",
        metavar="P",
        type=float,
        default=0.0,
        help="probability that any activation fails (seeded; default 0)",
    )
    run.add_argument("--seed", metavar="N", type=int, default=0, help="random seed")
    run.add_argument(
        "--tick-period",
        metavar="S",
        type=float,
        default=0.1,
        help="seconds between ticks (default 0.1)",
    )
    run.add_argument(
        "--max-ticks",
        metavar="N",
        type=int,
        default=100_000,
        help="stop (and halt the tree) after N ticks",
    )
    run.add_argument(
        "--ask",
        metavar="WHEN=QUESTION",
        action="append",
        default=[],
        help='ask live, e.g. --ask "12.5s=Why are you doing this?"',
    )
    run.add_argument(
        "--realtime",
        action="store_true",
        help="pace ticks to the wall clock instead of simulated time",
    )
    run.add_argument(
        "--flush-interval",
        metavar="S",
        type=float,
        default=1.0,
        help="seconds between flushes to disk (default 1)",
    )
    _add_descriptions(run)
    run.add_argument("-o", "--output", metavar="OUT", help="recording file to write")
    run.add_argument("--quiet", action="store_true", help="print only the recording's path")

    ask = commands.add_parser("ask", help="answer one question at a moment")
    ask.add_argument("run", metavar="RUN")
    _add_moment(ask, required=False)
    ask.add_argument("question", metavar="QUESTION")
    ask.add_argument("--json", action="store_true", help="JSON output")
    _add_descriptions(ask)

    explain = commands.add_parser("explain", help="the run's story, or Q1-Q6 at a moment (--at)")
    explain.add_argument("run", metavar="RUN")
    explain.add_argument(
        "--at",
        metavar="WHEN",
        help="answer Q1-Q6 at this moment (without it: the whole run's story)",
    )
    explain.add_argument("--json", action="store_true", help="JSON output")
    _add_descriptions(explain)

    show = commands.add_parser("show", help="the tree with statuses at a moment")
    show.add_argument("run", metavar="RUN")
    _add_moment(show, required=False)
    show.add_argument("--blackboard", action="store_true", help="also show the blackboard")
    show.add_argument("--plain", action="store_true", help="no colour")
    show.add_argument("--html", metavar="FILE", help="write the moment as an HTML page")

    timeline = commands.add_parser("timeline", help="the events of a run")
    timeline.add_argument("run", metavar="RUN")
    timeline.add_argument(
        "--node", metavar="N", help="name, path or uid; a type: every node of that type"
    )
    timeline.add_argument("--status", metavar="S", help="only transitions to this status")
    timeline.add_argument("--from", dest="start", metavar="W", help="from this moment")
    timeline.add_argument("--to", dest="end", metavar="W", help="up to this moment")
    timeline.add_argument("--writes", action="store_true", help="include blackboard writes")
    timeline.add_argument("--json", action="store_true", help="JSON lines output")
    timeline.add_argument("--plain", action="store_true", help="no colour")

    replay = commands.add_parser("replay", help="step through a run interactively")
    replay.add_argument("run", metavar="RUN")
    replay.add_argument("--plain", action="store_true", help="no colour")
    replay.add_argument(
        "--script",
        metavar="FILE",
        help="read commands from FILE instead of the keyboard ('-': stdin)",
    )

    sql = commands.add_parser(
        "sql",
        help="SQL over the read model (read-only)",
        description="Run one SQL query over the read model of one or more recordings. The "
        "query is read-only: it runs after the runs are attached (their caches read-only), "
        "with DuckDB's external access disabled and its configuration locked, so it "
        "cannot read or write files (read_csv, glob, COPY TO, ATTACH), install or load "
        "extensions, or change any later answer.",
    )
    sql.add_argument("runs", metavar="RUN", nargs="*")
    sql.add_argument("query", metavar="QUERY")
    sql.add_argument(
        "--lake",
        metavar="LAKE",
        help="query a Parquet lake written by 'export --parquet' instead (views named "
        "like the tables, plus causes; columns domain, date and run_id from the folders)",
    )
    sql.add_argument("--format", choices=("table", "csv", "json"), default="table")
    sql.add_argument(
        "--timeout",
        metavar="SECONDS",
        type=float,
        default=DEFAULT_QUERY_TIMEOUT,
        help=f"stop the query after SECONDS (default {DEFAULT_QUERY_TIMEOUT:g}; 0: no limit)",
    )

    diff = commands.add_parser("diff", help="divergence between two runs (or a run and a tree)")
    diff.add_argument("a", metavar="A", help="a recording")
    diff.add_argument("b", metavar="B", help="a recording, or a tree XML (its nominal run)")
    add_tree_flags(diff)
    add_limit_flags(diff)
    diff.add_argument("--json", action="store_true", help="JSON output")
    diff.add_argument("--plain", action="store_true", help="no colour")

    check = commands.add_parser("check", help="regression checks on stored runs")
    check.add_argument("runs", metavar="RUN", nargs="+")
    add_tree_flags(check)
    add_limit_flags(check)
    check.add_argument("--expect", metavar="F", help="expectations file (YAML)")
    check.add_argument(
        "--rerun",
        action="store_true",
        help="run the tree again with the recorded settings and compare",
    )
    check.add_argument("--tree", metavar="TREE", help="with --rerun: this tree file instead")
    check.add_argument("--json", action="store_true", help="JSON output")
    check.add_argument(
        "--html", metavar="FILE", help="when a check fails, write the viewer of that run to FILE"
    )

    view = commands.add_parser(
        "view",
        help="see a run in the browser (tree, timeline, answers)",
        description="Serve a web viewer of one run, or of two side by side, on 127.0.0.1.",
    )
    view.add_argument("run", metavar="REC", help="a recording")
    view.add_argument("other", metavar="REC2", nargs="?", help="a second recording to compare")
    view.add_argument("--port", metavar="P", type=int, default=0, help="port (default: a free one)")
    view.add_argument("--no-browser", action="store_true", help="do not open a browser")
    view.add_argument("--export", metavar="FILE", help="write one self-contained HTML file instead")

    recover = commands.add_parser("recover", help="salvage a truncated recording")
    recover.add_argument("broken", metavar="BROKEN")
    recover.add_argument("-o", "--output", metavar="FIXED", required=True)

    validate = commands.add_parser("validate", help="load and check a tree")
    validate.add_argument("tree", metavar="TREE")
    add_tree_flags(validate)
    _add_nodes_model(validate)
    validate.add_argument(
        "--outcomes", metavar="F", help="check an outcomes file against the tree too"
    )
    add_limit_flags(validate)
    validate.add_argument("--json", action="store_true", help="JSON output")

    from btlog.cli import cache, fleet, record_py, sources

    sources.add_parsers(commands)
    record_py.add_parsers(commands)
    cache.add_parsers(commands)
    fleet.add_parsers(commands)
    return parser


#: Each command's function as ``module:function`` of ``btlog.cli``: a command imports
#: only its own module, so ``ask`` never pays for the importers, the viewer or the fleet
#: (``tests/test_imports.py`` keeps each command's import set).
HANDLERS = {
    "run": "commands:run",
    "ask": "commands:ask",
    "explain": "commands:explain",
    "show": "commands:show",
    "timeline": "commands:timeline",
    "sql": "commands:sql",
    "recover": "commands:recover",
    "validate": "commands:validate",
    "replay": "replay:replay",
    "diff": "checks:diff",
    "check": "checks:check",
    "import": "sources:import_",
    "export": "sources:export",
    "attach": "sources:attach",
    "record-py": "record_py:record_py",
    "cache": "cache:cache_command",
    "view": "view:view",
    "fleet": "fleet:fleet",
}


def handler(command: str) -> Callable[[argparse.Namespace], int]:
    """The function of ``command``, its module imported now."""
    module, function = HANDLERS[command].split(":")
    return getattr(importlib.import_module(f"btlog.cli.{module}"), function)


def _is_bad_input(error: BaseException) -> bool:
    """Errors that describe the user's input (files, values, SQL), not a bug of btlog.
    DuckDB's and the executor's errors can only have been raised if their modules were
    imported, so they are looked up, not imported."""
    kinds: tuple[type[BaseException], ...] = (ValueError, OSError)
    duckdb = sys.modules.get("duckdb")
    if duckdb is not None:
        kinds += (duckdb.Error,)
    behavior = sys.modules.get("btlog.executor.behavior")
    if behavior is not None:
        kinds += (behavior.NodeExecutionError,)
    return isinstance(error, kinds)


def join_negative_moments(argv: Sequence[str]) -> list[str]:
    """``--at -2s`` as ``--at=-2s``: argparse would take ``-2s`` for an option."""
    joined: list[str] = []
    for arg in argv:
        if joined and joined[-1] in MOMENT_OPTIONS and _NEGATIVE.match(arg):
            joined[-1] = f"{joined[-1]}={arg}"
        else:
            joined.append(arg)
    return joined


def _rejoin_positionals(args: argparse.Namespace, extra: list[str]) -> bool:
    """Give back the positionals written after an option: argparse takes one run of
    them, so `export REC --to F OUT` leaves OUT over and `sql REC --format csv QUERY`
    leaves QUERY (the recording taken for the query). False if ``extra`` is not that."""
    if any(a.startswith("-") for a in extra):
        return False
    if args.command == "export":
        args.items += extra
        return True
    if args.command == "sql":
        args.runs += [args.query, *extra[:-1]]
        args.query = extra[-1]
        return True
    return False


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    fit_address_space()
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(
            join_negative_moments(sys.argv[1:] if argv is None else argv)
        )
        if extra and not _rejoin_positionals(args, extra):
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as exit_:
        return int(exit_.code or 0)
    from btlog.cli.cache import cache_dir_of

    try:
        apply_limit_flags(args)
        with cache_dir_of(args):
            return int(handler(args.command)(args) or EXIT_OK)
    except KeyboardInterrupt:
        print("btlog: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return EXIT_OK
    except Exception as error:
        if os.environ.get("BTLOG_DEBUG"):
            import traceback

            traceback.print_exc()
        if isinstance(error, MemoryError):  # an input too large for the memory given
            print(f"btlog {args.command}: {out_of_memory()}", file=sys.stderr)
            return EXIT_BAD_INPUT
        if _is_bad_input(error):
            print(f"btlog {args.command}: {safe(one_line(error))}", file=sys.stderr)
            return EXIT_BAD_INPUT
        print(
            f"btlog {args.command}: internal error, a bug in btlog ({type(error).__name__}: "
            f"{safe(one_line(error))}); BTLOG_DEBUG=1 shows the traceback",
            file=sys.stderr,
        )
        return EXIT_BUG


if __name__ == "__main__":
    sys.exit(main())

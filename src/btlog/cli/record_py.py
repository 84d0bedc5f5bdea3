"""``btlog record-py MODULE:FACTORY -o run.mcap``: record a py_trees tree's run."""

from __future__ import annotations

import argparse
import sys
from argparse import Namespace
from typing import TYPE_CHECKING

from btlog.render.escape import safe

if TYPE_CHECKING:
    from btlog.explain.questions import Answer
    from btlog.live_questions import LiveQuestion


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Add ``record-py`` to the command line."""
    parser = commands.add_parser(
        "record-py",
        help="tick a py_trees tree and record the run",
        description="Build a py_trees tree with FACTORY (a function of MODULE returning a "
        "BehaviourTree or its root behaviour), set it up, tick it and record every status "
        "change, blackboard write and subtree change.",
    )
    parser.add_argument(
        "factory",
        metavar="MODULE:FACTORY",
        help="e.g. py_trees.demos.selector:create_root, or path/to/trees.py:create_root",
    )
    parser.add_argument("-o", "--output", metavar="OUT", required=True, help="recording")
    parser.add_argument("--ticks", metavar="N", type=int, default=100, help="ticks (100)")
    parser.add_argument(
        "--period", metavar="S", type=float, default=0.1, help="seconds between ticks (0.1)"
    )
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="tick every --period seconds of the wall clock (default: a simulated clock)",
    )
    parser.add_argument(
        "--until-done", action="store_true", help="stop once the root succeeds or fails"
    )
    parser.add_argument(
        "--ask",
        metavar="WHEN=QUESTION",
        action="append",
        default=[],
        help='ask live, e.g. --ask "tick:5=What are you doing?"',
    )


def record_py(args: Namespace) -> int:
    """``btlog record-py``: print the answers, then the recording's summary."""
    from btlog.sources.py_trees_script import record_script

    def printed(question: LiveQuestion, result: Answer) -> None:
        print(f"[{safe(question.when)}] {safe(question.question)}", flush=True)
        print(f"  {safe(result.text)}", flush=True)

    run = record_script(
        args.factory,
        args.output,
        args.ticks,
        args.period,
        args.ask,
        realtime=args.realtime,
        until_done=args.until_done,
        on_answer=printed,
    )
    for line in run.refused:
        print(f"btlog record-py: not answered: {safe(line)}", file=sys.stderr)
    result = run.result
    assert result is not None
    for warning in result.warnings:
        print(f"btlog record-py: warning: {safe(warning)}", file=sys.stderr)
    print(
        f"{safe(args.factory)} -> {safe(result.path)}: {result.transitions} transitions, "
        f"{result.writes} writes, {result.ticks} ticks, last root status {result.final_status}"
    )
    return 0

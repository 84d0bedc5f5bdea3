"""The commands that record, inspect and query runs (one function per command)."""

from __future__ import annotations

import csv
import json
import sys
from argparse import Namespace
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING

from btlog.errors import EXIT_BAD_INPUT, EXIT_OK
from btlog.explain.hierarchy import current_nodes
from btlog.explain.insertion import apply_to_copy
from btlog.explain.questions import answer
from btlog.explain.questions import explain as explain_all
from btlog.limits import seconds
from btlog.outputs import refuse_overwrite
from btlog.render.escape import safe
from btlog.status import Status

# Each command imports what only it uses (rich's widgets, the executor) when it runs, so
# a warm ``btlog ask`` stays fast (tests/test_imports.py keeps each command's imports).
if TYPE_CHECKING:
    from rich.progress import Progress

    from btlog.explain.questions import Answer
    from btlog.replay.database import Run, RunDatabase
    from btlog.replay.moments import Resolved
    from btlog.runner import LiveQuestion


def _print_json(data: object) -> None:
    print(json.dumps(data, indent=2, default=repr))


# -- run ---------------------------------------------------------------------------------
def run(args: Namespace) -> int:
    """``btlog run``: execute and record; print the file, event count and final status."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from btlog.render.terminal import make_console
    from btlog.runner import RunConfig, execute

    config = RunConfig(
        tree=args.tree,
        domain=args.domain,
        outcomes_file=args.outcomes,
        nodes_model=args.nodes_model,
        fail=args.fail,
        failure_rate=args.failure_rate,
        seed=args.seed,
        tick_period=args.tick_period,
        max_ticks=args.max_ticks,
        questions=args.ask,
        realtime=args.realtime,
        flush_interval=args.flush_interval,
        descriptions_file=args.descriptions,
        main_tree=args.main_tree,
        trees=args.trees,
    )
    console = make_console()
    progress: Progress | None = None
    ticks = [0]  # the last tick begun

    def on_tick(tick: int) -> None:
        ticks[0] = tick
        if progress is not None:
            progress.update(progress.task_ids[0], completed=tick)

    def on_answer(question: LiveQuestion, result: Answer, seq: int) -> None:
        if args.quiet:
            return
        lines = f"[{safe(question.when)}] {safe(question.question)}\n  {safe(result.text)}"
        if progress is None or not sys.stdout.isatty():
            print(lines, flush=True)
            return
        # on the terminal, above the bar, which first shows the tick of the answer
        progress.update(progress.task_ids[0], completed=ticks[0])
        progress.refresh()
        progress.console.print(lines, highlight=False, markup=False)

    if sys.stderr.isatty() and not args.quiet:
        progress = Progress(
            TextColumn("running"),
            BarColumn(),
            TextColumn("tick {task.completed}"),
            TimeElapsedColumn(),
            console=make_console(stderr=True),
            transient=True,
            redirect_stdout=False,
            redirect_stderr=False,
        )
        with progress:
            progress.add_task("run", total=args.max_ticks)
            result = execute(config, args.output, on_answer, on_tick=on_tick)
    else:
        result = execute(config, args.output, on_answer)
    if args.quiet:
        print(safe(result.path))
    else:
        console.print(f"recording: {safe(result.path)}", highlight=False)
        console.print(
            f"events: {result.events}  ticks: {result.ticks}  "
            f"final status: {result.final_status.name}",
            highlight=False,
        )
    if not result.final_status.completed:
        print(
            f"btlog run: warning: stopped after --max-ticks {args.max_ticks} with the tree "
            f"{result.final_status.name}; the tree was halted",
            file=sys.stderr,
        )
    for warning in result.warnings:
        print(f"btlog run: warning: {safe(warning)}", file=sys.stderr)
    for refusal in result.refused:  # the run is recorded: its moment was outside it
        print(f"btlog run: warning: {safe(refusal)} (not answered)", file=sys.stderr)
    return EXIT_OK


# -- questions ---------------------------------------------------------------------------
def _open_runs(*paths: str) -> RunDatabase:
    """Open recordings; on a terminal, say so while a first ingestion builds the cache
    (a warm open shows nothing, and so does not import rich)."""
    from btlog.replay.database import open_runs

    if sys.stderr.isatty() and not _cached(paths):
        from btlog.render.terminal import make_console

        with make_console(stderr=True).status(
            "reading the recording (the first time builds its cache)…"
        ):
            database = open_runs(*paths)
    else:
        database = open_runs(*paths)
    for notice in database.notices:
        print(f"btlog: notice: {safe(notice)}", file=sys.stderr)
    for info in database.runs:
        for warning in info.warnings:
            print(f"btlog: warning: {safe(warning)}", file=sys.stderr)
    return database


def _cached(paths: tuple[str, ...]) -> bool:
    """Whether every recording's cache is built (an unreadable one: False, and opening it
    says why)."""
    from btlog.replay.database import cache_location

    try:
        return all(cache_location(path).is_file() for path in paths)
    except OSError:
        return False


def _open_run(path: str) -> tuple[RunDatabase, Run]:
    database = _open_runs(path)
    return database, database.run(path)


def _describe(run: Run, descriptions: str | None) -> None:
    """Apply a descriptions file (``--descriptions``) to a recorded run's tree, over the
    descriptions it was recorded with; warn about entries that name no node."""
    if not descriptions:
        return
    from btlog.tree.descriptions import apply_descriptions, load_descriptions

    for key in apply_descriptions(run.tree, load_descriptions(descriptions)):
        print(
            f"btlog: warning: {safe(descriptions)}: {safe(repr(key))} names no node",
            file=sys.stderr,
        )


@contextmanager
def _moment(path: str, moment: str, descriptions: str | None = None) -> Iterator[tuple]:
    """(run, tree, state, resolved moment) at a moment of a recording, while its read
    model is open; ``descriptions``, a descriptions file, gives its nodes' words."""
    database, run = _open_run(path)
    try:
        _describe(run, descriptions)
        resolved = run.resolve(moment)
        tree, state = run.state_after(resolved.count)
        yield run, tree, state, resolved
    finally:
        database.close()


def ask(args: Namespace) -> int:
    """``btlog ask``: one answer at a moment (Q7 shows the tree it would give)."""
    with _moment(args.run, args.at, args.descriptions) as (run, tree, state, moment):
        result = answer(tree, state, args.question, run.history(), moment.t_ns)
    if args.json:
        _print_json({**result.to_json(), "moment": moment.to_json()})
        return 0 if result.known else EXIT_BAD_INPUT
    if not result.known:  # as for a question btlog does not understand: bad input
        print(f"btlog ask: {safe(result.text)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(safe(result.text))
    if result.insertion is not None:
        from btlog.render.terminal import make_console, print_lines, tree_lines

        changed = apply_to_copy(tree, result.insertion, seq=state.seq)
        console = make_console()
        console.print("\nThe tree after this insertion (the recording is unchanged):")
        current = {n.uid for n in current_nodes(tree, state)}
        print_lines(console, tree_lines(changed, state, current))
    return 0


#: Metadata of an imported run that says what its source left out, shown by ``explain``.
NOTE_KEYS = ("mid_run", "incomplete")


def recording_notes(metadata: dict) -> list[str]:
    """What the recording says is missing from the run (a log that begins mid-run, a
    goal without its result), one note each."""
    return [str(metadata[key]) for key in NOTE_KEYS if metadata.get(key)]


def explain(args: Namespace) -> int:
    """``btlog explain``: the run's story, or Q1–Q6 at a moment (``--at``), and what the
    recording says is missing."""
    if args.at is None:
        return _story(args)
    with _moment(args.run, args.at, args.descriptions) as (run, tree, state, moment):
        answers = explain_all(tree, state, run.history())
        notes = recording_notes(run.info.metadata)
    if args.json:
        _print_json(
            {
                "moment": moment.to_json(),
                "answers": [a.to_json() for a in answers],
                "notes": notes,
            }
        )
        return 0
    for result in answers:
        print(f"{result.question}\n  {safe(result.text)}")
    for note in notes:
        print(f"Note: {safe(note)}")
    return 0


def _story(args: Namespace) -> int:
    """``btlog explain REC``: the whole run, top down."""
    from btlog.explain.story import story

    with _moment(args.run, "end", args.descriptions) as (run, tree, state, _moment_at):
        extent = run.extent
        told = story(
            tree, state, run.history(), duration_ns=extent.duration_ns, ticks=run.ticks_run()
        )
        notes = recording_notes(run.info.metadata)
    if args.json:
        _print_json({**told.to_json(), "notes": notes})
        return 0
    for line in told.lines():
        print(safe(line))
    for note in notes:
        print(f"Note: {safe(note)}")
    return 0


def show(args: Namespace) -> int:
    """``btlog show``: the tree with each node's status at a moment."""
    if args.html:
        refuse_overwrite(args.html, [args.run], "--html")
    with _moment(args.run, args.at) as (run, tree, state, moment):
        current = {n.uid for n in current_nodes(tree, state)}
        answers = explain_all(tree, state, run.history()) if args.html else []
    if args.html:
        from btlog.render.html import page

        title = f"{Path(args.run).name} at {args.at}"
        Path(args.html).write_text(page(title, tree, state, current, answers), encoding="utf-8")
        print(safe(args.html))
        return 0
    from rich.text import Text

    from btlog.render.terminal import blackboard_lines, make_console, print_lines, tree_lines

    console = make_console(args.plain)
    console.print(moment_header(moment), highlight=False)
    print_lines(console, tree_lines(tree, state, current))
    if args.blackboard:
        console.print()
        print_lines(console, blackboard_lines(state) or [Text(_no_blackboard(args.run))])
    return 0


def moment_header(moment: Resolved) -> str:
    """``at WHEN: seq S, tick T, TIME (last event at L)``: the moment as every header
    names it (``btlog.replay.moments.Resolved``): S the last event applied, T the
    moment's tick, TIME the moment's own time, L the last event's when it differs."""
    from btlog.render.terminal import format_ns

    last = "before the first event" if moment.seq is None else f"seq {moment.seq}"
    head = f"at {safe(moment.moment.text)}: {last}, tick {moment.tick}, {format_ns(moment.t_ns)}"
    if moment.last_event_t_ns is not None and moment.last_event_t_ns != moment.t_ns:
        head += f" (last event at {format_ns(moment.last_event_t_ns)})"
    return head


def _no_blackboard(path: str) -> str:
    """Why an empty blackboard is empty: it is, or the imported source never records it."""
    from btlog.record.reader import read_metadata

    source = read_metadata(path).get("source")
    if isinstance(source, dict) and not source.get("blackboard", True):
        return f"(the blackboard was not recorded: {source.get('format')} logs hold none)"
    return "(the blackboard is empty)"


def timeline(args: Namespace) -> int:
    """``btlog timeline``: the events, filtered by node, status and time, printed as they
    are read (a run's whole timeline in bounded memory)."""
    database, run = _open_run(args.run)
    try:
        status = None
        if args.status:
            try:
                status = Status[args.status.upper()]
            except KeyError:
                raise ValueError(f"unknown status {args.status!r}") from None
        entries = run.iter_timeline(node=args.node, status=status, start=args.start, end=args.end)
        rows = (e._asdict() for e in entries if args.writes or e.kind != "write")
        if args.json:
            for row in rows:
                print(json.dumps(row, default=repr))
            return 0
        from btlog.render.terminal import make_console

        console = make_console(args.plain)
        printed = False
        for row in rows:
            console.print(timeline_line(row), highlight=False)
            printed = True
        if not printed:
            console.print("(no events match)")
    finally:
        database.close()
    return 0


def timeline_line(row: dict) -> str:
    """One event of a timeline on one line (names escaped)."""
    from btlog.render.terminal import format_ns

    head = f"{row['seq']:>7}  {format_ns(row['t_ns']):>10}  tick {row['tick']:<6}"
    if row["kind"] == "write":
        value = json.dumps(row["value"], default=repr)
        return f"{head} {safe(row['scope'] or '(root)')}.{safe(row['key'])} = {safe(value)}"
    if row["kind"] == "mutation":
        return f"{head} inserted {safe(row['node'] or '')} #{row['uid']}"
    return (
        f"{head} {safe(row['node'] or '')} #{row['uid']}  {row['prev_status']} -> {row['status']}"
    )


# -- sql ---------------------------------------------------------------------------------
def sql(args: Namespace) -> int:
    """``btlog sql``: run a query over one or many runs, read-only (``RunDatabase.lock``),
    within ``--timeout`` seconds."""
    args.timeout = seconds(args.timeout, "--timeout") or None
    if args.lake is not None:
        if args.runs:
            raise ValueError("sql: give recordings or --lake LAKE, not both")
        from btlog.cli.fleet import lake_sql

        columns, rows = lake_sql(args)
        print_rows(args.format, columns, iter(rows))
    elif not args.runs:
        raise ValueError("sql: give at least one recording (or --lake LAKE)")
    else:
        database = _open_runs(*args.runs)
        try:
            database.lock()
            with database.sql_rows(args.query, timeout=args.timeout) as (columns, streamed):
                print_rows(args.format, columns, streamed)
        finally:
            database.close()
    return 0


#: Rows of ``sql``'s table output drawn as one table (a longer result: one a block).
TABLE_ROWS = 10_000


def batched(rows: Iterator[tuple], size: int) -> Iterator[list[tuple]]:
    """``rows`` in lists of ``size`` (the last shorter)."""
    while block := list(islice(rows, size)):
        yield block


def print_rows(form: str, columns: list[str], rows: Iterator[tuple]) -> None:
    """Print a query's rows as they come (bounded memory whatever their number): CSV,
    a JSON array, or tables of ``TABLE_ROWS`` rows each."""
    if form == "json":
        opening = "["  # json.dumps(rows, indent=2), a row at a time
        for row in rows:
            item = json.dumps(dict(zip(columns, row, strict=True)), default=str, indent=2)
            sys.stdout.write(f"{opening}\n  " + item.replace("\n", "\n  "))
            opening = ","
        sys.stdout.write("\n]\n" if opening == "," else "[]\n")
    elif form == "csv":
        writer = csv.writer(sys.stdout, lineterminator="\n")  # a Unix tool's lines, not CRLF
        writer.writerow([safe(c) for c in columns])
        for block in batched(rows, TABLE_ROWS):
            writer.writerows([["" if v is None else safe(v) for v in row] for row in block])
    else:
        from rich.table import Table

        from btlog.render.terminal import make_console

        console, empty = make_console(), True
        for block in batched(rows, TABLE_ROWS):
            table = Table(*[safe(c) for c in columns])
            for row in block:
                table.add_row(*[safe("NULL" if v is None else v) for v in row])
            console.print(table)
            empty = False
        if empty:
            console.print(Table(*[safe(c) for c in columns]))


# -- files -------------------------------------------------------------------------------
def recover(args: Namespace) -> int:
    """``btlog recover``: rewrite a truncated recording into a valid one."""
    from btlog.record.recovery import recover as salvage

    refuse_overwrite(args.output, [args.broken])
    report = salvage(args.broken, args.output)
    print(safe(report))
    return 0


#: How ``validate`` says why the main tree is the one (``Tree.main_choice``).
MAIN_TREE_CHOICES = {
    "uncalled": " (the only tree no other tree calls; --main-tree chooses another)",
    "--main-tree": " (--main-tree)",
}


def validate(args: Namespace) -> int:
    """``btlog validate``: load a tree, build it as ``run`` does (every check a run makes
    before its first tick), and report what it holds."""
    from btlog.runner import RunConfig, prepare

    config = RunConfig(
        tree=args.tree,
        outcomes_file=args.outcomes,
        nodes_model=args.nodes_model,
        main_tree=args.main_tree,
        trees=args.trees,
    )
    tree = prepare(config).tree
    kinds = Counter(n.kind for n in tree)
    subtrees = [n for n in tree if n.kind == "subtree"]
    leaf_types = sorted({n.type for n in tree if n.is_execution})
    if args.json:
        _print_json(
            {
                "file": args.tree,
                "main_tree": tree.name,
                "main_tree_choice": tree.main_choice,
                "warnings": tree.warnings,
                "format": tree.format,
                "nodes": len(tree),
                "kinds": dict(kinds),
                "files": tree.files,
                "subtrees": [n.description for n in subtrees],
                "leaf_types": leaf_types,
            }
        )
        return 0
    for warning in tree.warnings:
        print(f"btlog validate: warning: {safe(warning)}", file=sys.stderr)
    print(f"{safe(args.tree)}: OK (BehaviorTree.CPP v{tree.format} format)")
    why = MAIN_TREE_CHOICES.get(tree.main_choice, "")
    print(f"  main tree: {safe(tree.name)}{why}; goal: {safe(tree.root.description)}")
    print(
        "  nodes: "
        + str(len(tree))
        + " ("
        + ", ".join(f"{count} {kind}" for kind, count in sorted(kinds.items()))
        + ")"
    )
    if subtrees:
        print("  subgoals: " + "; ".join(safe(n.description) for n in subtrees))
    print("  leaf types: " + "; ".join(safe(t) for t in leaf_types))
    if len(tree.files) > 1:
        print("  files: " + ", ".join(safe(f) for f in tree.files))
    return 0

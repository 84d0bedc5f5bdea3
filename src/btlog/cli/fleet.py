"""The commands over a fleet of runs: ``export --parquet``, ``sql --lake``, ``fleet``."""

from __future__ import annotations

import argparse
import json
from argparse import Namespace
from collections import Counter

from btlog.render.escape import safe

_DATE = r"\d{4}-\d{2}-\d{2}"


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Add ``fleet`` to the command line."""
    fleet = commands.add_parser(
        "fleet",
        help="report across many runs exported to a Parquet lake",
        description="Outcome counts; per node its activations, failure rate and duration "
        "percentiles; the most frequent failure causes. Across every run of LAKE (written "
        "by 'btlog export RUN... --parquet LAKE'), or one domain/date of it.",
    )
    fleet.add_argument("lake", metavar="LAKE")
    fleet.add_argument("--domain", metavar="D", help="only runs of this domain")
    fleet.add_argument("--date", metavar="YYYY-MM-DD", help="only runs started that day")
    fleet.add_argument("--nodes", metavar="N", type=int, default=15, help="node rows shown (15)")
    fleet.add_argument("--json", action="store_true", help="JSON output (every node)")
    fleet.add_argument(
        "--compact",
        action="store_true",
        help="first merge each partition's files into one per table (an export does it "
        "at its end; this repairs a lake an interrupted export left behind)",
    )


def export_parquet(args: Namespace) -> int:
    """``btlog export RUN... --parquet LAKE``: every run's tables into the lake."""
    from btlog.fleet.lake import check_exportable, export_runs

    if args.jobs < 1:
        raise ValueError(f"--jobs {args.jobs}: expected 1 or more")
    check_exportable(args.items, args.parquet)
    done = export_runs(args.items, args.parquet, jobs=args.jobs)
    transitions = sum(e.transitions for e in done)
    partitions = len({e.partition for e in done})
    print(
        f"{len(done)} runs ({transitions} transitions) -> {safe(args.parquet)} "
        f"({partitions} partition{'s' if partitions != 1 else ''})"
    )
    return 0


def fleet(args: Namespace) -> int:
    """``btlog fleet LAKE``: the fleet report (``btlog.fleet.report``)."""
    import re

    from btlog.fleet.report import duckdb_report

    if args.date is not None and not re.fullmatch(_DATE, args.date):
        raise ValueError(f"--date {args.date!r}: expected YYYY-MM-DD")
    if args.compact:
        from btlog.fleet.compact import compact_lake

        compact_lake(args.lake)
    report = duckdb_report(args.lake, args.domain, args.date)
    if args.json:
        print(json.dumps(report.to_json(), indent=2))
        return 0
    if not report.runs:
        print("no runs match")
        return 0
    from rich.table import Table

    from btlog.render.terminal import make_console

    console = make_console()
    outcomes = ", ".join(f"{row['runs']} {safe(row['final_status'])}" for row in report.outcomes)
    console.print(f"{report.runs} runs: {outcomes}")
    nodes = Table("node (path)", "activations", "completed", "failed", "failure rate",
                  "p50 s", "p90 s", "p99 s")  # fmt: skip
    for row, label in zip(report.nodes[: args.nodes], node_labels(report.nodes), strict=False):
        nodes.add_row(
            safe(label),
            str(row["activations"]),
            str(row["completed"]),
            str(row["failed"]),
            "-" if row["failure_rate"] is None else f"{row['failure_rate']:.1%}",
            *("-" if row[k] is None else f"{row[k]:.3f}" for k in ("p50_s", "p90_s", "p99_s")),
        )
    console.print(nodes)
    if len(report.nodes) > args.nodes:
        console.print(f"({len(report.nodes) - args.nodes} more nodes: --nodes N or --json)")
    if report.causes:
        causes = Table("failed", "because", "times", "runs")
        for row in report.causes:
            causes.add_row(
                safe(row["failed_node"] or "-"),
                safe(f"{row['cause']} {row['verb']}"),
                str(row["times"]),
                str(row["runs"]),
            )
        console.print(causes)
    else:
        console.print("no failures")
    return 0


def node_labels(rows: list[dict]) -> list[str]:
    """Each node row's path, which names it across runs; a nameless node's path (its
    scope and nothing) or a path several rows share gets the node's type and uid too."""
    shared = Counter(row["path"] for row in rows)
    labels = []
    for row in rows:
        path = row["path"] or "(root)"
        if not row["name"] or shared[row["path"]] > 1:
            path += f" [{row['type']} #{row['uid']}]"
        labels.append(path)
    return labels


def lake_sql(args: Namespace) -> tuple[list[str], list[tuple]]:
    """``btlog sql --lake LAKE QUERY``: one read-only query over the lake's views, within
    ``--timeout`` seconds."""
    from btlog.fleet.lake import reading_lake
    from btlog.replay.database import run_query

    with reading_lake(args.lake) as con:
        return run_query(con, args.query, timeout=args.timeout)

"""The commands that bring other tools' runs in and out: ``import``, ``attach``, ``export``."""

from __future__ import annotations

import argparse
import sys
from argparse import Namespace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from btlog.cli.tree_flags import add_tree_flags
from btlog.outputs import refuse_overwrite
from btlog.render.escape import safe
from btlog.sources.tick_gap import DEFAULT_TICK_GAP_NS

if TYPE_CHECKING:  # the importers are imported by the command that runs them
    from btlog.sources.builder import BuildResult
    from btlog.tree.loader import TreeSource
    from btlog.tree.registry import Registry


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Add ``import``, ``attach`` and ``export`` to the command line."""
    imp = commands.add_parser(
        "import",
        help="import a BT.CPP log (FileLogger2 .btlog, v3 FileLogger .fbl, SqliteLogger "
        ".db3/.btdb) or a Nav2 or py_trees_ros bag",
        description="Turn a BehaviorTree.CPP log, or a rosbag2 bag (MCAP or SQLite, a folder "
        "or one file) with Nav2's /behavior_tree_log or py_trees_ros' BehaviourTree "
        "snapshots, into btlog recordings (format from content).",
    )
    imp.add_argument(
        "file",
        metavar="FILE",
        help=".btlog, .fbl, .db3, .btdb file, or a rosbag2 folder/.mcap/.db3",
    )
    imp.add_argument("-o", "--output", metavar="OUT", help="recording to write (FILE.mcap)")
    imp.add_argument("--tree", metavar="XML", help="the tree file (checked against the log's)")
    add_tree_flags(imp)
    imp.add_argument("--session", metavar="N", type=int, help="SQLite: only this session")
    imp.add_argument("--goal", metavar="N", type=int, help="Nav2 bag: only goal N (from 1)")
    _add_model_and_gap(imp)

    attach = commands.add_parser(
        "attach",
        help="record a running BT.CPP process live (Groot2 protocol)",
        description="Record a BT.CPP process that runs a Groot2Publisher (or Nav2 with "
        "enable_groot_monitoring) until --duration, or Ctrl-C.",
    )
    attach.add_argument("endpoint", metavar="tcp://HOST:PORT", help="the publisher's port")
    attach.add_argument("-o", "--output", metavar="OUT", required=True, help="recording")
    attach.add_argument("--duration", metavar="S", type=float, help="stop after S seconds")
    attach.add_argument(
        "--ask",
        metavar="WHEN=QUESTION",
        action="append",
        default=[],
        help='ask live, e.g. --ask "5s=What went wrong?"',
    )
    attach.add_argument(
        "--blackboard", action="store_true", help="poll the blackboards, record changes"
    )
    attach.add_argument(
        "--poll", metavar="S", type=float, default=0.01, help="seconds between polls (0.01)"
    )
    attach.add_argument(
        "--timeout",
        metavar="S",
        type=float,
        default=3.0,
        help="seconds to wait for each reply before the publisher counts as silent (3)",
    )
    attach.add_argument(
        "--reconnect",
        metavar="S",
        type=float,
        default=30.0,
        help="when the publisher falls silent or restarts, try to reconnect for S seconds "
        "(30; 0: end the recording at once); the time without data is marked as a gap",
    )
    _add_model_and_gap(attach)

    export = commands.add_parser(
        "export",
        help="write a recording in another tool's format (btlog: FileLogger2; nav2: ROS 2 MCAP)",
        description="Write a recording as a BT.CPP FileLogger2 .btlog, which Groot2 opens, or "
        "as a ROS 2 MCAP bag with Nav2's /behavior_tree_log (nav2), which Foxglove opens.",
    )
    export.add_argument(
        "items",
        metavar="REC OUT | RUN...",
        nargs="*",
        help="with --to: a recording and the file to write (OUT.btlog or OUT.mcap); "
        "with --parquet: the recordings to export",
    )
    export.add_argument("--to", choices=("btlog", "nav2"), help="the format")
    export.add_argument(
        "--parquet",
        metavar="LAKE",
        help="write each run's tables as Parquet under LAKE (LAKE/TABLE/domain=…/date=…/, "
        "one file per table and partition), for 'btlog fleet' and 'sql --lake'",
    )
    export.add_argument(
        "--jobs",
        metavar="N",
        type=int,
        default=1,
        help="with --parquet: export in N processes (default 1)",
    )


def _add_model_and_gap(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--nodes-model",
        metavar="FILE",
        help="XML with a <TreeNodesModel> declaring the kinds and ports of your node types",
    )
    parser.add_argument(
        "--tick-gap",
        metavar="MS",
        type=float,
        default=DEFAULT_TICK_GAP_NS / 1e6,
        help="a pause longer than this between transitions starts a new tick (default 1)",
    )


def _tree_source(args: Namespace) -> TreeSource | None:
    """``--tree`` as loaded with ``--main-tree`` and ``--trees`` (which need it)."""
    if args.tree is None:
        if args.main_tree or args.trees:
            raise ValueError("--main-tree and --trees choose the tree of --tree XML: give it")
        return None
    from btlog.tree.loader import TreeSource

    return TreeSource(args.tree, args.main_tree, tuple(args.trees))


def _registry(args: Namespace) -> Registry | None:
    from btlog.tree.loader import load_nodes_model

    return load_nodes_model(args.nodes_model) if args.nodes_model else None


def _gap_ns(args: Namespace) -> int:
    if not args.tick_gap > 0:
        raise ValueError(f"--tick-gap {args.tick_gap}: must be > 0")
    return round(args.tick_gap * 1e6)


def _report(source: str, result: BuildResult, command: str) -> None:
    for warning in result.warnings:
        print(f"btlog {command}: warning: {safe(warning)}", file=sys.stderr)
    print(
        f"{safe(source)} -> {safe(result.path)}: {result.transitions} transitions, "
        f"{result.writes} writes, {result.ticks} ticks, last root status {result.final_status}"
    )


def import_(args: Namespace) -> int:
    """``btlog import``: one recording per run in the file."""
    from btlog.sources import detect

    kind = detect(args.file)
    # --tree with --main-tree and --trees: one path-like value every importer accepts
    args.tree = _tree_source(args)
    registry, gap = _registry(args), _gap_ns(args)
    default = Path(args.output) if args.output else Path(Path(args.file).name).with_suffix(".mcap")
    if args.output:
        refuse_overwrite(args.output, [args.file, args.tree])
    if args.goal is not None and kind != "rosbag2":
        raise ValueError(f"{args.file}: --goal applies to Nav2 bags only")
    if kind == "rosbag2":
        from btlog.sources.nav2_rosbag import import_bag
        from btlog.sources.py_trees_ros_bag import import_snapshots, snapshot_topics

        if args.session is not None:
            raise ValueError(f"{args.file}: --session applies to SQLite logs only")
        if not args.output:
            default = Path(f"{Path(args.file).stem}-btlog.mcap")
        if snapshot_topics(args.file):  # py_trees_ros: the snapshots carry the tree
            if args.tree is not None or args.goal is not None:
                raise ValueError(f"{args.file}: py_trees_ros snapshots take no --tree, --goal")
            results = [import_snapshots(args.file, default)]
        else:
            results = import_bag(args.file, default, args.tree, registry, args.goal, gap)
    elif kind == "btcpp-fbl":
        from btlog.sources.btcpp_fbl import import_fbl

        if args.session is not None:
            raise ValueError(f"{args.file}: --session applies to SQLite logs only")
        results = [import_fbl(args.file, default, args.tree, registry, gap)]
    elif kind == "btcpp-filelog2":
        from btlog.sources.btcpp_filelog import import_filelog

        if args.session is not None:
            raise ValueError(f"{args.file}: --session applies to SQLite logs only")
        results = [import_filelog(args.file, default, args.tree, registry, gap)]
    else:
        from btlog.sources.btcpp_sqlite import import_sqlite, session_ids

        ids = session_ids(args.file)
        if args.session is not None:
            outputs = {args.session: default}
        elif len(ids) == 1:
            outputs = {ids[0]: default}
        else:
            outputs = {i: default.with_name(f"{default.stem}-session{i}.mcap") for i in ids}
        if not outputs:
            raise ValueError(f"{args.file}: the log has no sessions")
        results = import_sqlite(args.file, outputs, args.tree, registry, gap)
    for result in results:
        _report(args.file, result, "import")
    return 0


#: Per export format: the file suffix it needs and what its files cannot hold.
_EXPORTS = {
    "btlog": (".btlog", "Groot2 and BT.CPP expect", "FileLogger2 holds transitions only"),
    "nav2": (".mcap", "a ROS 2 bag needs", "BehaviorTreeLog holds status changes only"),
}


def export(args: Namespace) -> int:
    """``btlog export REC --to btlog OUT.btlog``, ``--to nav2 OUT.mcap``, or
    ``RUN... --parquet LAKE``."""
    from btlog.record.reader import open_recording

    if args.parquet is not None:
        if args.to is not None:
            raise ValueError("--to and --parquet cannot be combined")
        from btlog.cli.fleet import export_parquet

        return export_parquet(args)
    if args.to is None or len(args.items) != 2:
        raise ValueError("give REC OUT with --to btlog|nav2, or RUN... --parquet LAKE")
    args.run, args.output = args.items

    suffix, expects, holds = _EXPORTS[args.to]
    if Path(args.output).suffix != suffix:
        raise ValueError(f"{args.output}: {expects} the suffix {suffix}")
    refuse_overwrite(args.output, [args.run], "OUT")
    result: Any = None
    if args.to == "btlog":  # bounded memory when the file is in seq order (the usual case)
        from btlog.sinks.filelog_stream import stream_filelog

        streamed = stream_filelog(args.run, args.output)
        if streamed is not None:
            _warn(streamed.warnings)
            result = streamed.result
    elif args.to == "nav2":  # the same, for the ROS 2 bag
        from btlog.sinks.nav2_stream import stream_nav2

        bag = stream_nav2(args.run, args.output)
        if bag is not None:
            result, warnings = bag
            _warn(warnings)
    if result is None:
        recording = open_recording(args.run)
        _warn(recording.warnings)
        if args.to == "nav2":
            from btlog.sinks.nav2_rosbag import export_nav2

            result = export_nav2(recording, args.output)
        else:
            from btlog.sinks.btcpp_filelog import export_filelog

            result = export_filelog(recording, args.output)
    if result.writes_left_out:
        print(
            f"btlog export: note: {result.writes_left_out} blackboard writes left out ({holds})",
            file=sys.stderr,
        )
    messages = getattr(result, "messages", None)
    counted = f"{messages} messages, " if messages is not None else ""
    print(f"{safe(args.run)} -> {safe(result.path)}: {counted}{result.transitions} transitions")
    return 0


def _warn(warnings: list[str]) -> None:
    for warning in warnings:
        print(f"btlog export: warning: {safe(warning)}", file=sys.stderr)


def attach(args: Namespace) -> int:
    """``btlog attach tcp://HOST:PORT -o OUT``: record until --duration or Ctrl-C."""
    from btlog.explain.questions import Answer
    from btlog.live_questions import LiveQuestion
    from btlog.sources.attach import AttachOptions
    from btlog.sources.attach import attach as record
    from btlog.sources.builder import RecordingBuilder
    from btlog.sources.live import LiveAnswers

    if args.duration is not None and args.duration <= 0:
        raise ValueError(f"--duration {args.duration}: must be > 0")
    for flag, value in (("--poll", args.poll), ("--timeout", args.timeout)):
        if not 0 < value <= 3600:
            raise ValueError(f"{flag} {value}: must be > 0 and at most 3600 seconds")
    if not 0 <= args.reconnect < float("inf"):
        raise ValueError(f"--reconnect {args.reconnect}: must be >= 0 seconds")
    questions = [LiveQuestion.parse(q) for q in args.ask]
    options = AttachOptions(
        args.duration,
        args.poll,
        args.blackboard,
        timeout=args.timeout,
        tick_gap_ns=_gap_ns(args),
        reconnect=args.reconnect,
    )

    def printed(question: LiveQuestion, result: Answer) -> None:
        print(f"[{safe(question.when)}] {safe(question.question)}", flush=True)
        print(f"  {safe(result.text)}", flush=True)

    class Hooks(LiveAnswers):
        def on_start(self, builder: RecordingBuilder) -> None:
            super().on_start(builder)
            print(f"attached to {args.endpoint} ({len(builder.tree)} nodes); Ctrl-C to stop")

        def on_fault(self, builder: RecordingBuilder, message: str) -> None:
            print(f"btlog attach: {safe(message)}", file=sys.stderr, flush=True)

    result = record(
        args.endpoint,
        args.output,
        options,
        _registry(args),
        Hooks(questions, printed),
    )
    _report(args.endpoint, result.build, "attach")
    return 0

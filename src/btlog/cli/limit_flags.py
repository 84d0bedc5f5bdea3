"""``--max-nodes`` and ``--max-file-size``: the commands that load trees may move the
bounds of ``btlog.limits`` (for one process, before anything is read)."""

from __future__ import annotations

import argparse

from btlog import limits


def add_limit_flags(parser: argparse.ArgumentParser) -> None:
    """Give a command that loads trees the two flags, with the defaults in its help."""
    parser.add_argument(
        "--max-nodes",
        metavar="N",
        type=int,
        help=f"refuse trees of more than N nodes once SubTrees are expanded "
        f"(default {limits.MAX_NODES})",
    )
    parser.add_argument(
        "--max-file-size",
        metavar="BYTES",
        type=int,
        help=f"refuse tree, outcomes and expectations files over BYTES "
        f"(default {limits.MAX_FILE_BYTES})",
    )


def apply_limit_flags(args: argparse.Namespace) -> None:
    """Put the flags given on the command line in force (commands without them: no-op)."""
    limits.override(
        max_file_bytes=getattr(args, "max_file_size", None),
        max_nodes=getattr(args, "max_nodes", None),
    )

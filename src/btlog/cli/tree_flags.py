"""``--main-tree`` and ``--trees``: how the commands that load trees choose them, as a
BT.CPP program does (``registerBehaviorTreeFromFile`` for each file, then
``createTree(ID)``)."""

from __future__ import annotations

import argparse


def add_tree_flags(parser: argparse.ArgumentParser) -> None:
    """Give a command that loads trees the two flags."""
    parser.add_argument(
        "--main-tree",
        metavar="ID",
        help="the tree to create (default: main_tree_to_execute, else the only tree, else "
        "the one tree no other tree calls)",
    )
    parser.add_argument(
        "--trees",
        metavar="PATH",
        action="append",
        default=[],
        help="register more tree files before creating the main tree, as a BT.CPP program "
        "does: a file, or a folder (its *.xml files); repeatable",
    )

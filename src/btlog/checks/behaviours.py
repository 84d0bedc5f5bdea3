"""Where a behaviour comes from: a recording's executed actions, or a tree's nominal run.

``btlog diff`` and ``btlog check --rerun`` compare two behaviours; each side is either
an MCAP recording (its events folded into executed actions) or a tree XML file, run in
memory with every leaf succeeding at once (what the tree does when nothing goes wrong).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import EventLog
from btlog.executor.clock import SimClock
from btlog.executor.engine import Executor
from btlog.explain.divergence import (
    ActionList,
    Divergence,
    ExecutedAction,
    actions_from_events,
    diverge,
)
from btlog.record.reader import Recording, UntidyRecording, open_recording, stream_events
from btlog.record.walk import MAGIC
from btlog.tree.loader import load_tree

#: Tick limit of a nominal run (a tree that never completes is cut off here).
NOMINAL_MAX_TICKS = 1000
#: The prefix that tells a recording from a tree file.
_MCAP_PREFIX = MAGIC[:5]


def executed_actions(recording: Recording | str | os.PathLike[str]) -> ActionList:
    """The executed actions of a recording (a ``Recording`` or the path of one). A path
    is read front to back without holding its events (``stream_events``) unless the file
    is untidy (damaged, out of order): then it is read whole."""
    if isinstance(recording, str | os.PathLike):
        streamed = stream_events(recording)
        if streamed is not None:
            try:
                return actions_from_events(*streamed)
            except UntidyRecording:
                pass
        recording = open_recording(recording)
    return actions_from_events(recording.tree, recording.events)


def nominal_actions(
    tree_path: str | os.PathLike[str], main_tree: str | None = None, trees: Sequence[str] = ()
) -> ActionList:
    """The nominal sequence of a tree: its actions when every leaf succeeds at once.

    The tree (``main_tree`` of the file and of ``trees``, as ``load_tree`` chooses) runs in
    memory (simulated clock, scripted leaves, no file) until the root completes or
    ``NOMINAL_MAX_TICKS`` ticks have passed.
    """
    tree = load_tree(os.fspath(tree_path), main_tree=main_tree, trees=trees)
    defaults: dict[str, Any] = {"default": {"status": "SUCCESS", "duration": 0}}
    outcomes = Outcomes.from_mapping(defaults, "nominal outcomes")
    executor = Executor(tree, clock=SimClock(), leaf_factory=scripted_leaf_factory(tree, outcomes))
    log = EventLog()
    executor.subscribe(log)
    try:
        executor.run(NOMINAL_MAX_TICKS)
    finally:
        executor.close()
    return actions_from_events(tree, log.events)


def is_recording(path: str | os.PathLike[str]) -> bool:
    """True when ``path`` starts like an MCAP file (otherwise it is taken as a tree)."""
    try:
        with open(path, "rb") as file:
            return file.read(len(_MCAP_PREFIX)) == _MCAP_PREFIX
    except OSError:
        return True  # let the recording reader report the missing/unreadable file


def actions_of(
    path: str | os.PathLike[str], main_tree: str | None = None, trees: Sequence[str] = ()
) -> Sequence[ExecutedAction]:
    """The behaviour stored at ``path``: a recording's executed actions, or a tree XML's
    nominal sequence (``main_tree`` and ``trees`` as for ``nominal_actions``)."""
    if is_recording(path):
        return executed_actions(path)
    return nominal_actions(path, main_tree, trees)


def label(path: str | os.PathLike[str]) -> str:
    """How a behaviour's source is named in reports."""
    name = os.fspath(path)
    return name if is_recording(path) else f"{name} (nominal sequence of the tree)"


def diff_paths(
    a: str | os.PathLike[str],
    b: str | os.PathLike[str],
    main_tree: str | None = None,
    trees: Sequence[str] = (),
) -> Divergence:
    """Compare the behaviours stored at two paths (recordings or tree XML files; a tree
    is chosen with ``main_tree`` and ``trees``)."""
    return diverge(
        actions_of(a, main_tree, trees), actions_of(b, main_tree, trees), label(a), label(b)
    )

"""``btlog view --export``: the viewer as one self-contained HTML file.

The page carries each run's events as columns (time, tick, kind, node, status or write)
and its ticks (number, start, end), folds the events in the browser and resolves moments
there by the rules of ``btlog.replay.moments`` (``api.js``'s ``resolveMoment``, checked
against it by the tests). The answers to the standard questions are computed here, by
``btlog.explain`` with the run's history (a ``LiveHistory`` fed the run's events), after
every event that can change them (status changes and tree mutations; blackboard writes
do not enter the answers), and stored only where they change; so is the run's story.
Questions about a named node ("Why did X fail?", "Can you X?") need the recording: the
page says so and gives the ``btlog ask`` command that answers. Nothing is fetched:
scripts, styles and data are inlined.
"""

from __future__ import annotations

from typing import Any

import orjson

from btlog.explain.hierarchy import current_nodes
from btlog.explain.questions import QUESTIONS
from btlog.history import LiveHistory
from btlog.limits import MAX_NODES
from btlog.status import STATUS_NAMES, Status
from btlog.view.model import RunView, answers_json, question_patterns, standard_questions
from btlog.view.page import page_html

#: The most events an exported page holds (past it, the page would be too slow to open):
#: one tick of the widest legal tree (``MAX_NODES`` leaves under one Sequence, two changes
#: each, and RUNNING where a leaf takes a tick) fits.
MAX_EXPORT_EVENTS = 3 * MAX_NODES
_CODES = {name: code for code, name in enumerate(STATUS_NAMES)}
_KINDS = {"status": 0, "write": 1, "mutation": 2}


class ExportTooLarge(ValueError):
    """A recording with more events than an exported page holds."""


def run_data(view: RunView) -> dict[str, Any]:
    """One run of an exported page: its meta, every event as columns indexed by seq
    (``st``: the new status's code for a status change, the index into ``writes`` for a
    blackboard write), and the standard answers and current nodes after every event where
    they change (``answers``: see ``_AnswerSets``)."""
    run = view.run
    columns: dict[str, list] = {k: [] for k in ("t", "tick", "kind", "uid", "st", "prev")}
    writes: list[list] = []
    unset = _unset_seqs(view)
    mutations = {m.seq: m for m in run.mutations}
    # the state and the run's history so far, its snapshots spread as the read model's
    projection = LiveHistory(run.tree, snapshot_every=run.snapshot_every)
    changes = _AnswerSets()
    changes.record(projection, 0)
    for entry in run.timeline():
        columns["t"].append(entry.t_ns)
        columns["tick"].append(entry.tick)
        columns["kind"].append(_KINDS[entry.kind])
        columns["uid"].append(entry.uid)
        columns["prev"].append(_CODES.get(entry.prev_status or "", 0))
        if entry.kind == "status":
            prev, status = Status[entry.prev_status or "IDLE"], Status[entry.status or "IDLE"]
            columns["st"].append(int(status))
            projection.on_status(entry.seq, entry.t_ns, entry.tick, entry.uid or 0, prev, status)
        elif entry.kind == "write":
            columns["st"].append(len(writes))
            kind = "unset" if entry.seq in unset else "set"
            writes.append([entry.scope, entry.key, entry.value, kind])
            projection.on_write(
                entry.seq, entry.t_ns, entry.tick, entry.scope or "", entry.key or "",
                entry.value, kind, entry.uid,
            )  # fmt: skip
            continue  # writes do not enter the answers
        else:
            columns["st"].append(0)
            projection.on_mutation(mutations[entry.seq])
        changes.record(projection, entry.seq + 1)
    return {
        "meta": view.meta(),
        "events": {**columns, "writes": writes},
        "ticks": _ticks(view),
        "answers": changes.to_json(),
    }


def _ticks(view: RunView) -> dict[str, list[int]]:
    """The run's tick records as columns (tick, start, end), in order."""
    _cols, rows = view.database.sql(
        "SELECT tick, start_ns, end_ns FROM ticks WHERE run_id = $run ORDER BY tick",
        {"run": view.run.run_id},
    )
    return {key: [row[i] for row in rows] for i, key in enumerate(("tick", "start", "end"))}


def _unset_seqs(view: RunView) -> set[int]:
    _cols, rows = view.database.sql(
        "SELECT seq FROM blackboard WHERE run_id = $run AND type = 'unset'",
        {"run": view.run.run_id},
    )
    return {row[0] for row in rows}


class _AnswerSets:
    """The answers after each event, as the page holds them: ``at`` (counts, ascending)
    and ``sets`` (the current nodes and the indexes of the answers into ``table``, where
    each distinct answer is written once, without its nodes when they are the current
    ones), a set only where it changes. The page's size
    is so bounded by the distinct answers, not by events x answer length (a goal of
    5,000 steps is said in one long answer, which would otherwise be repeated at every
    event)."""

    def __init__(self) -> None:
        self.at: list[int] = []
        self.sets: list[dict[str, list[int]]] = []
        self.table: list[dict[str, Any]] = []
        self._index: dict[tuple[str, bytes], int] = {}

    def record(self, projection: LiveHistory, count: int) -> None:
        """Append the answers after ``count`` events when they differ from the last ones."""
        tree, state = projection.tree, projection.state
        current = [n.uid for n in current_nodes(tree, state)]
        answers = [self._indexed(a, current) for a in answers_json(tree, state, projection)]
        found = {"answers": answers, "current": current}
        if not self.sets or self.sets[-1] != found:
            self.at.append(count)
            self.sets.append(found)

    def _indexed(self, answer: dict[str, Any], current: list[int]) -> int:
        """The index of ``answer`` in the table, which it joins if new; its nodes are left
        out when they are the ``current`` ones (the page puts them back)."""
        if answer["nodes"] == current:
            answer = {k: v for k, v in answer.items() if k != "nodes"}
        # the text apart: an answer kept by the tree (``Tree.shaped``) is the same string
        # object every time, whose hash Python keeps
        rest = orjson.dumps({k: v for k, v in answer.items() if k != "answer"})
        key = (answer["answer"], rest)
        index = self._index.get(key)
        if index is None:
            index = self._index[key] = len(self.table)
            self.table.append(answer)
        return index

    def to_json(self) -> dict[str, list]:
        """The page's ``answers``."""
        return {"at": self.at, "sets": self.sets, "table": self.table}


def export_data(
    views: list[RunView],
    diff: dict | None,
    report: str | None,
    limit: int = MAX_EXPORT_EVENTS,
) -> dict:
    """The data of an exported page (``ExportTooLarge`` past ``limit`` events a run)."""
    for view in views:
        if view.events > limit:
            raise ExportTooLarge(
                f"{view.run.info.file}: {view.events} events; an exported page holds at most "
                f"{limit} - open it with `btlog view` instead"
            )
    return {
        "runs": [run_data(view) for view in views],
        "diff": diff,
        "report": report,
        "patterns": question_patterns(),
        "questions": standard_questions(),
        "can_answer": " ".join(QUESTIONS.values()),
        "files": [view.run.info.file for view in views],
    }


def export_page(views: list[RunView], diff: dict | None = None, report: str | None = None) -> str:
    """The self-contained HTML of the viewer for ``views``."""
    title = "btlog view - " + " vs ".join(view.label for view in views)
    return page_html(export_data(views, diff, report), title)

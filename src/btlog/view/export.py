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

from btlog.explain.hierarchy import current_nodes
from btlog.explain.questions import QUESTIONS
from btlog.history import LiveHistory
from btlog.status import STATUS_NAMES, Status
from btlog.view.model import RunView, answers_json, question_patterns, standard_questions
from btlog.view.page import page_html

#: The most events an exported page holds (past it, the page would be too slow to open).
MAX_EXPORT_EVENTS = 200_000
_CODES = {name: code for code, name in enumerate(STATUS_NAMES)}
_KINDS = {"status": 0, "write": 1, "mutation": 2}


class ExportTooLarge(ValueError):
    """A recording with more events than an exported page holds."""


def run_data(view: RunView) -> dict[str, Any]:
    """One run of an exported page: its meta, every event as columns indexed by seq
    (``st``: the new status's code for a status change, the index into ``writes`` for a
    blackboard write), and the standard answers and current nodes after every event where
    they change (``answers.at``: counts, ascending; ``answers.sets``)."""
    run = view.run
    columns: dict[str, list] = {k: [] for k in ("t", "tick", "kind", "uid", "st", "prev")}
    writes: list[list] = []
    unset = _unset_seqs(view)
    mutations = {m.seq: m for m in run.mutations}
    projection = LiveHistory(run.tree)  # the state and the run's history so far
    changes: dict[str, list] = {"at": [], "sets": []}
    _record_answers(projection, 0, changes)
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
        _record_answers(projection, entry.seq + 1, changes)
    return {
        "meta": view.meta(),
        "events": {**columns, "writes": writes},
        "ticks": _ticks(view),
        "answers": changes,
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


def _record_answers(projection: LiveHistory, count: int, changes: dict[str, list]) -> None:
    """Append the answers after ``count`` events when they differ from the last ones."""
    tree, state = projection.tree, projection.state
    found = {
        "answers": answers_json(tree, state, projection),
        "current": [n.uid for n in current_nodes(tree, state)],
    }
    if not changes["sets"] or changes["sets"][-1] != found:
        changes["at"].append(count)
        changes["sets"].append(found)


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

"""What the viewer shows, as JSON, computed from the read model (``btlog.replay.database``).

One ``RunView`` per opened run answers the page's questions: the run and its nodes
(``meta``), the state at a moment (statuses, current nodes, blackboard with writers, the
answers to the standard questions), the events around a moment, the Gantt segments, a
step by tick, and any question (``answer``, the very function ``btlog ask`` calls).
A moment is any form ``--at`` takes, resolved by ``btlog.replay.moments`` as every other
command resolves it (the page shows its seq, tick and time, and the last event's time
apart); the page also names one by a *count*, the number of events applied (``seq:N`` is
count N + 1), or by a time since the start. Answers and the story read the run's history,
as ``btlog ask`` and ``btlog explain`` do.
"""

from __future__ import annotations

import re
from bisect import bisect_left
from typing import Any

import orjson

from btlog.checks.behaviours import diff_paths
from btlog.explain.divergence import to_json
from btlog.explain.hierarchy import current_nodes
from btlog.explain.questions import _PATTERNS, EXPLAIN_INTENTS, QUESTIONS, answer, explain
from btlog.explain.story import story
from btlog.history import History
from btlog.replay.database import Run, RunDatabase
from btlog.replay.moments import Resolved, before_start, time_moment
from btlog.state import State
from btlog.tree.model import Node, Tree

#: Events listed on each side of the moment.
EVENT_WINDOW = 40
_RANGE = "run_id = $run AND seq >= $lo AND seq < $hi"
_EVENTS_SQL = f"""
    SELECT seq, t_ns, tick, 'status', uid, prev_status::VARCHAR, status::VARCHAR,
           NULL, NULL, NULL FROM transitions WHERE {_RANGE}
    UNION ALL SELECT seq, t_ns, tick, 'write', writer_uid, NULL, NULL, scope, key,
           value::VARCHAR FROM blackboard WHERE {_RANGE}
    UNION ALL SELECT seq, t_ns, NULL, 'mutation', inserted_root_uid, NULL, NULL,
           NULL, NULL, NULL FROM mutations WHERE {_RANGE}
    ORDER BY seq"""
#: Time buckets of the Gantt: segments of one node and status starting in the same
#: bucket are drawn as one bar.
GANTT_BUCKETS = 1500


def node_json(node: Node) -> dict[str, Any]:
    """A node as the page draws it."""
    return {
        "uid": node.uid,
        "parent": None if node.parent is None else node.parent.uid,
        "kind": node.kind,
        "type": node.type,
        "name": node.name,
        "path": node.path,
        "scope": node.scope,
        "ports": {k: {"value": p.value, "dir": p.direction} for k, p in node.ports.items()},
        "added": node.added_seq,
    }


def question_patterns() -> list[list[str]]:
    """The question recogniser's (intent, regex) pairs in JavaScript syntax, so the
    exported page recognises the same paraphrases as ``btlog ask``."""
    return [[intent, re.sub(r"\(\?P<", "(?<", p.pattern)] for intent, p in _PATTERNS]


def answers_json(tree: Tree, state: State, history: History | None) -> list[dict[str, Any]]:
    """The standard answers (Q1-Q6) at a state, given the run's history."""
    return [a.to_json() for a in explain(tree, state, history)]


class RunView:
    """The viewer's queries on one run of a ``RunDatabase``."""

    def __init__(self, database: RunDatabase, run: Run, label: str) -> None:
        self.database = database
        self.run = run
        self.label = label
        self.tree = run.final_tree()
        self._writers: dict[tuple[str, str], tuple[list[int], list[int | None]]] | None = None

    @property
    def events(self) -> int:
        """How many events the run has."""
        return self.run.extent.events

    def meta(self) -> dict[str, Any]:
        """The run: label, extent, metadata and every node (of the final tree)."""
        info = self.run.info
        return {
            "label": self.label,
            "run_id": info.run_id,
            "file": info.file,
            "tree_name": info.tree_name,
            "final_status": info.final_status,
            "events": self.events,
            "duration_ns": self.run.extent.duration_ns,
            "last_tick": self.run.extent.last_tick,
            "started_at": None if info.started_at is None else info.started_at.isoformat(),
            "warnings": list(info.warnings),
            "nodes": [node_json(n) for n in self.tree],
            "root": self.tree.root.uid,
            "story": self.story(),
        }

    def story(self) -> dict[str, Any]:
        """The run's story (``btlog explain REC``'s content, its JSON as it is)."""
        tree, state = self.run.state_after(self.events)
        extent = self.run.extent
        told = story(
            tree,
            state,
            self.run.history(),
            duration_ns=extent.duration_ns,
            ticks=self.run.ticks_run(),
        )
        return told.to_json()

    def clamp(self, count: int) -> int:
        """``count`` within 0..events."""
        return max(0, min(self.events, count))

    def resolve(self, moment: str) -> Resolved:
        """A moment in any form ``--at`` takes (``seq:-1``: before the first event)."""
        if moment.strip() == "seq:-1":
            return before_start()
        return self.run.resolve(moment)

    def at_count(self, count: int) -> Resolved:
        """The moment right after the first ``count`` events (clamped to the run)."""
        count = self.clamp(count)
        return self.resolve(f"seq:{count - 1}")

    def at_time(self, t_ns: int) -> Resolved:
        """The moment at a time since the start (clamped to the run)."""
        return self.resolve(time_moment(max(0, min(self.run.extent.duration_ns, t_ns))))

    def state(self, moment: Resolved) -> dict[str, Any]:
        """Everything the page shows at a moment."""
        count = moment.count
        tree, state = self.run.state_after(count)
        current = [n.uid for n in current_nodes(tree, state)]
        return {
            "count": count,
            "moment": moment.to_json(),
            "t_ns": moment.t_ns,
            "tick": moment.tick,
            "status": {str(uid): s.name for uid, s in state.status.items() if s.name != "IDLE"},
            "present": sorted(tree.nodes),
            "current": current,
            "blackboard": self.blackboard(state, count),
            "answers": answers_json(tree, state, self.run.history()),
            "events": self.event_rows(count),
        }

    def _writes(self) -> dict[tuple[str, str], tuple[list[int], list[int | None]]]:
        """Every write's seq and writer per (scope, key), read once (seqs ascending)."""
        if self._writers is None:
            _cols, rows = self.database.sql(
                "SELECT scope, key, seq, writer_uid FROM blackboard WHERE run_id = $run "
                "ORDER BY seq",
                {"run": self.run.run_id},
            )
            writers: dict[tuple[str, str], tuple[list[int], list[int | None]]] = {}
            for scope, key, seq, writer in rows:
                seqs, uids = writers.setdefault((scope, key), ([], []))
                seqs.append(seq)
                uids.append(writer)
            self._writers = writers
        return self._writers

    def blackboard(self, state: State, count: int) -> list[dict[str, Any]]:
        """The blackboard at a state, each entry with its last writer and write seq."""
        writes = self._writes()
        entries = []
        for scope, values in sorted(state.blackboard.items()):
            for key, value in sorted(values.items()):
                seqs, uids = writes.get((scope, key), ([], []))
                last = bisect_left(seqs, count) - 1
                writer, seq = (uids[last], seqs[last]) if last >= 0 else (None, None)
                entries.append(
                    {"scope": scope, "key": key, "value": value, "writer": writer, "seq": seq}
                )
        return entries

    def event_rows(self, count: int, before: int = EVENT_WINDOW) -> dict[str, Any]:
        """The events around a moment: ``before`` events up to it and as many after
        (status changes, writes with the writer's uid, insertions with the inserted
        subtree's root)."""
        lo = max(0, self.clamp(count) - before)
        hi = min(self.events, self.clamp(count) + before)
        _cols, rows = self.database.sql(_EVENTS_SQL, {"run": self.run.run_id, "lo": lo, "hi": hi})
        keys = ("seq", "t_ns", "tick", "kind", "uid", "prev", "status", "scope", "key", "value")
        events = []
        for row in rows:
            event = dict(zip(keys, row, strict=True))
            event["value"] = None if event["value"] is None else orjson.loads(event["value"])
            events.append({k: v for k, v in event.items() if v is not None or k == "uid"})
        return {"lo": lo, "rows": events}

    def step_tick(self, moment: Resolved, direction: int) -> Resolved:
        """The end of the next (``direction`` 1) or previous (-1) tick, whether or not it
        has events (within the run's ticks)."""
        tick = max(0, min(self.run.extent.last_tick, moment.tick + direction))
        return self.resolve(f"tick:{tick}")

    def gantt(self, lo: int = 0, hi: int | None = None) -> dict[str, Any]:
        """The execution nodes' non-IDLE intervals that overlap the time window [lo, hi]
        (the whole run by default), columnar: uid, status, start, end."""
        duration = max(1, self.run.extent.duration_ns)
        hi = duration if hi is None else max(lo + 1, hi)
        _cols, rows = self.database.sql(
            """WITH t AS (
                 SELECT uid, t_ns, status,
                        lead(t_ns) OVER (PARTITION BY uid ORDER BY seq) AS t_end
                 FROM transitions WHERE run_id = $run AND uid IN (
                   SELECT uid FROM nodes WHERE run_id = $run
                   AND kind IN ('action', 'condition')))
               SELECT uid, status::VARCHAR, min(t_ns), max(coalesce(t_end, $dur))
               FROM t WHERE status <> 'IDLE' AND t_ns <= $hi AND coalesce(t_end, $dur) >= $lo
               GROUP BY uid, status, floor((t_ns - $lo) * $buckets / ($hi - $lo))
               ORDER BY 1, 3""",
            {
                "run": self.run.run_id,
                "dur": duration,
                "buckets": GANTT_BUCKETS,
                "lo": lo,
                "hi": hi,
            },
        )
        return {
            "uid": [r[0] for r in rows],
            "status": [r[1] for r in rows],
            "start": [r[2] for r in rows],
            "end": [r[3] for r in rows],
        }

    def ask(self, moment: Resolved, question: str) -> dict[str, Any]:
        """The answer ``btlog ask`` gives at this moment: the same ``answer`` with the
        run's history and the moment's time (an error message for questions it does not
        understand)."""
        tree, state = self.run.state_after(moment.count)
        try:
            return answer(tree, state, question, self.run.history(), moment.t_ns).to_json()
        except ValueError as error:
            return {"question": question, "intent": None, "answer": str(error), "nodes": []}


def standard_questions() -> list[list[str]]:
    """The standard questions, (intent, text), in the order ``explain`` asks them."""
    return [[intent, QUESTIONS[intent]] for intent in EXPLAIN_INTENTS]


def divergence_json(a: str, b: str) -> dict[str, Any]:
    """``btlog diff A B --json`` for the page's side-by-side view."""
    return to_json(diff_paths(a, b))

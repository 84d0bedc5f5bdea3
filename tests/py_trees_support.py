"""Helpers for the py_trees tests: a tick loop that keeps what the live tree and the
live recorder said after every tick, and the recording read back through the read model."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from btlog.explain.questions import NODE_INTENTS, QUESTIONS, answer
from btlog.replay.database import open_runs
from btlog.replay.sql_history import SqlHistory
from btlog.sources.py_trees import STATUS, PyTreesRecorder

PLAIN = [q for intent, q in QUESTIONS.items() if "X" not in q]
ABOUT_X = [q for intent, q in QUESTIONS.items() if intent in NODE_INTENTS]


def questions_about(names: list[str]) -> list[str]:
    """Every question, those about X asked about each of ``names``."""
    return PLAIN + [q.replace("X", name) for name in names for q in ABOUT_X]


@dataclass
class Seen:
    """After each tick: the live tree's statuses by uid, the last event's seq, and the
    live answers to the questions asked."""

    statuses: list[dict[int, Any]] = field(default_factory=list)
    seqs: list[int] = field(default_factory=list)
    answers: list[list[str]] = field(default_factory=list)


def live_statuses(root: Any, recorder: PyTreesRecorder) -> dict[int, Any]:
    """Every recorded behaviour's status now, as btlog's (INVALID as IDLE), by uid."""
    found = {}
    for behaviour in root.iterate():
        uid = recorder.watch.uid_of(behaviour)
        if uid is not None:
            found[uid] = STATUS[behaviour.status]
    return found


def tick_and_watch(
    tree: Any, recorder: PyTreesRecorder, ticks: int, asked: list[str], seen: Seen
) -> None:
    """Tick ``ticks`` times; after each, note what ``Seen`` keeps."""
    assert recorder.history is not None
    for _ in range(ticks):
        tree.tick()
        seen.statuses.append(live_statuses(tree.root, recorder))
        seen.seqs.append(recorder.builder.seq - 1)
        history = recorder.history
        seen.answers.append([answer(history.tree, history.state, q, history).text for q in asked])


def assert_replay_equals_live(path: Path, seen: Seen, asked: list[str]) -> None:
    """The state btlog replays at every tick is the live tree's, and the post-hoc answers
    at each tick's last event are the live ones."""
    database = open_runs(path, cache=False)
    try:
        run = database.run(str(path))
        history = SqlHistory(run, in_memory=True)
        for tick, statuses in enumerate(seen.statuses, start=1):
            _, state = run.state_at(f"tick:{tick}")
            replayed = {uid: state.status_of(uid) for uid in statuses}
            assert replayed == statuses, f"tick {tick}"
        for seq, expected in zip(seen.seqs, seen.answers, strict=True):
            if seq < 0:
                continue
            tree, state = run.state_at(f"seq:{seq}")
            assert [answer(tree, state, q, history).text for q in asked] == expected, seq
    finally:
        database.close()


class AssignmentSpy:
    """Every change of ``status`` in a tree, in the order py_trees makes it, seen at the
    assignment itself: each behaviour gets a subclass of its class (same name) whose
    ``status`` is a data descriptor noting ``(behaviour, old, new)`` when the value
    changes. What a recording of the tree must hold, change for change."""

    def __init__(self, root: Any) -> None:
        self.changes: list[tuple[Any, Any, Any]] = []
        spied: dict[type, type] = {}
        descriptor = _Noting(self.changes)
        for behaviour in root.iterate():
            cls = type(behaviour)
            if cls not in spied:
                spied[cls] = type(cls)(cls.__name__, (cls,), {"status": descriptor})
            status = behaviour.status
            behaviour.__class__ = spied[cls]
            behaviour.__dict__["status"] = status


class _Noting:
    """The ``status`` of a spied behaviour (reads find the instance's dict)."""

    def __init__(self, changes: list[tuple[Any, Any, Any]]) -> None:
        self.changes = changes

    def __set__(self, behaviour: Any, status: Any) -> None:
        slots = behaviour.__dict__
        old = slots.get("status", status)
        slots["status"] = status
        if old is not status:
            self.changes.append((behaviour, old, status))

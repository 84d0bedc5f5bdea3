"""Questions asked live (``btlog run --ask WHEN=QUESTION``), answered as post hoc.

WHEN is any moment that post-hoc ``--at`` accepts, parsed by the one moment parser
(``btlog.replay.moments``). While the run goes on, a question is answered at the tick
boundary where its moment is reached (``12.5s``, ``tick:N``, an ISO-8601 wall time;
``seq:N`` at the end of the tick holding event N), from the live state projection, with
the same code that answers post hoc; "Can you …?" then inserts the self-contained
subtree into the running tree and records the mutation. What the run never reached
(``end``, ``-2s``, a moment after the last tick) is resolved when the run is over, after
its teardown, against the run's own events exactly as the read model resolves it: the
state at the moment is folded from those events, and a moment outside the run is refused
with the message post-hoc ``btlog ask`` gives.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from btlog.events import Subscriber, TickRecord, TreeMutation
from btlog.executor.engine import Executor
from btlog.explain.questions import Answer, answer, parse_question
from btlog.history import LiveHistory
from btlog.record.recorder import Recorder
from btlog.replay.moments import (
    SEQ,
    TICK,
    TIME,
    WALL,
    Moment,
    MomentError,
    RunExtent,
    parse_moment,
    parse_started_at,
    resolve_moment,
    wall_offset_ns,
)
from btlog.state import State
from btlog.status import Status
from btlog.tree.model import Tree


class LiveQuestionError(ValueError):
    """A ``--ask`` that cannot be used; one line naming it."""


@dataclass(frozen=True)
class LiveQuestion:
    """``--ask WHEN=QUESTION``: the question and its parsed moment."""

    when: str
    question: str
    moment: Moment

    @classmethod
    def parse(cls, text: str) -> LiveQuestion:
        """Parse ``WHEN=QUESTION`` (LiveQuestionError naming the option if bad)."""
        when, sep, question = text.partition("=")
        when, question = when.strip(), question.strip()
        if not sep or not when or not question:
            raise LiveQuestionError(
                f"--ask {text!r}: expected WHEN=QUESTION, e.g. 12.5s=What are you doing?"
            )
        try:
            moment = parse_moment(when)
        except MomentError as error:
            raise LiveQuestionError(f"--ask {text!r}: {error}") from None
        parse_question(question)
        return cls(when, question, moment)

    def due(self, executor: Executor, next_tick_ns: int, started_at_ns: int | None) -> bool:
        """True when the state now (before the next tick) is the state at WHEN; moments
        counted from the end are never due while the run goes on."""
        return self.due_after(executor.runtime.tick, executor.seq, next_tick_ns, started_at_ns)

    def due_after(
        self, ticks: int, events: int, next_tick_ns: int, started_at_ns: int | None
    ) -> bool:
        """``due`` for any source: ``ticks`` ticks and ``events`` events are over, the
        next tick starts at ``next_tick_ns``."""
        kind, value = self.moment.kind, self.moment.value
        if kind == TICK:
            return ticks >= value
        if kind == SEQ:
            return events > value
        if kind == TIME:
            return next_tick_ns > value
        if kind == WALL and started_at_ns is not None:
            try:
                return next_tick_ns > wall_offset_ns(self.moment, started_at_ns)
            except MomentError:
                return False  # before the start: refused at the end, as post hoc
        return False


def moment_time(moment: Moment, state: State, started_at_ns: int | None, tick_end_ns: int) -> int:
    """The moment's time since the start, as post hoc resolves it: its own time, for
    ``tick:N`` the end of that tick (``tick_end_ns``: the live run's last tick is N), for
    ``seq:N`` the time of the last event applied."""
    if moment.kind == TIME:
        return moment.value
    if moment.kind == WALL:
        return wall_offset_ns(moment, started_at_ns)
    if moment.kind == TICK:
        return max(tick_end_ns, state.t_ns)
    return state.t_ns


class EventExtent(Subscriber):
    """The times and ticks of every event and the end of the last tick: what resolving
    a moment against the finished run needs."""

    def __init__(self) -> None:
        self.times: list[int] = []
        self.ticks: list[int] = []
        self.tick_records: list[tuple[int, int, int]] = []

    def on_status(
        self, seq: int, t_ns: int, tick: int, uid: int, prev: Status, status: Status
    ) -> None:
        """A status change: its time and tick."""
        self.times.append(t_ns)
        self.ticks.append(tick)

    def on_write(
        self,
        seq: int,
        t_ns: int,
        tick: int,
        scope: str,
        key: str,
        value: Any,
        type_name: str,
        writer_uid: int | None,
    ) -> None:
        """A blackboard write: its time and tick."""
        self.times.append(t_ns)
        self.ticks.append(tick)

    def on_mutation(self, mutation: TreeMutation) -> None:
        """A change of the tree: its time and tick."""
        self.times.append(mutation.t_ns)
        self.ticks.append(mutation.tick)

    def on_tick(self, record: TickRecord) -> None:
        """The end of a tick: its number, start and end."""
        self.tick_records.append((record.tick, record.start_ns, record.end_ns))

    @property
    def end_ns(self) -> int:
        """The end of the last tick so far (0 before the first)."""
        return self.tick_records[-1][2] if self.tick_records else 0


def at_the_end(
    question: LiveQuestion, extent: EventExtent, history: LiveHistory, started_at: str | None
) -> tuple[Tree, State, int]:
    """The tree, state and time of ``question``'s moment in a finished run, resolved
    against its events (``extent``, ``history``) as post hoc; ``MomentError`` for a moment
    outside the run."""
    run = RunExtent.from_events(extent.times, extent.ticks, extent.tick_records, started_at)
    resolved = resolve_moment(question.moment, run)
    if resolved.count == len(extent.times):
        return history.tree, history.state, resolved.t_ns
    tree, state = history.state_after(resolved.count)
    return tree, state, resolved.t_ns


class LiveQuestions(Subscriber):
    """Answers a run's live questions from a live state projection (see the module)."""

    def __init__(
        self,
        executor: Executor,
        questions: list[LiveQuestion],
        recorder: Recorder | None,
        on_answer: Callable[[LiveQuestion, Answer, int], None] | None,
        started_at: str | None = None,
    ) -> None:
        self.executor = executor
        self.pending = list(questions)
        self.recorder = recorder
        self.on_answer = on_answer
        self.started_at = started_at
        self.projection = LiveHistory(executor.tree)  # the state, and the past
        self.answered: list[tuple[LiveQuestion, Answer, int]] = []
        self.refused: list[str] = []
        self.extent = EventExtent()
        self._started_ns = parse_started_at(started_at)[0]
        executor.subscribe(self.projection)
        executor.subscribe(self.extent)

    def before_tick(self, executor: Executor) -> None:
        """Answer every question that is due before the next tick."""
        next_ns = executor.runtime.tick * executor.runtime.clock.period_ns
        if not executor.runtime.clock.simulated:
            next_ns = executor.runtime.clock.now_ns()
        for question in [q for q in self.pending if q.due(executor, next_ns, self._started_ns)]:
            self.pending.remove(question)
            state = self.projection.state
            at_ns = moment_time(question.moment, state, self._started_ns, self.extent.end_ns)
            self._answer(question, self.projection.tree, state, at_ns, running=True)

    def finish(self) -> None:
        """Answer what is left now that the run is over (call after its teardown):
        each moment resolved against the run's events as post hoc; moments outside the
        run are refused (``refused`` holds the one-line reasons)."""
        for question in list(self.pending):
            self.pending.remove(question)
            try:
                tree, state, at_ns = at_the_end(
                    question, self.extent, self.projection, self.started_at
                )
            except MomentError as error:
                self.refused.append(f"--ask {question.when}={question.question!r}: {error}")
                continue
            self._answer(question, tree, state, at_ns, running=False)

    def _answer(
        self, question: LiveQuestion, tree: Tree, state: State, at_ns: int, running: bool
    ) -> None:
        """Answer from ``(tree, state)`` at time ``at_ns``, as post hoc; while running, a
        "Can you …?" with a plan changes the running tree (once over, it only answers)."""
        result = answer(tree, state, question.question, self.projection, at_ns)
        seq = state.seq
        tick = self.executor.runtime.tick if seq == self.executor.seq else state.tick
        if running and result.insertion is not None:
            plan = result.insertion
            self.executor.insert_after(
                plan.parent.uid,
                plan.after.uid,
                self.executor.tree.node(plan.source.uid),
                question.question,
            )
        if self.recorder is not None:
            self.recorder.on_answer(
                seq, state.t_ns, tick, question.question, result.intent, result.text
            )
        self.answered.append((question, result, seq))
        if self.on_answer is not None:
            self.on_answer(question, result, seq)

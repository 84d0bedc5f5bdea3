"""Questions asked live about a run that is being imported as it happens (``attach --ask``).

The same ``--ask WHEN=QUESTION`` as ``btlog run``, answered with the same ``answer``
from a ``StateProjection`` fed by the builder, once WHEN is reached: a time since the
start (the publisher's clock), ``tick:N`` (once tick N is over) or ``seq:N`` (once event N
is in). Each answer is printed and recorded on ``/btlog/answers``. The tree of a remote
process cannot change: "Can you X?" is answered without inserting anything.
"""

from __future__ import annotations

from collections.abc import Callable

from btlog.explain.questions import Answer, answer
from btlog.live_questions import LiveQuestion
from btlog.replay.moments import SEQ, TICK, TIME
from btlog.sources.attach import AttachHooks
from btlog.sources.builder import RecordingBuilder
from btlog.state import StateProjection


class LiveAnswers(AttachHooks):
    """Answers ``questions`` when due, from a projection of the builder's events."""

    def __init__(
        self, questions: list[LiveQuestion], on_answer: Callable[[LiveQuestion, Answer], None]
    ) -> None:
        self.projection: StateProjection | None = None
        self.pending = list(questions)
        self.on_answer = on_answer

    def on_start(self, builder: RecordingBuilder) -> None:
        """Follow the builder's events from the first."""
        self.projection = StateProjection(builder.tree)
        builder.subscribe(self.projection)

    def on_poll(self, builder: RecordingBuilder, t_ns: int) -> None:
        """Answer every question that is due now."""
        self.poll(builder, t_ns)

    def before_close(self, builder: RecordingBuilder) -> None:
        """Answer what is left."""
        self.finish(builder)

    def due(self, question: LiveQuestion, builder: RecordingBuilder, t_ns: int) -> bool:
        """True once the moment WHEN is in the past."""
        kind, value = question.moment.kind, question.moment.value
        if kind == TICK:
            return builder.tick > value
        if kind == SEQ:
            return builder.seq > value
        return kind == TIME and t_ns > value  # end, -2s, wall times: at the end

    def poll(self, builder: RecordingBuilder, t_ns: int) -> None:
        """Answer every question that is due now."""
        for question in [q for q in self.pending if self.due(q, builder, t_ns)]:
            self.pending.remove(question)
            self.ask(question, builder)

    def finish(self, builder: RecordingBuilder) -> None:
        """Answer what is left at the end."""
        for question in list(self.pending):
            self.pending.remove(question)
            self.ask(question, builder)

    def ask(self, question: LiveQuestion, builder: RecordingBuilder) -> Answer:
        """Answer now from the state so far, and record the answer."""
        if self.projection is None:
            raise RuntimeError("LiveAnswers.ask before on_start")
        state = self.projection.state
        result = answer(self.projection.tree, state, question.question)
        builder.recorder.on_answer(
            builder.seq, state.t_ns, builder.tick, question.question, result.intent, result.text
        )
        self.on_answer(question, result)
        return result

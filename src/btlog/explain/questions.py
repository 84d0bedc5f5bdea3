"""Questions in, answers out: one entry point for live and post-hoc explanations.

``answer(tree, state, question, history)`` recognises the question (case-insensitive,
the paper's phrasings and common paraphrases), finds the current node(s) in ``state``
and runs the paper's algorithm, or one of the history questions (``btlog.explain.causes``,
``flow``, ``recall``). It is a pure function of (tree, state, history): the executor's
live view (``LiveHistory``) and a recording's read model (``SqlHistory``) pass their own
(equal) states and histories to the same code. Without a history, the questions about
the past answer from the moment alone (Q6 is then Algorithm 7 only).

With several running nodes (under a Parallel) each gets an answer; distinct answers are
joined with " and ".
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from btlog.explain.causes import last_completion, what_went_wrong_over_history
from btlog.explain.flow import entry, next_sentence
from btlog.explain.hierarchy import (
    current_nodes,
    doing,
    goal,
    how,
    per_node,
    subgoal,
    subgoal_node,
    why,
)
from btlog.explain.insertion import InsertionPlan, find_requested, plan_insertion
from btlog.explain.recall import about, find_nodes, how_long, when_last, why_failed, why_not
from btlog.explain.words import act, goal_words, words
from btlog.history import History
from btlog.state import State
from btlog.tree.model import Node, Tree

QUESTIONS = {
    "doing": "What are you doing?",
    "why": "Why are you doing this?",
    "subgoal": "What is your subgoal?",
    "goal": "What is your goal?",
    "how_subgoal": "How do you achieve your subgoal?",
    "how_goal": "How do you achieve your goal?",
    "wrong": "What went wrong?",
    "can": "Can you X?",
    "next": "What will you do next?",
    "why_failed": "Why did X fail?",
    "why_not": "Why didn't you X?",
    "when_fail": "When did X last fail?",
    "when_succeed": "When did X last succeed?",
    "when_start": "When did X last start?",
    "how_long": "How long did X take?",
}
#: The event that decides which of several same-named nodes a question is about.
_EVENT_OF = {
    "why_failed": "fail",
    "why_not": "fail",
    "when_fail": "fail",
    "when_succeed": "succeed",
    "when_start": "start",
    "how_long": "start",
}
#: Questions about one node X (``{X}`` in the templates).
NODE_INTENTS = ("why_failed", "why_not", "when_fail", "when_succeed", "when_start", "how_long")
#: The questions of ``explain`` (Q1–Q6), in order.
EXPLAIN_INTENTS = ("doing", "why", "subgoal", "goal", "how_subgoal", "how_goal", "wrong")

_YOU = r"(?:you|u)"
_PATTERNS: list[tuple[str, re.Pattern]] = [
    (intent, re.compile(p))
    for intent, p in [
        ("next", rf"^what (?:will|are|r) {_YOU} (?:do|doing|going to do|gonna do) next$"),
        ("next", r"^what(?: is|'s|s)? (?:next|coming next|your next step)$"),
        ("next", rf"^what (?:comes|happens|do {_YOU} do) next$"),
        ("why_not", rf"^why (?:didn't|didnt|did not|haven't|havent|have not) {_YOU} (?P<what>.+)$"),
        ("why_not", rf"^why did {_YOU} not (?P<what>.+)$"),
        ("why_failed", rf"^why did {_YOU} fail (?:to )?(?P<what>.+)$"),
        ("why_failed", r"^why (?:did|has|have) (?P<what>.+?) (?:fail|failed|not succeed)$"),
        ("when_fail", r"^when did (?P<what>.+?) (?:last fail|fail last|fail)$"),
        ("when_succeed", r"^when did (?P<what>.+?) (?:last succeed|succeed last|succeed)$"),
        ("when_start", rf"^when did {_YOU} last (?P<what>.+)$"),
        (
            "when_start",
            r"^when (?:did|was) (?P<what>.+?) (?:last start|start last|start|last run|last "
            r"started|started|begin|last begin)$",
        ),
        ("how_long", r"^how long (?:did|has|does) (?P<what>.+?) (?:take|taken|run|been running)$"),
        (
            "how_long",
            rf"^how long did (?:it take (?:{_YOU} )?to|{_YOU} take to|{_YOU}) (?P<what>.+)$",
        ),
        ("can", rf"^(?:can|could|will|would) {_YOU} (?:please )?(?P<what>.+)$"),
        ("doing", rf"^what (?:are|r) {_YOU} (?:doing|up to)(?: now| right now)?$"),
        ("doing", r"^what is (?:happening|going on)(?: now)?$"),
        ("doing", rf"^what do {_YOU} do(?: now)?$"),
        ("why", rf"^why(?: (?:are|do) {_YOU} (?:doing|do) (?:this|that|it))?(?: now)?$"),
        ("why", rf"^why (?:are|r) {_YOU} .+$"),
        (
            "how_subgoal",
            rf"^how (?:do|will|can|are) {_YOU} (?:going to )?(?:achieve|accomplish|reach|"
            rf"do) (?:your |the |this )?(?:sub ?goal|sub-goal|it)$",
        ),
        (
            "how_goal",
            rf"^how (?:do|will|can|are) {_YOU} (?:going to )?(?:achieve|accomplish|reach|"
            rf"do) (?:your |the )?(?:overall |main |final )?goal$",
        ),
        ("subgoal", r"^what(?: is|'s|s) (?:your|the)(?: current)? (?:sub ?goal|sub-goal)$"),
        ("goal", r"^what(?: is|'s|s) (?:your|the)(?: overall| main| final)? goal$"),
        ("wrong", r"^what went wrong$"),
        ("wrong", r"^(?:was|is) (?:there )?(?:anything|something) wrong$"),
        ("wrong", r"^how (?:was|is|were) (?:the )?failures? handled$"),
        ("wrong", r"^(?:did )?(?:anything|something) (?:go )?wrong$"),
        ("wrong", r"^what (?:failed|is wrong|was wrong)$"),
    ]
]


class UnknownQuestion(ValueError):
    """A question btlog does not understand; the message is the paper's reply."""

    def __init__(self, question: str) -> None:
        self.question = question
        listed = " ".join(QUESTIONS.values())
        super().__init__(f'Sorry. I don\'t understand "{question}". I can answer: {listed}')


@dataclass(frozen=True)
class Answer:
    """An answer with what it was about: the intent, the node(s) and, for "Can you X?",
    the insertion plan."""

    question: str
    intent: str
    text: str
    nodes: tuple[int, ...] = ()
    insertion: InsertionPlan | None = field(default=None, compare=False)
    #: False when the question names a node the tree does not have (the answer says so).
    known: bool = True

    def to_json(self) -> dict:
        """JSON-ready form (``--json``)."""
        data: dict[str, Any] = {
            "question": self.question,
            "intent": self.intent,
            "answer": self.text,
            "nodes": list(self.nodes),
        }
        if not self.known:
            data["known"] = False
        if self.insertion is not None:
            data["insertion"] = self.insertion.to_json()
        return data


def normalise(question: str) -> str:
    """Lower-case, single spaces, no trailing punctuation."""
    text = " ".join(question.strip().lower().replace("’", "'").split())
    return text.rstrip("?!. ")


def parse_question(question: str) -> tuple[str, str | None]:
    """The intent of a question and, for "Can you X?", X; UnknownQuestion otherwise."""
    text = normalise(question)
    for intent, pattern in _PATTERNS:
        match = pattern.match(text)
        if match:
            return intent, match.groupdict().get("what")
    raise UnknownQuestion(question.strip())


def answer(
    tree: Tree,
    state: State,
    question: str,
    history: History | None = None,
    at_ns: int | None = None,
) -> Answer:
    """Answer ``question`` about the moment ``state`` of a run of ``tree``, whose past
    up to that moment ``history`` holds; ``at_ns`` is the moment's time when it is later
    than the last event's (durations of running nodes are measured to it)."""
    intent, argument = parse_question(question)
    return _answer_intent(tree, state, question, intent, argument, history, at_ns)


def _answer_intent(
    tree: Tree,
    state: State,
    question: str,
    intent: str,
    argument: str | None,
    history: History | None,
    at_ns: int | None = None,
) -> Answer:
    """``answer`` once the question is recognised as ``intent`` (and ``argument``)."""
    if intent in NODE_INTENTS:
        now_ns = state.t_ns if at_ns is None else max(at_ns, state.t_ns)
        return _about_node(tree, state, history, question, intent, argument or "", now_ns)
    nodes = current_nodes(tree, state)
    uids = tuple(n.uid for n in nodes)
    if intent == "doing":
        text = per_node(nodes, doing, "I am not doing anything.")
    elif intent == "why":
        text = per_node(nodes, lambda n: why(n, tree), "I am not doing anything.")
    elif intent == "subgoal":
        text = per_node(nodes, subgoal, "Sorry. I don't have a subgoal.")
    elif intent == "goal":
        text = goal(tree)
    elif intent == "how_subgoal":
        text = per_node(nodes, lambda n: _how_subgoal(tree, n), "Sorry. I don't have a subgoal.")
    elif intent == "how_goal":
        text = tree.shaped(("how", "goal"), lambda: how(tree.root, "goal", tree))
    elif intent == "wrong":
        text = what_went_wrong_over_history(tree, state, history)
    elif intent == "next":
        text = _next(tree, state, history, nodes)
    else:
        return _can(tree, nodes, question, argument or "")
    return Answer(question, intent, text, uids)


def _how_subgoal(tree: Tree, node: Node) -> str:
    """Q5 for the subgoal of ``node``, once per subgoal and shape of the tree."""
    target = subgoal_node(node)
    key = ("how", "subgoal", None if target is None else target.uid)
    return tree.shaped(key, lambda: how(target, "subgoal"))


def _next(tree: Tree, state: State, history: History | None, nodes: list[Node]) -> str:
    """``What will you do next?`` for each current node."""
    if history is not None and last_completion(tree.root, state, history) is not None:
        return f"I have finished {goal_words(tree)}."
    if not nodes:
        first = dict.fromkeys(act(n) for n in entry(tree.root, state))
        return f"I will {' and '.join(first)} first."
    return per_node(nodes, lambda n: next_sentence(tree, n, state, history), "")


def _about_node(
    tree: Tree,
    state: State,
    history: History | None,
    question: str,
    intent: str,
    what: str,
    now_ns: int,
) -> Answer:
    """The questions about one node X."""
    nodes = find_nodes(tree, what)
    if not nodes:
        return _unknown(question, intent, what)
    if history is None:
        from btlog.history import LiveHistory

        history = LiveHistory(tree)  # no past known: an empty history
    node = about(nodes, _EVENT_OF.get(intent), state, history)
    if intent == "why_failed":
        text = why_failed(tree, node, state, history)
    elif intent == "why_not":
        text = why_not(tree, node, state, history)
    elif intent == "how_long":
        text = how_long(node, state, history, now_ns)
    else:
        text = when_last(node, intent.removeprefix("when_"), state, history)
    return Answer(question, intent, text, (node.uid,))


def _unknown(question: str, intent: str, what: str) -> Answer:
    """The answer to a question about a node the tree does not have."""
    return Answer(question, intent, f'Sorry. I don\'t know "{what.strip()}".', known=False)


def _can(tree: Tree, nodes: list[Node], question: str, wanted: str) -> Answer:
    wanted = wanted.strip()
    if find_requested(tree, wanted) is None:
        return _unknown(question, "can", wanted)
    plan = plan_insertion(tree, nodes[0] if nodes else None, wanted)
    if plan is None:
        return Answer(
            question, "can", f'Sorry. I cannot redo "{wanted}".', tuple(n.uid for n in nodes)
        )
    text = f"Yes. I will {words(plan.requested)} after {words(plan.after)}."
    return Answer(question, "can", text, (plan.source.uid,), plan)


def explain(tree: Tree, state: State, history: History | None = None) -> list[Answer]:
    """Q1–Q6 together."""
    return [
        _answer_intent(tree, state, QUESTIONS[intent], intent, None, history)
        for intent in EXPLAIN_INTENTS
    ]

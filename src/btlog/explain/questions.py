"""Questions in, answers out: one entry point for live and post-hoc explanations.

``answer(tree, state, question)`` recognises the question (case-insensitive, the paper's
phrasings and common paraphrases), finds the current node(s) in ``state`` and runs the
paper's algorithm. It is a pure function of (tree, state): the executor's live view and
a replay from a recording pass their own (equal) states to the same code.

With several running nodes (under a Parallel) each gets an answer; distinct answers are
joined with " and ".
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

from btlog.explain.failure import what_went_wrong
from btlog.explain.hierarchy import current_nodes, doing, goal, how, subgoal, subgoal_node, why
from btlog.explain.insertion import InsertionPlan, plan_insertion
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
}
#: The questions of ``explain`` (Q1–Q6), in order.
EXPLAIN_INTENTS = ("doing", "why", "subgoal", "goal", "how_subgoal", "how_goal", "wrong")

_YOU = r"(?:you|u)"
_PATTERNS: list[tuple[str, re.Pattern]] = [
    (intent, re.compile(p))
    for intent, p in [
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

    def to_json(self) -> dict:
        """JSON-ready form (``--json``)."""
        data = {
            "question": self.question,
            "intent": self.intent,
            "answer": self.text,
            "nodes": list(self.nodes),
        }
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


def _join(texts: list[str]) -> str:
    distinct = list(dict.fromkeys(texts))
    if len(distinct) == 1:
        return distinct[0]
    return " and ".join(t.rstrip(".") for t in distinct[:-1]) + " and " + distinct[-1]


def _per_node(nodes: list[Node], render: Callable[[Node], str], empty: str) -> str:
    return _join([render(n) for n in nodes]) if nodes else empty


def answer(tree: Tree, state: State, question: str) -> Answer:
    """Answer ``question`` about the moment ``state`` of a run of ``tree``."""
    intent, argument = parse_question(question)
    nodes = current_nodes(tree, state)
    uids = tuple(n.uid for n in nodes)
    if intent == "doing":
        text = _per_node(nodes, doing, "I am not doing anything.")
    elif intent == "why":
        text = _per_node(nodes, why, "I am not doing anything.")
    elif intent == "subgoal":
        text = _per_node(nodes, subgoal, "Sorry. I don't have a subgoal.")
    elif intent == "goal":
        text = goal(tree)
    elif intent == "how_subgoal":
        text = _per_node(
            nodes, lambda n: how(subgoal_node(n), "subgoal"), "Sorry. I don't have a subgoal."
        )
    elif intent == "how_goal":
        text = how(tree.root, "goal")
    elif intent == "wrong":
        text = _per_node(nodes, lambda n: what_went_wrong(n, state), "Nothing went wrong.")
    else:
        return _can(tree, nodes, question, argument or "")
    return Answer(question, intent, text, uids)


def _can(tree: Tree, nodes: list[Node], question: str, wanted: str) -> Answer:
    wanted = wanted.strip()
    plan = plan_insertion(tree, nodes[0] if nodes else None, wanted)
    if plan is None:
        return Answer(
            question, "can", f'Sorry. I cannot redo "{wanted}".', tuple(n.uid for n in nodes)
        )
    text = f"Yes. I will {plan.requested.description} after {plan.after.description}."
    return Answer(question, "can", text, (plan.source.uid,), plan)


def explain(tree: Tree, state: State) -> list[Answer]:
    """Q1–Q6 together."""
    return [answer(tree, state, QUESTIONS[intent]) for intent in EXPLAIN_INTENTS]

"""The renderers on their own: terminal lines, the HTML page and the divergence report,
given a real tree and the real state of a run (no CLI in between)."""

from __future__ import annotations

import copy
from html.parser import HTMLParser

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.executor.engine import Executor
from btlog.explain.divergence import ExecutedAction, diverge
from btlog.explain.hierarchy import current_nodes
from btlog.explain.questions import answer
from btlog.render.divergence import render_lines
from btlog.render.html import page
from btlog.render.terminal import blackboard_lines, format_ns, tree_lines
from btlog.state import State, StateProjection
from btlog.tree.loader import load_tree_text
from btlog.tree.model import Tree

XML = """<root BTCPP_format="4">
  <BehaviorTree ID="Main">
    <Sequence name="make &lt;tea&gt;">
      <Script code="cups := 2"/>
      <Action ID="boil" name="boil water"/>
      <Action ID="pour" name="pour"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


@pytest.fixture(scope="module")
def moment() -> tuple[Tree, State]:
    """The tree and state after two ticks: the Script ran, "boil water" is RUNNING (taken
    before the executor's teardown resets every node)."""
    tree = load_tree_text(XML)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 3}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    projection = StateProjection(tree)
    executor.subscribe(projection)
    try:
        executor.tick()
        executor.tick()
        return copy.deepcopy((projection.tree, projection.state))
    finally:
        executor.close()


def test_tree_lines_draw_one_line_per_node_with_status_and_current(moment) -> None:
    tree, state = moment
    current = [n.uid for n in current_nodes(tree, state)]
    lines = [line.plain for line in tree_lines(tree, state, current)]
    assert len(lines) == len(tree)
    assert lines[0].startswith("make <tea>  Sequence  #1  RUNNING")
    assert lines[1].startswith("├── Script  #2  SUCCESS")
    assert lines[2] == "├── boil water  boil  #3  RUNNING  ◀ current"
    assert lines[3] == "└── pour  #4  IDLE"


def test_tree_lines_without_a_state_show_every_node_idle(moment) -> None:
    tree, _ = moment
    assert all(line.plain.endswith("IDLE") for line in tree_lines(tree, None))


def test_blackboard_lines_name_the_scope_and_show_json(moment) -> None:
    _, state = moment
    lines = [line.plain for line in blackboard_lines(state)]
    assert lines == ["[(root)]", "  cups = 2"]


def test_format_ns_gives_seconds_to_the_millisecond() -> None:
    assert format_ns(0) == "0.000s"
    assert format_ns(1_234_000_000) == "1.234s"
    assert format_ns(12_000_000_000) == "12.000s"


class _Collector(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.text: list[str] = []
        self.current = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        self.current += ("class", "current") in attrs

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def test_html_page_escapes_names_and_marks_the_current_node(moment) -> None:
    tree, state = moment
    current = [n.uid for n in current_nodes(tree, state)]
    answers = [answer(tree, state, "What are you doing?")]
    document = page("tea <run>", tree, state, current, answers)
    assert "<tea>" not in document and "&lt;tea&gt;" in document
    parsed = _Collector()
    parsed.feed(document)
    text = "".join(parsed.text)
    assert parsed.tags.count("li") == len(tree)
    assert parsed.current == 1
    assert "tea <run>" in text and "I boil water." in text and "cups" in text


def _action(description: str, seq: int) -> ExecutedAction:
    return ExecutedAction(seq, seq, description, "T", "action", "steps", 1, "goal")


def test_divergence_lines_mark_divergent_rows_and_summarise() -> None:
    a = [_action("pick", 1), _action("place", 2)]
    b = [_action("pick", 1), _action("scan", 2), _action("place", 3)]
    lines = render_lines(diverge(a, b, "run A", "run B"))
    kinds = [kind for _, kind in lines]
    texts = [text for text, _ in lines]
    assert kinds[:2] == ["title", "title"] and kinds[-1] == "summary"
    divergent = [text for text, kind in lines if kind == "divergent"]
    assert len(divergent) == 1 and divergent[0].lstrip().startswith("!")
    assert "scan  (in steps)" in divergent[0]
    assert 'subgoal "goal": edit distance 1, LCS length 2 (2 vs 3 actions)' in texts
    assert texts[-1] == "total edit distance 1: 1 of 1 subgoal diverge"

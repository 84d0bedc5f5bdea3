"""The run's story: what a user reads first after a run (``btlog explain REC``).

Top down: the outcome, duration and ticks; each failure episode in time order — when,
what Q6 said at that moment, and how the failure was handled (retried, attempt k of n;
fell back to another child; or propagated up to the goal); then each subgoal with its
result, duration and attempts. A pure function of (tree, state, history) like the
answers, built from history queries only.

An *episode* is one execution node's failure as the failure handlers above it
(``btlog.explain.handlers``) saw it: each handler whose child failed because of it
reacted once, innermost first. Consecutive episodes that read the same (same sentence,
same handling) are told once with a count, and at most ``MAX_EPISODES`` failures are
looked at, so a long run with a few failures fits one screen and a run failing all the
time still says how often.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from btlog.explain.causes import activation_start, algorithm7, cause, root_failure, seconds
from btlog.explain.failure import NOTHING_WRONG
from btlog.explain.handlers import FELL_BACK, PROPAGATED, Reaction, handler_of
from btlog.explain.hierarchy import steps
from btlog.history import ANY_STATUS, COMPLETIONS, History, Transition
from btlog.state import State
from btlog.status import FAILURE
from btlog.tree.model import SUBTREE, Node, Tree

#: Handled failures looked at (the rest are counted).
MAX_EPISODES = 200
#: Above this many episodes, those that read the same are told once.
SCREEN = 12


@dataclass
class Episode:
    """A failure and how it was handled; ``count`` consecutive ones read the same."""

    seq: int
    t_ns: int
    leaf: str
    sentence: str
    handling: list[str]
    count: int = 1
    last_t_ns: int = 0

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {
            "seq": self.seq,
            "t_ns": self.t_ns,
            "last_t_ns": self.last_t_ns,
            "count": self.count,
            "leaf": self.leaf,
            "what_went_wrong": self.sentence,
            "handling": self.handling,
        }


@dataclass
class Subgoal:
    """One subgoal: how often it started, its last result and the time it took."""

    name: str
    depth: int
    attempts: int
    result: str | None
    first_ns: int | None
    last_ns: int | None
    last_start_ns: int | None = None

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {
            "subgoal": self.name,
            "depth": self.depth,
            "attempts": self.attempts,
            "result": self.result,
            "start_ns": self.first_ns,
            "end_ns": self.last_ns,
            "last_attempt_start_ns": self.last_start_ns,
        }

    def text(self) -> str:
        """E.g. ``go pick screw: SUCCESS in 19.600 s (43.700 s to 63.300 s)``."""
        result = self.result or ("not started" if not self.attempts else "not finished")
        text = f"{'  ' * self.depth}{self.name}: {result}"
        if self.first_ns is not None and self.last_ns is not None:
            text += (
                f" in {seconds(self.last_ns - self.first_ns)} s"
                f" ({seconds(self.first_ns)} s to {seconds(self.last_ns)} s)"
            )
        if self.attempts > 1:
            text += f", {self.attempts} attempts"
            if self.last_start_ns is not None and self.last_ns is not None:
                text += f", the last in {seconds(self.last_ns - self.last_start_ns)} s"
        return text


@dataclass
class Story:
    """The whole run, told top down."""

    goal: str
    outcome: str
    why: str | None
    duration_ns: int
    ticks: int
    events: int
    failures: int
    episodes: list[Episode] = field(default_factory=list)
    subgoals: list[Subgoal] = field(default_factory=list)

    def to_json(self) -> dict:
        """JSON-ready form (``btlog explain REC --json``)."""
        return {
            "goal": self.goal,
            "outcome": self.outcome,
            "why": self.why,
            "duration_ns": self.duration_ns,
            "ticks": self.ticks,
            "events": self.events,
            "handled_failures": self.failures,
            "episodes": [e.to_json() for e in self.episodes],
            "subgoals": [s.to_json() for s in self.subgoals],
        }

    def lines(self) -> list[str]:
        """The story as plain text lines."""
        out = [
            f"Goal: {self.goal}. Outcome: {self.outcome} after {seconds(self.duration_ns)} s, "
            f"{self.ticks} ticks, {self.events} events."
        ]
        if self.why:
            out.append(self.why)
        told = sum(e.count for e in self.episodes)
        out.append(f"Failures: {told}." if told else "No failures.")
        for episode in self.episodes:
            when = f"{seconds(episode.t_ns)} s"
            if episode.count > 1:
                when += f" … {seconds(episode.last_t_ns)} s, {episode.count} times"
            out.append(f"  {when}: {episode.sentence}")
            out.append(f"    {'; '.join(episode.handling)}.")
        if self.failures > MAX_EPISODES:
            out.append(
                f"  {self.failures} failures were handled in all; the first {MAX_EPISODES} "
                "are told."
            )
        if self.subgoals:
            out.append("Subgoals:")
        out += [f"  {sub.text()}" for sub in self.subgoals]
        return out


def _subgoals(tree: Tree) -> list[Node]:
    """The SubTree nodes; the goal's steps (Algorithm 5) when the tree has none."""
    found = [n for n in tree if n.kind == SUBTREE]
    return found or steps(tree.root)


def _subgoal(node: Node, now: int, history: History) -> Subgoal:
    starts = history.count([node.uid], ANY_STATUS, 0, now, starts=True)
    first = history.first([node.uid], ANY_STATUS, 0, now, starts=True)
    done = history.last([node.uid], COMPLETIONS, 0, now)
    last_start = (
        None if done is None else history.last([node.uid], ANY_STATUS, 0, done.seq, starts=True)
    )
    depth = sum(1 for a in node.ancestors() if a.kind == SUBTREE)
    return Subgoal(
        node.description,
        depth,
        starts,
        None if done is None else done.status.name,
        None if first is None else first.t_ns,
        None if done is None else done.t_ns,
        None if last_start is None else last_start.t_ns,
    )


def _reaction(tree: Tree, failed: Transition, history: History) -> Reaction | None:
    child = tree.nodes.get(failed.uid)
    parent = child.parent if child is not None else None
    rule = handler_of(parent) if parent is not None else None
    if child is None or parent is None or rule is None:
        return None
    since = activation_start(parent, failed.seq + 1, history)
    failures = history.count([child.uid], (FAILURE,), since, failed.seq + 1)
    return rule.react(parent, child, failures)


def _sentence(tree: Tree, failed: Transition, leaf: Node, history: History) -> str:
    """Q6 right after the handler saw the failure; the cause when Algorithm 7 is silent."""
    then_tree, then = history.state_after(failed.seq + 1)
    text = algorithm7(then_tree, then)
    if text != NOTHING_WRONG:
        return text
    node = tree.node(failed.uid)
    return f"I could not {node.description} because {leaf.description} failed."


def _episodes(tree: Tree, state: State, history: History) -> tuple[list[Episode], int]:
    """The episodes, and how many handled failures the run had."""
    now = state.seq
    handled = [c.uid for n in tree if handler_of(n) is not None for c in n.children]
    failures = history.count(handled, (FAILURE,), 0, now)
    by_leaf: dict[int, Episode] = {}
    # (handler, its activation) -> (the child it fell back to, the episode)
    fell_back: dict[tuple[int, int], tuple[int, Episode]] = {}
    episodes: list[Episode] = []
    for failed in history.transitions(handled, (FAILURE,), 0, now, MAX_EPISODES):
        leaf_done = cause(tree, tree.node(failed.uid), failed, history)
        parent = tree.node(failed.uid).parent
        assert parent is not None
        key = (parent.uid, activation_start(parent, failed.seq + 1, history))
        episode = by_leaf.get(leaf_done.seq)
        if episode is None and key in fell_back and fell_back[key][0] == failed.uid:
            episode = fell_back[key][1]  # the alternative failed too: the same episode
        if episode is None:
            leaf = tree.node(leaf_done.uid)
            sentence = _sentence(tree, failed, leaf, history)
            episode = Episode(leaf_done.seq, leaf_done.t_ns, leaf.description, sentence, [])
            episodes.append(episode)
        by_leaf[leaf_done.seq] = episode
        reaction = _reaction(tree, failed, history)
        if reaction is not None:
            episode.handling.append(reaction.text())
            if reaction.kind == FELL_BACK and reaction.target is not None:
                fell_back[key] = (reaction.target.uid, episode)
    root_done = history.last([tree.root.uid], COMPLETIONS, 0, now)
    if root_done is not None and root_done.status is FAILURE:
        leaf_done = cause(tree, tree.root, root_done, history)
        episode = by_leaf.get(leaf_done.seq)
        if episode is None:
            sentence = root_failure(tree, state, history) or ""
            described = tree.node(leaf_done.uid).description
            episode = Episode(leaf_done.seq, leaf_done.t_ns, described, sentence, [])
            episodes.append(episode)
            failures += 1
        episode.handling.append(f"{PROPAGATED} to {tree.root.description}: the run failed")
    return _grouped(episodes), failures


def _grouped(episodes: list[Episode]) -> list[Episode]:
    """Episodes in time order; those that read the same (same sentence, same handling)
    told once with a count — consecutive ones, or all of them when there are more than
    ``SCREEN`` kinds, so that a run failing often still fits a screen."""
    ordered = sorted(episodes, key=lambda e: e.seq)
    for episode in ordered:
        episode.last_t_ns = episode.t_ns
        episode.handling = episode.handling or [PROPAGATED]
    grouped: list[Episode] = []
    for episode in ordered:
        previous = grouped[-1] if grouped else None
        if previous is not None and _same(previous, episode):
            _merge(previous, episode)
        else:
            grouped.append(episode)
    if len(grouped) <= SCREEN:
        return grouped
    kinds: dict[tuple[str, tuple[str, ...]], Episode] = {}
    for episode in grouped:
        key = (episode.sentence, tuple(episode.handling))
        if key in kinds:
            _merge(kinds[key], episode)
        else:
            kinds[key] = episode
    return list(kinds.values())


def _same(a: Episode, b: Episode) -> bool:
    return a.sentence == b.sentence and a.handling == b.handling


def _merge(into: Episode, episode: Episode) -> None:
    into.count += episode.count
    into.last_t_ns = max(into.last_t_ns, episode.last_t_ns)


def story(tree: Tree, state: State, history: History) -> Story:
    """The story of the run up to ``state`` (its end, for ``btlog explain REC``)."""
    now = state.seq
    root_done = history.last([tree.root.uid], COMPLETIONS, 0, now)
    outcome = "not finished" if root_done is None else root_done.status.name
    why = root_failure(tree, state, history) if outcome == FAILURE.name else None
    episodes, failures = _episodes(tree, state, history)
    return Story(
        goal=tree.root.description,
        outcome=outcome,
        why=why,
        duration_ns=state.t_ns,
        ticks=state.tick,
        events=state.seq,
        failures=failures,
        episodes=episodes,
        subgoals=[_subgoal(n, now, history) for n in _subgoals(tree)],
    )

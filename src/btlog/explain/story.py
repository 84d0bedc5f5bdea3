"""The run's story: what a user reads first after a run (``btlog explain REC``).

Top down: the goal and how the run ended — its **outcome** is the run's final status,
the root's status after its last tick (``not finished (RUNNING)`` for a run that was
stopped, cut short or is ticked in a loop); when the root ran more than once (a tree
ticked in a loop, re-run after each completion) each **run of the goal** is told on its
own line, or counted by result when there are many; then each failure **episode** in time
order — when, what Q6 said about it, and how it was handled (retried, attempt k of n;
fell back to another child; or propagated up to the goal); then each **subgoal**
(``btlog.explain.hierarchy.subgoals``) with its result, duration and runs (activations)
in the last run of the goal. The **gaps** in the data come first when there are any
(times a source gave no data: ``btlog attach``'s publisher fell silent or restarted; the
writes of ``btlog.events.GAP_SCOPE`` in the state). A pure function of (tree, state,
history) like the answers, built from history queries only.

An *episode* is one execution node's real failure as the failure handlers above it
(``btlog.explain.handlers``) saw it: each handler whose child failed because of it
reacted once, innermost first. A guard's failure (a condition failing in front of the
branch it guards: the tree choosing a branch; ``btlog.explain.failure``) is no episode:
the story counts guards apart. The sentence is Q6 at the moment the innermost handler
saw the failure, asked of the failed leaf itself, with the leaf's grounds. Consecutive
episodes that read the same (same sentence, same handling) are told once with a count
when there are many, and at most ``MAX_EPISODES`` episodes (of at most ``MAX_EXAMINED``
handled failures) are looked at, so a long run with a few failures fits one screen and
a run failing all the time still says how often.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

from btlog.events import GAP_SCOPE, Gap, gaps_in
from btlog.explain.causes import (
    actions_below,
    activation_start,
    because,
    by_guard,
    cause,
    episode_sentence,
    root_failure,
)
from btlog.explain.handlers import FELL_BACK, PROPAGATED, Reaction, handler_of
from btlog.explain.hierarchy import subgoals
from btlog.explain.words import goal_words, is_named, seconds, words
from btlog.history import (
    ANY_STATUS,
    COMPLETIONS,
    History,
    Transition,
    TransitionIndex,
    activation_end,
)
from btlog.state import State
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS
from btlog.tree.model import SUBTREE, Node, Tree

#: Episodes looked at (the rest are counted).
MAX_EPISODES = 200
#: Handled failures examined for episodes (guards included), read this many at a time.
MAX_EXAMINED = 20_000
PAGE = 500
#: Events before each failure of a page that its episode, guard and cause are read
#: from (``History.read_ahead``: a hint; what lies further back is asked for).
NEIGHBOURHOOD = 1024
#: Above this many episodes (or runs of the goal), those that read the same are told once.
SCREEN = 12
#: The root's changes per run of the goal read at once (a start, a result, a reset, a
#: halt: fewer in all but odd runs; beyond, each end is asked for).
OWN_CHANGES = 4


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
    """One subgoal in the last run of the goal: how often it ran (its activations: a
    retry, a replanning or a loop runs it again; *attempts* are the paper's retries,
    told by the episodes), its last result and the time it took."""

    name: str
    depth: int
    runs: int
    result: str | None
    first_ns: int | None
    last_ns: int | None
    last_start_ns: int | None = None

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {
            "subgoal": self.name,
            "depth": self.depth,
            "runs": self.runs,
            "result": self.result,
            "start_ns": self.first_ns,
            "end_ns": self.last_ns,
            "last_run_start_ns": self.last_start_ns,
        }

    def text(self) -> str:
        """E.g. ``go pick screw: SUCCESS in 19.600 s (43.700 s to 63.300 s)``; one that
        ran more than once: ``grasp cup: SUCCESS, 3 runs (1.500 s to 3.000 s), the last
        in 0.500 s``."""
        result = self.result or ("not started" if not self.runs else "not finished")
        text = f"{'  ' * self.depth}{self.name}: {result}"
        if self.first_ns is None or self.last_ns is None:
            return text
        span = f"({seconds(self.first_ns)} s to {seconds(self.last_ns)} s)"
        if self.runs <= 1 or self.last_start_ns is None:
            return f"{text} in {seconds(self.last_ns - self.first_ns)} s {span}"
        last = seconds(self.last_ns - self.last_start_ns)
        return f"{text}, {self.runs} runs {span}, the last in {last} s"


@dataclass
class GoalRun:
    """One run of the goal (an activation of the root): its result, or None while it
    runs or after it was halted."""

    start_ns: int
    end_ns: int | None
    result: str | None

    def to_json(self) -> dict:
        """JSON-ready form."""
        return {"start_ns": self.start_ns, "end_ns": self.end_ns, "result": self.result}

    def text(self) -> str:
        """E.g. ``SUCCESS in 10.000 s (0.000 s to 10.000 s)``."""
        if self.end_ns is None:
            return f"running since {seconds(self.start_ns)} s"
        span = f"({seconds(self.start_ns)} s to {seconds(self.end_ns)} s)"
        return f"{self.result or 'halted'} in {seconds(self.end_ns - self.start_ns)} s {span}"


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
    runs: list[GoalRun] = field(default_factory=list)
    guards: int = 0
    examined_all: bool = True
    gaps: list[Gap] = field(default_factory=list)

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
            "guard_failures": self.guards,
            "examined_all_failures": self.examined_all,
            "goal_runs": [r.to_json() for r in self.runs],
            "episodes": [e.to_json() for e in self.episodes],
            "subgoals": [s.to_json() for s in self.subgoals],
            "gaps": [g.to_json() for g in self.gaps],
        }

    def lines(self) -> list[str]:
        """The story as plain text lines."""
        out = [
            f"Goal: {self.goal}. Outcome: {self.outcome} after {seconds(self.duration_ns)} s, "
            f"{self.ticks} ticks, {self.events} events."
        ]
        if self.why:
            out.append(self.why)
        if self.gaps:
            out.append(f"Gaps in the data: {len(self.gaps)}.")
            for gap in self.gaps[:SCREEN]:
                span = f"{seconds(gap.from_ns)} s to {seconds(gap.to_ns)} s"
                out.append(f"  No data from {span}: {gap.why}.")
            if len(self.gaps) > SCREEN:
                out.append(f"  … and {len(self.gaps) - SCREEN} more.")
        if len(self.runs) > 1:
            out.append(f"The goal ran {len(self.runs)} times:")
            out += [f"  {line}" for line in _runs_told(self.runs)]
        told = sum(e.count for e in self.episodes)
        out.append(f"Failures: {told}." if told else "No failures.")
        for episode in self.episodes:
            when = f"{seconds(episode.t_ns)} s"
            if episode.count > 1:
                when += f" … {seconds(episode.last_t_ns)} s, {episode.count} times"
            out.append(f"  {when}: {episode.sentence}")
            out.append(f"    {'; '.join(episode.handling)}.")
        if self.failures > MAX_EPISODES or not self.examined_all:
            more = "at least " if not self.examined_all else ""
            out.append(
                f"  {more}{self.failures} failures were handled in all; the first "
                f"{MAX_EPISODES} are told."
            )
        if self.guards:
            failures = "failure" if self.guards == 1 else "failures"
            out.append(f"  ({self.guards} {failures} by design chose another branch.)")
        if self.subgoals:
            last = " (in the goal's last run)" if len(self.runs) > 1 else ""
            out.append(f"Subgoals{last}:")
        out += [f"  {sub.text()}" for sub in self.subgoals]
        return out


def _runs_told(runs: list[GoalRun]) -> list[str]:
    """Each run of the goal, numbered; counted by result when there are many."""
    if len(runs) <= SCREEN:
        return [f"{i}. {run.text()}" for i, run in enumerate(runs, 1)]
    counts: dict[str, int] = {}
    for run in runs[:-1]:
        key = run.result or "halted"
        counts[key] = counts.get(key, 0) + 1
    summary = ", ".join(f"{n} {result}" for result, n in counts.items())
    return [f"1–{len(runs) - 1}. {summary}", f"{len(runs)}. {runs[-1].text()}"]


def _outcome(status: str) -> str:
    """The outcome as the story says it: the final status, or that the run never
    completed (``not finished (RUNNING)``), or never started."""
    if status in ("SUCCESS", "FAILURE"):
        return status
    return "not started" if status == IDLE.name else f"not finished ({status})"


def final_status(tree: Tree, state: State, history: History) -> str:
    """The run's final status: the root's status after its last tick (its last change
    other than a reset to IDLE), IDLE when it never ran."""
    statuses = (RUNNING, *COMPLETIONS)
    last = history.last([tree.root.uid], statuses, 0, state.seq)
    return IDLE.name if last is None else last.status.name


def goal_runs(tree: Tree, state: State, history: History, limit: int = 10_000) -> list[GoalRun]:
    """Every run of the goal (at most ``limit``): each activation of the root."""
    root, now = tree.root.uid, state.seq
    starts = history.transitions([root], ANY_STATUS, 0, now, limit, starts=True)
    # the root's own changes before its last start, read at once: the end of every run
    # but the last is found among them (``activation_end`` asks only about the root)
    before = starts[-1].seq if starts else 0
    own = TransitionIndex()
    changes = history.transitions([root], ANY_STATUS, 0, before, OWN_CHANGES * limit)
    for change in changes:
        own.add(change)
    read = changes[-1].seq if len(changes) == OWN_CHANGES * limit else before
    runs = []
    for index, start in enumerate(starts):
        hi = starts[index + 1].seq if index + 1 < len(starts) else now
        end = activation_end(own if hi <= read else history, start, hi)
        if end is None:
            runs.append(GoalRun(start.t_ns, None, None))
        else:
            result = end.status.name if end.status in COMPLETIONS else None
            runs.append(GoalRun(start.t_ns, end.t_ns, result))
    return runs


def _subgoal(node: Node, lo: int, now: int, history: History, starts: int) -> Subgoal:
    """The subgoal ``node`` in events ``lo <= seq < now``, which it started ``starts``
    times."""
    first = history.first([node.uid], ANY_STATUS, lo, now, starts=True)
    done = history.last([node.uid], COMPLETIONS, lo, now)
    last_start = (
        None if done is None else history.last([node.uid], ANY_STATUS, lo, done.seq, starts=True)
    )
    depth = sum(1 for a in node.ancestors() if a.kind == SUBTREE and is_named(a))
    return Subgoal(
        words(node),
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


class _Failures:
    """The handled failures that may be episodes: failures of a failure handler's
    children, guards' left out (counted), read in pages, each with whether it was made
    from a success (by design: an episode only as the alternative a handler fell back to
    in one, e.g. a ForceFailure clean-up; else counted with the guards)."""

    def __init__(self, tree: Tree, now: int, history: History) -> None:
        self.tree, self.now, self.history = tree, now, history
        handled = [c for n in tree if handler_of(n) is not None for c in n.children]
        self.guards = history.count(
            [c.uid for c in handled if not actions_below(c)], (FAILURE,), 0, now
        )
        self.uids = [c.uid for c in handled if actions_below(c)]
        # what the questions about their failures are about: each such child, what is
        # below it (the cause, a guard's actions) and its handler (the reaction)
        self.asked = {
            n.uid for c in handled if actions_below(c) for n in (c.parent, *c.walk()) if n
        }
        self.examined_all = True

    def __iter__(self) -> Iterator[tuple[Transition, bool]]:
        try:
            yield from self._pages()
        finally:
            self.history.read_ahead([])  # what was read ahead for the last page goes

    def _pages(self) -> Iterator[tuple[Transition, bool]]:
        lo, examined = 0, 0
        while lo < self.now:
            page = self.history.transitions(self.uids, (FAILURE,), lo, self.now, PAGE)
            spans = [(f.seq - NEIGHBOURHOOD, f.seq + 1) for f in page]
            self.history.read_ahead(spans, self.asked)
            for failed in page:
                examined += 1
                if examined > MAX_EXAMINED:
                    self.examined_all = False
                    return
                node = self.tree.node(failed.uid)
                if by_guard(self.tree, node, failed, self.history):
                    self.guards += 1
                else:
                    made = cause(self.tree, node, failed, self.history).status is SUCCESS
                    yield failed, made
            if len(page) < PAGE:
                return
            lo = page[-1].seq + 1


def _episodes(tree: Tree, state: State, history: History) -> tuple[list[Episode], int, _Failures]:
    """The episodes, how many real handled failures the run had, and what was read."""
    now = state.seq
    by_leaf: dict[int, Episode] = {}
    # (handler, its activation) -> (the child it fell back to, the episode)
    fell_back: dict[tuple[int, int], tuple[int, Episode]] = {}
    episodes: list[Episode] = []
    failures = 0
    found = _Failures(tree, now, history)
    for failed, made in found:
        if len(by_leaf) >= MAX_EPISODES and failed.seq not in by_leaf:
            failures += 1
            continue
        leaf_done = cause(tree, tree.node(failed.uid), failed, history)
        parent = tree.node(failed.uid).parent
        assert parent is not None
        key = (parent.uid, activation_start(parent, failed.seq + 1, history))
        episode = by_leaf.get(leaf_done.seq)
        if episode is None and key in fell_back and fell_back[key][0] == failed.uid:
            episode = fell_back[key][1]  # the alternative failed too: the same episode
        if episode is None and made:  # by design, and no episode's alternative
            found.guards += 1
            continue
        failures += 1
        if episode is None:
            if len(episodes) >= MAX_EPISODES:
                continue
            leaf = tree.node(leaf_done.uid)
            sentence = episode_sentence(tree, failed, leaf, history)
            episode = Episode(leaf_done.seq, leaf_done.t_ns, words(leaf), sentence, [])
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
            sentence = _root_sentence(tree, root_done, history)
            described = words(tree.node(leaf_done.uid))
            episode = Episode(leaf_done.seq, leaf_done.t_ns, described, sentence, [])
            episodes.append(episode)
            failures += 1
        episode.handling.append(f"{PROPAGATED} to {goal_words(tree)}: the run failed")
    return _grouped(episodes), failures, found


def _root_sentence(tree: Tree, root_done: Transition, history: History) -> str:
    return f"I could not {goal_words(tree)} because {because(tree, tree.root, root_done, history)}."


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


def story(
    tree: Tree,
    state: State,
    history: History,
    *,
    duration_ns: int | None = None,
    ticks: int | None = None,
) -> Story:
    """The story of the run up to ``state`` (its end, for ``btlog explain REC``);
    ``duration_ns`` and ``ticks`` are the run's own extent when it went on past its last
    event (ticks in which nothing changed: a run cut short, or stopped while waiting),
    and the ticks it ran, its teardown not counted, as ``btlog run`` and ``btlog
    recover`` count them."""
    now = state.seq
    status = final_status(tree, state, history)
    outcome = _outcome(status)
    why = root_failure(tree, state, history) if status == FAILURE.name else None
    runs = goal_runs(tree, state, history)
    since = 0
    if len(runs) > 1:
        last_start = history.last([tree.root.uid], ANY_STATUS, 0, now, starts=True)
        since = 0 if last_start is None else last_start.seq
    episodes, failures, found = _episodes(tree, state, history)
    goals = subgoals(tree)
    runs_of = history.counts([n.uid for n in goals], ANY_STATUS, since, now, starts=True)
    return Story(
        goal=goal_words(tree),
        outcome=outcome,
        why=why,
        duration_ns=max(state.t_ns, duration_ns or 0),
        ticks=state.tick if ticks is None else ticks,
        events=state.seq,
        failures=failures,
        episodes=episodes,
        subgoals=[_subgoal(n, since, now, history, runs_of[n.uid]) for n in goals],
        runs=runs,
        guards=found.guards,
        examined_all=found.examined_all,
        gaps=gaps_in(state.blackboard.get(GAP_SCOPE, {})),
    )

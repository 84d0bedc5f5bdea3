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
when there are many. A run with more episodes than fit a screen (more than ``SCREEN``
entries, or ``MAX_EPISODES`` episodes) is told by *kind* of episode — its failed leaf's
subgoal could not be done because the leaf failed —, the ``KINDS`` most frequent first,
the rest counted. Every number is exact: each of the first ``MAX_EXAMINED`` handled
failures is in an episode or by design, those past them are counted as not examined
(the totals then say "at least"), and the runs of the goal are counted in full.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace

from btlog.events import GAP_SCOPE, Gap, gaps_in
from btlog.explain.causes import (
    actions_below,
    activation_start,
    because,
    by_guard,
    cause,
    could_not,
    episode_sentence,
    root_failure,
)
from btlog.explain.handlers import FELL_BACK, PROPAGATED, RETRIED, Reaction, handler_of
from btlog.explain.hierarchy import subgoal_of, subgoals
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

#: Episodes whose sentences are read to tell them in time order (more are told by kind).
MAX_EPISODES = 200
#: Handled failures examined for episodes (guards included), read this many at a time.
MAX_EXAMINED = 20_000
PAGE = 500
#: Events before each failure of a page that its episode, guard and cause are read
#: from (``History.read_ahead``: a hint; what lies further back is asked for).
NEIGHBOURHOOD = 1024
#: Events at each end of the goal's last run that the subgoals' first start, last
#: completion and last start are read from at once (``History.read_ahead``; what lies
#: further in is asked for): three questions a subgoal, answered from memory.
SUBGOAL_ENDS = 1 << 12
#: Above this many episodes (or runs of the goal), those that read the same are told once.
SCREEN = 12
#: The root's changes per run of the goal read at once (a start, a result, a reset, a
#: halt: fewer in all but odd runs; beyond, each end is asked for).
OWN_CHANGES = 4
#: Kinds of failure episode listed when they are told by kind (the rest are counted).
KINDS = 10
#: Subgoals listed (those that did not succeed first; the rest are counted).
SUBGOALS = 24
#: Ways a kind of episode was handled, listed (the rest are counted).
WAYS = 3


@dataclass
class Episode:
    """A failure and how it was handled; ``count`` episodes read the same (or, in a
    summary by kind, are of the same kind: the failed leaf ``leaf_uid`` and its
    subgoal). ``at_seq``: the event after which ``btlog explain --at seq:N`` asks about
    the first; ``handled``: the handled failures of the episodes."""

    seq: int
    t_ns: int
    leaf: str
    sentence: str
    handling: list[str]
    count: int = 1
    last_t_ns: int = 0
    leaf_uid: int = 0
    at_seq: int = 0
    handled: int = 0
    failed: Transition | None = None
    way: list[str] = field(default_factory=list)
    ways: dict[str, int] = field(default_factory=dict)

    def to_json(self) -> dict:
        """JSON-ready form."""
        told = {
            "seq": self.seq,
            "t_ns": self.t_ns,
            "last_t_ns": self.last_t_ns,
            "count": self.count,
            "leaf": self.leaf,
            "what_went_wrong": self.sentence,
            "handling": self.handling,
        }
        if self.ways:
            told["handled_so"] = self.ways
        return told

    def text(self) -> list[str]:
        """Two lines: when and what went wrong, and how it was handled."""
        if self.ways:
            when = f"{self.count} {'time' if self.count == 1 else 'times'}, "
            when += f"{seconds(self.t_ns)} s … {seconds(self.last_t_ns)} s (--at seq:{self.at_seq})"
            ways = sorted(self.ways.items(), key=lambda w: -w[1])
            told = [f"{n}× {way}" for way, n in ways[:WAYS]]
            if len(ways) > WAYS:
                rest = sum(n for _, n in ways[WAYS:])
                told.append(f"{rest}× otherwise")
            return [f"  {when}: {self.sentence}", f"    {'; '.join(told)}."]
        when = f"{seconds(self.t_ns)} s"
        if self.count > 1:
            when += f" … {seconds(self.last_t_ns)} s, {self.count} times"
        return [f"  {when}: {self.sentence}", f"    {'; '.join(self.handling)}."]


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

    @property
    def told_result(self) -> str:
        """Its last result, ``not finished`` or ``not started``."""
        return self.result or ("not started" if not self.runs else "not finished")

    def text(self) -> str:
        """E.g. ``go pick screw: SUCCESS in 19.600 s (43.700 s to 63.300 s)``; one that
        ran more than once: ``grasp cup: SUCCESS, 3 runs (1.500 s to 3.000 s), the last
        in 0.500 s``."""
        text = f"{'  ' * self.depth}{self.name}: {self.told_result}"
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
class Failures:
    """The run's failures as the story counts them, every number exact over the handled
    failures examined (``examined_all``: all of them; else the first ``MAX_EXAMINED``, up
    to ``until_ns``): ``episodes`` (the run's failure episodes; ``listed``, those told),
    ``kinds`` (0 when the episodes are told in time order), the ``handled`` failures of
    failure handlers' children in the whole run, of which ``in_episodes`` belong to
    episodes, ``by_design`` were by design and ``not_examined`` were not looked at."""

    episodes: int = 0
    listed: list[Episode] = field(default_factory=list)
    kinds: int = 0
    handled: int = 0
    in_episodes: int = 0
    by_design: int = 0
    not_examined: int = 0
    until_ns: int = 0
    other_seq: int = 0

    @property
    def examined_all(self) -> bool:
        """Whether every handled failure was examined."""
        return self.not_examined == 0

    def lines(self) -> list[str]:
        """The failures told: the episodes in time order, or their most frequent kinds."""
        more = "" if self.examined_all else "at least "
        if self.kinds:
            listed = sum(e.count for e in self.listed)
            kinds = f"of {more}one kind" if self.kinds == 1 else f"of {more}{self.kinds} kinds"
            order = "" if self.kinds == 1 else ", the most frequent first"
            out = [
                f"Failures: {more}{self.episodes}, {kinds}{order} "
                "(btlog explain --at seq:N tells one):"
            ]
        else:
            out = [f"Failures: {more}{self.episodes}." if self.episodes or more else "No failures."]
        for episode in self.listed:
            out += episode.text()
        if self.kinds > len(self.listed):
            others = self.kinds - len(self.listed)
            out.append(
                f"  … and {others} other kinds of failure ({self.episodes - listed} episodes): "
                f"btlog explain --at seq:{self.other_seq} tells the first of the most frequent."
            )
        if not self.examined_all:
            out.append(
                f"  {self.not_examined} more handled failures after {seconds(self.until_ns)} s "
                f"were not examined (the first {MAX_EXAMINED} are)."
            )
        if self.by_design:
            failures = "failure" if self.by_design == 1 else "failures"
            out.append(f"  ({more}{self.by_design} {failures} by design chose another branch.)")
        return out


@dataclass
class Story:
    """The whole run, told top down."""

    goal: str
    outcome: str
    why: str | None
    duration_ns: int
    ticks: int
    events: int
    failures: Failures
    subgoals: list[Subgoal] = field(default_factory=list)
    runs: list[GoalRun] = field(default_factory=list)
    run_count: int = 0
    run_results: dict[str, int] = field(default_factory=dict)
    gaps: list[Gap] = field(default_factory=list)

    @property
    def episodes(self) -> list[Episode]:
        """The episodes told (kinds of them in a summary)."""
        return self.failures.listed

    def to_json(self) -> dict:
        """JSON-ready form (``btlog explain REC --json``)."""
        found = self.failures
        return {
            "goal": self.goal,
            "outcome": self.outcome,
            "why": self.why,
            "duration_ns": self.duration_ns,
            "ticks": self.ticks,
            "events": self.events,
            "failure_episodes": found.episodes,
            "failure_kinds": found.kinds,
            "handled_failures": found.handled,
            "handled_failures_in_episodes": found.in_episodes,
            "guard_failures": found.by_design,
            "handled_failures_not_examined": found.not_examined,
            "examined_all_failures": found.examined_all,
            "goal_run_count": self.run_count,
            "goal_run_results": self.run_results,
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
        if self.run_count > 1:
            out.append(f"The goal ran {self.run_count} times:")
            out += [f"  {line}" for line in _runs_told(self.runs, self.run_count, self.run_results)]
        out += self.failures.lines()
        if self.subgoals:
            last = " (in the goal's last run)" if self.run_count > 1 else ""
            out.append(f"Subgoals{last}:")
        out += _subgoals_told(self.subgoals)
        return out


def _subgoals_told(told: list[Subgoal]) -> list[str]:
    """Each subgoal in tree order; of more than ``SUBGOALS``, those that did not succeed
    chosen first, and the rest counted by result."""
    if len(told) <= SUBGOALS:
        return [f"  {sub.text()}" for sub in told]
    chosen = sorted(range(len(told)), key=lambda i: (told[i].result == SUCCESS.name, i))
    shown, rest = sorted(chosen[:SUBGOALS]), chosen[SUBGOALS:]
    results: dict[str, int] = {}
    for index in rest:
        results[told[index].told_result] = results.get(told[index].told_result, 0) + 1
    summary = ", ".join(f"{n} {result}" for result, n in results.items())
    return [f"  {told[i].text()}" for i in shown] + [
        f"  … and {len(rest)} more subgoals ({summary})."
    ]


def _runs_told(runs: list[GoalRun], count: int, results: dict[str, int]) -> list[str]:
    """Each run of the goal, numbered; when there are many, those before the last counted
    by result (``results``) and the last told."""
    if count <= SCREEN:
        return [f"{i}. {run.text()}" for i, run in enumerate(runs, 1)]
    summary = ", ".join(f"{n} {result}" for result, n in results.items())
    return [f"1–{count - 1}. {summary}", f"{count}. {runs[-1].text()}"]


def run_results(tree: Tree, history: History, runs: list[GoalRun], count: int, now: int) -> dict:
    """How the runs of the goal before the last ended, exactly: counted from the listed
    ``runs`` when they are all of them (``count``), else from the root's completions
    before its last start (each run ends in at most one; the others were halted)."""
    told: dict[str, int] = {}
    if len(runs) == count:
        for run in runs[:-1]:
            told[run.result or "halted"] = told.get(run.result or "halted", 0) + 1
    else:
        root = tree.root.uid
        last = history.last([root], ANY_STATUS, 0, now, starts=True)
        before = 0 if last is None else last.seq
        told = {s.name: history.count([root], (s,), 0, before) for s in COMPLETIONS}
        told["halted"] = count - 1 - sum(told.values())
    return {result: n for result, n in sorted(told.items(), key=lambda r: -r[1]) if n}


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
    """The runs of the goal (each activation of the root): every one when there are at
    most ``limit``, else the first ``limit - 1`` and the last."""
    root, now = tree.root.uid, state.seq
    starts = history.transitions([root], ANY_STATUS, 0, now, limit, starts=True)
    if len(starts) == limit:
        last = history.last([root], ANY_STATUS, 0, now, starts=True)
        if last is not None and last.seq != starts[-1].seq:
            starts[-1] = last
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
        self.of_guards = history.count(
            [c.uid for c in handled if not actions_below(c)], (FAILURE,), 0, now
        )
        self.guards = self.of_guards
        self.uids = [c.uid for c in handled if actions_below(c)]
        # what the questions about their failures are about: each such child, what is
        # below it (the cause, a guard's actions) and its handler (the reaction)
        self.asked = {
            n.uid for c in handled if actions_below(c) for n in (c.parent, *c.walk()) if n
        }
        self.examined, self.until_ns, self.not_examined = 0, 0, 0

    @property
    def handled(self) -> int:
        """The handled failures of the whole run (examined or not)."""
        return self.of_guards + self.examined + self.not_examined

    def __iter__(self) -> Iterator[tuple[Transition, bool]]:
        try:
            yield from self._pages()
        finally:
            self.history.read_ahead([])  # what was read ahead for the last page goes

    def _pages(self) -> Iterator[tuple[Transition, bool]]:
        lo = 0
        while lo < self.now:
            page = self.history.transitions(self.uids, (FAILURE,), lo, self.now, PAGE)
            spans = [(f.seq - NEIGHBOURHOOD, f.seq + 1) for f in page]
            self.history.read_ahead(spans, self.asked)
            for failed in page:
                if self.examined == MAX_EXAMINED:
                    rest = self.history.count(self.uids, (FAILURE,), failed.seq, self.now)
                    self.not_examined = rest
                    return
                self.examined += 1
                self.until_ns = failed.t_ns
                node = self.tree.node(failed.uid)
                if by_guard(self.tree, node, failed, self.history):
                    self.guards += 1
                else:
                    made = cause(self.tree, node, failed, self.history).status is SUCCESS
                    yield failed, made
            if len(page) < PAGE:
                return
            lo = page[-1].seq + 1


def _episodes(tree: Tree, state: State, history: History) -> tuple[list[Episode], _Failures]:
    """Every episode of the handled failures examined (time order, no sentence yet), and
    what was examined."""
    now = state.seq
    by_leaf: dict[int, Episode] = {}
    # (handler, its activation) -> (the child it fell back to, the episode)
    fell_back: dict[tuple[int, int], tuple[int, Episode]] = {}
    episodes: list[Episode] = []
    found = _Failures(tree, now, history)
    for failed, made in found:
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
        if episode is None:
            leaf = tree.node(leaf_done.uid)
            episode = Episode(
                leaf_done.seq, leaf_done.t_ns, words(leaf), "", [], leaf_uid=leaf.uid, failed=failed
            )
            episode.at_seq = failed.seq
            episodes.append(episode)
        episode.handled += 1
        by_leaf[leaf_done.seq] = episode
        reaction = _reaction(tree, failed, history)
        if reaction is not None:
            episode.handling.append(reaction.text())
            episode.way.append("retried" if reaction.kind == RETRIED else reaction.text())
            if reaction.kind == FELL_BACK and reaction.target is not None:
                fell_back[key] = (reaction.target.uid, episode)
    root_done = history.last([tree.root.uid], COMPLETIONS, 0, now)
    if root_done is not None and root_done.status is FAILURE:
        leaf_done = cause(tree, tree.root, root_done, history)
        episode = by_leaf.get(leaf_done.seq)
        if episode is None:
            sentence = _root_sentence(tree, root_done, history)
            leaf = tree.node(leaf_done.uid)
            episode = Episode(
                leaf_done.seq, leaf_done.t_ns, words(leaf), sentence, [], leaf_uid=leaf.uid
            )
            episode.at_seq = root_done.seq
            episodes.append(episode)
        episode.handling.append(f"{PROPAGATED} to {goal_words(tree)}: the run failed")
        episode.way.append("the run failed")
    ordered = sorted(episodes, key=lambda e: e.seq)
    for episode in ordered:
        episode.last_t_ns = episode.t_ns
        episode.handling = episode.handling or [PROPAGATED]
    return ordered, found


def _root_sentence(tree: Tree, root_done: Transition, history: History) -> str:
    return f"I could not {goal_words(tree)} because {because(tree, tree.root, root_done, history)}."


def _told(tree: Tree, history: History, episodes: list[Episode]) -> tuple[list[Episode], int, int]:
    """The episodes told, their kinds (0 when told in time order) and where the first of
    the most frequent kind not told happened (0 if none): in time order,
    those that read the same (same sentence, same handling) told once with a count, when
    that fits a screen (``SCREEN`` entries of at most ``MAX_EPISODES`` episodes); else the
    ``KINDS`` most frequent kinds of episode (the node that could not be done and the
    failed leaf), each with its first and last time and how often it was handled each
    way, the rest counted."""
    if len(episodes) <= MAX_EPISODES:
        for episode in episodes:
            if episode.failed is not None:
                leaf = tree.node(episode.leaf_uid)
                episode.sentence = episode_sentence(tree, episode.failed, leaf, history)
        grouped = _grouped([replace(e, ways={}) for e in episodes])
        if len(grouped) <= SCREEN:
            return grouped, 0, 0
    kinds: dict[str, Episode] = {}
    for episode in episodes:
        way = ", ".join(episode.way or episode.handling)
        sentence = _kind_sentence(tree, tree.node(episode.leaf_uid))
        kind = kinds.get(sentence)
        if kind is None:
            kind = kinds[sentence] = replace(episode, sentence=sentence, handling=[], ways={})
        else:
            _merge(kind, episode)
        kind.ways[way] = kind.ways.get(way, 0) + 1
    ordered = sorted(kinds.values(), key=lambda k: (-k.count, k.seq))
    shown = ordered if len(ordered) <= KINDS + 1 else ordered[:KINDS]
    return shown, len(ordered), (ordered[len(shown)].at_seq if len(ordered) > len(shown) else 0)


def _kind_sentence(tree: Tree, leaf: Node) -> str:
    """What a kind of episode reads: the failed leaf's subgoal (as the subgoals are told)
    could not be done because the leaf failed."""
    node = subgoal_of(leaf, tree)
    if node is not tree.root and words(node) == words(leaf):
        return f"I could not {words(leaf)}."
    return could_not(tree, node, leaf)


def _grouped(episodes: list[Episode]) -> list[Episode]:
    """Episodes in time order; those that read the same (same sentence, same handling)
    told once with a count — consecutive ones, or all of them when there are more than
    ``SCREEN`` kinds."""
    grouped: list[Episode] = []
    for episode in episodes:
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
    into.handled += episode.handled
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
    root = tree.root.uid
    run_count = history.count([root], ANY_STATUS, 0, now, starts=True)
    runs = goal_runs(tree, state, history, limit=SCREEN)
    since = 0
    if run_count > 1:
        last_start = history.last([root], ANY_STATUS, 0, now, starts=True)
        since = 0 if last_start is None else last_start.seq
    episodes, found = _episodes(tree, state, history)
    listed, kinds, other_seq = _told(tree, history, episodes)
    failures = Failures(
        episodes=len(episodes),
        listed=listed,
        kinds=kinds,
        handled=found.handled,
        in_episodes=sum(e.handled for e in episodes),
        by_design=found.guards,
        not_examined=found.not_examined,
        until_ns=found.until_ns,
        other_seq=other_seq,
    )
    goals = subgoals(tree)
    runs_of = history.counts([n.uid for n in goals], ANY_STATUS, since, now, starts=True)
    ends = [(since, min(since + SUBGOAL_ENDS, now)), (max(now - SUBGOAL_ENDS, since), now)]
    history.read_ahead(ends, [n.uid for n in goals])
    told = [_subgoal(n, since, now, history, runs_of[n.uid]) for n in goals]
    history.read_ahead([])
    return Story(
        goal=goal_words(tree),
        outcome=outcome,
        why=why,
        duration_ns=max(state.t_ns, duration_ns or 0),
        ticks=state.tick if ticks is None else ticks,
        events=state.seq,
        failures=failures,
        subgoals=told,
        runs=runs,
        run_count=run_count,
        run_results=run_results(tree, history, runs, run_count, now),
        gaps=gaps_in(state.blackboard.get(GAP_SCOPE, {})),
    )

"""The story of a run with many failures reads each page of failures' neighbourhoods at
once (``History.read_ahead``): it must tell, byte for byte, what the in-memory history
fed by the same events tells, and every question asked with spans read ahead must get
the answer SQL alone gives — at the spans' edges, across them and beyond them."""

from __future__ import annotations

import random
import re
from pathlib import Path

import pytest

from btlog.explain import story as story_module
from btlog.explain.handlers import handler_of
from btlog.explain.story import PAGE, SCREEN, goal_runs, story
from btlog.history import ANY_STATUS, LiveHistory, resumes
from btlog.record.recorder import Recorder
from btlog.replay.database import open_runs
from btlog.replay.sql_history import SqlHistory
from btlog.runner import RunConfig, prepare
from btlog.status import FAILURE

ROOT = Path(__file__).resolve().parent.parent
NAV2 = ROOT / "trees" / "nav2"
#: name -> (the run, ticks, at least this many handled failures in its story): the
#: kitting tree has more than a page of failures, Nav2's RecoveryNode halts itself
#: before it returns its result (changes that resume, not start, an activation).
CASES = {
    "kitting": (
        RunConfig(str(ROOT / "trees" / "kitting.xml"), outcomes={"default": {"ticks": 1}}),
        1500,
        PAGE,
    ),
    "nav2": (
        RunConfig(str(NAV2 / "navigate_to_pose.xml"), nodes_model=str(NAV2 / "nodes_model.xml")),
        3000,
        100,
    ),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def failing(request, tmp_path_factory) -> tuple[Path, LiveHistory, int]:
    """A tree ticked in a loop (its goal run again and again), each leaf's activation
    failing with probability 0.3: recorded, and folded into the live history from the
    same events; with the failures its story must count at least."""
    config, ticks, failures = CASES[request.param]
    config.failure_rate, config.seed = 0.3, 5
    prepared = prepare(config)
    path = tmp_path_factory.mktemp(request.param) / "run.mcap"
    live = LiveHistory(prepared.tree)
    executor = prepared.executor
    executor.subscribe(Recorder(path, prepared.tree, {"domain": "scripted"}, flush_interval=0))
    executor.subscribe(live)
    for _ in range(ticks):
        executor.tick()
    executor.close()
    return path, live, failures


@pytest.mark.parametrize("neighbourhood", [story_module.NEIGHBOURHOOD, 64])
def test_story_from_sql_is_the_live_story(failing, monkeypatch, neighbourhood: int) -> None:
    """Halfway and at the end, the story from the recording's SQL history (pages read
    ahead; with a short neighbourhood most questions reach past what was read) is the
    live history's, text and JSON."""
    monkeypatch.setattr(story_module, "NEIGHBOURHOOD", neighbourhood)
    path, live, failures = failing
    with open_runs(path, cache=False) as database:
        run = database.run(str(path))
        for at in (f"seq:{run.extent.events // 2}", "end"):
            tree, state = run.state_at(at)
            expected = story(tree, state, live)
            told = story(tree, state, SqlHistory(run, in_memory=False))
            assert told.lines() == expected.lines(), at
            assert told.to_json() == expected.to_json(), at
    assert expected.failures.handled > failures
    assert expected.failures.episodes > 10


def _queries(rng: random.Random, uids: list[int], edges: list[int], end: int):
    """Random questions whose ranges start and end at, around and between ``edges``."""
    near = [max(0, e + d) for e in edges for d in (-2, -1, 0, 1, 2)] + [0, end]
    for _ in range(300):
        lo, hi = sorted(rng.sample(near, 2))
        kind = rng.choice(["last", "first", "all", "count"])
        chosen = rng.sample(uids, min(len(uids), rng.randint(1, 4)))
        statuses = rng.sample(list(ANY_STATUS), rng.randint(1, 3))
        yield kind, chosen, statuses, lo, hi, rng.random() < 0.5, rng.choice([1, 3, 50])


@pytest.mark.parametrize("some", [False, True])
def test_read_ahead_answers_as_sql(failing, some: bool) -> None:
    """Spans read ahead (of every node, or of some), some starting at a change that
    resumes the halt right before it: every question, about the nodes that changed there,
    answers as SQL does."""
    path, live, _ = failing
    rng = random.Random(7)
    end = live.state.seq
    changes = live.transitions(list(live.tree.nodes), ANY_STATUS, 0, end, end)
    before: dict[int, object] = {}
    resuming = []
    for change in changes:
        if resumes(before.get(change.uid), change):  # type: ignore[arg-type]
            resuming.append(change)
        before[change.uid] = change
    starts = [c.seq for c in resuming[:: max(1, len(resuming) // 6)]]
    starts += [rng.randrange(end) for _ in range(6)]
    spans = [(s, s + rng.randint(1, 400)) for s in starts]
    uids = sorted({c.uid for c in resuming} | {c.uid for c in changes[:: len(changes) // 20]})
    with open_runs(path, cache=False) as database:
        run = database.run(str(path))
        sql, ahead = SqlHistory(run, in_memory=False), SqlHistory(run, in_memory=False)
        ahead.read_ahead(spans, uids[::2] if some else None)
        for query in _queries(rng, uids, [e for span in spans for e in span], end):
            assert ahead.select(*query) == sql.select(*query), query


def _numbers(told) -> dict:
    """The story's numbers, each read from its text and checked against its JSON."""
    lines, data = told.lines(), told.to_json()
    (head,) = [line for line in lines if line.startswith("Failures: ")]
    episodes = int(re.match(r"Failures: (?:at least )?(\d+)", head).group(1))
    assert episodes == data["failure_episodes"]
    counted = [re.match(r"  (\d+) times?, ", line) for line in lines]
    others = [re.search(r"other kinds of failure \((\d+) episodes", line) for line in lines]
    designed = [re.match(r"  \((?:at least )?(\d+) failures? by design", line) for line in lines]
    return {
        "episodes": episodes,
        "listed": sum(int(m.group(1)) for m in counted if m),
        "others": sum(int(m.group(1)) for m in others if m),
        "by_design": sum(int(m.group(1)) for m in designed if m),
    }


@pytest.mark.parametrize("examined", [None, 100])
@pytest.mark.parametrize("told_in_time_order", [None, 5])
def test_every_number_of_the_story_adds_up(
    failing, monkeypatch, examined: int | None, told_in_time_order: int | None
) -> None:
    """Each handled failure is counted once: in an episode, by design, or not examined;
    the kinds told and the other kinds add up to the episodes the story says; how many
    episodes are told in time order (``MAX_EPISODES``) changes none of the numbers; with
    ``MAX_EXAMINED`` hit, the totals are "at least" and the failures not examined are
    counted exactly."""
    _path, live, _ = failing
    if examined is not None:
        monkeypatch.setattr(story_module, "MAX_EXAMINED", examined)
    unbounded = story(live.tree, live.state, live).failures
    if told_in_time_order is not None:
        monkeypatch.setattr(story_module, "MAX_EPISODES", told_in_time_order)
    told = story(live.tree, live.state, live)
    found = told.failures
    handled = [c.uid for n in live.tree if handler_of(n) for c in n.children]
    assert found.handled == live.count(handled, (FAILURE,), 0, live.state.seq)
    assert found.handled == found.in_episodes + found.by_design + found.not_examined
    assert (found.episodes, found.by_design) == (unbounded.episodes, unbounded.by_design)
    numbers = _numbers(told)
    assert numbers["episodes"] == found.episodes
    assert numbers["listed"] + numbers["others"] == found.episodes
    assert numbers["by_design"] == found.by_design
    text = "\n".join(told.lines())
    if examined is None:
        assert found.examined_all and "at least" not in text
    else:
        assert not found.examined_all
        assert f"{found.not_examined} more handled failures after " in text
        assert f"Failures: at least {found.episodes}," in text


def test_the_runs_of_the_goal_are_counted_exactly(failing) -> None:
    """However many runs of the goal are listed, their count and results are exact and
    the last one told is the run's real last."""
    _, live, _ = failing
    told = story(live.tree, live.state, live)
    every = goal_runs(live.tree, live.state, live, limit=10**9)
    assert told.run_count == len(every) > SCREEN
    assert told.runs[-1] == every[-1]
    results: dict[str, int] = {}
    for run in every[:-1]:
        results[run.result or "halted"] = results.get(run.result or "halted", 0) + 1
    assert told.run_results == results
    assert f"The goal ran {len(every)} times:" in told.lines()
    for limit in (2, 3, SCREEN):
        listed = goal_runs(live.tree, live.state, live, limit=limit)
        assert listed == [*every[: limit - 1], every[-1]]


def test_a_run_failing_in_many_ways_fits_a_screen(failing) -> None:
    """Many kinds of failure: the most frequent told first, the rest counted."""
    _, live, _ = failing
    told = story(live.tree, live.state, live)
    lines = told.lines()
    assert len(lines) <= 40, "\n".join(lines)
    counts = [e.count for e in told.episodes]
    assert counts == sorted(counts, reverse=True)

"""The story of a run with many failures reads each page of failures' neighbourhoods at
once (``History.read_ahead``): it must tell, byte for byte, what the in-memory history
fed by the same events tells, and every question asked with spans read ahead must get
the answer SQL alone gives — at the spans' edges, across them and beyond them."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from btlog.explain import story as story_module
from btlog.explain.story import PAGE, story
from btlog.history import ANY_STATUS, LiveHistory, resumes
from btlog.record.recorder import Recorder
from btlog.replay.database import open_runs
from btlog.replay.sql_history import SqlHistory
from btlog.runner import RunConfig, prepare

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
    assert expected.failures > failures
    assert len(expected.episodes) > 10


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

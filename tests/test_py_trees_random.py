"""Hypothesis-built py_trees trees with random outcomes: after every tick the statuses
btlog replays at that tick are those read from the live tree (``root.iterate()``,
INVALID as IDLE), pre-emption included, and every question answered live is answered
the same post hoc, from the recording alone; the recorded changes are those py_trees
makes to ``status``, in its order."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import py_trees
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from py_trees.common import OneShotPolicy, ParallelPolicy
from py_trees.common import Status as PtStatus

from btlog.record.reader import open_recording
from btlog.sources.py_trees import STATUS, record
from tests.py_trees_support import (
    AssignmentSpy,
    Seen,
    assert_replay_equals_live,
    questions_about,
    tick_and_watch,
)

OUTCOMES = st.sampled_from([PtStatus.SUCCESS, PtStatus.FAILURE, PtStatus.RUNNING])
LEAF = st.tuples(st.just("leaf"), st.lists(OUTCOMES, max_size=4), OUTCOMES)
COMPOSITES = ["sequence", "sequence*", "selector", "selector*", "parallel all", "parallel one"]
DECORATORS = [
    "inverter",
    "retry",
    "repeat",
    "failure is success",
    "success is failure",
    "success is running",
    "running is failure",
    "one shot",
]


def _shapes(children: st.SearchStrategy) -> st.SearchStrategy:
    return st.one_of(
        st.tuples(st.sampled_from(COMPOSITES), st.lists(children, min_size=1, max_size=3)),
        st.tuples(st.sampled_from(DECORATORS), children, st.integers(1, 3)),
    )


SHAPES = st.recursive(LEAF, _shapes, max_leaves=8)


def build(shape: Any, names: itertools.count) -> py_trees.behaviour.Behaviour:
    """The py_trees behaviours of a shape; every name unique."""
    name = f"{shape[0]} {next(names)}"
    kind = shape[0]
    if kind == "leaf":
        return py_trees.behaviours.StatusQueue(name, queue=list(shape[1]), eventually=shape[2])
    if kind in COMPOSITES:
        children = [build(child, names) for child in shape[1]]
        if kind.startswith("parallel"):
            policy = (
                ParallelPolicy.SuccessOnAll()
                if kind.endswith("all")
                else (ParallelPolicy.SuccessOnOne())
            )
            return py_trees.composites.Parallel(name, policy=policy, children=children)
        memory = kind.endswith("*")
        composites = py_trees.composites
        cls = composites.Sequence if kind.startswith("seq") else composites.Selector
        return cls(name, memory=memory, children=children)
    child = build(shape[1], names)
    count = shape[2]
    d = py_trees.decorators
    if kind == "retry":
        return d.Retry(name, child, num_failures=count)
    if kind == "repeat":
        return d.Repeat(name, child, num_success=count)
    if kind == "one shot":
        return d.OneShot(name, child, policy=OneShotPolicy.ON_SUCCESSFUL_COMPLETION)
    simple = {
        "inverter": d.Inverter,
        "failure is success": d.FailureIsSuccess,
        "success is failure": d.SuccessIsFailure,
        "success is running": d.SuccessIsRunning,
        "running is failure": d.RunningIsFailure,
    }
    return simple[kind](name, child)


#: A Selector(memory=False) whose higher priority succeeds on its 3rd tick while the lower
#: priority's leaf is RUNNING: that leaf goes INVALID without being visited.
PREEMPTION = (
    "selector",
    [
        ("leaf", [PtStatus.FAILURE, PtStatus.FAILURE], PtStatus.SUCCESS),
        ("sequence*", [("leaf", [], PtStatus.SUCCESS), ("leaf", [], PtStatus.RUNNING)]),
    ],
)


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(SHAPES, st.integers(1, 10), st.randoms(use_true_random=False))
@example(PREEMPTION, 5, __import__("random").Random(0))
def test_random_py_trees_replay_and_answers(tmp_path_factory, shape, ticks, rng) -> None:
    py_trees.blackboard.Blackboard.clear()
    root = build(shape, itertools.count(1))
    tree = py_trees.trees.BehaviourTree(root)
    names = sorted({b.name for b in root.iterate()})
    asked = questions_about(rng.sample(names, min(2, len(names))))
    seen = Seen()
    path = Path(tmp_path_factory.mktemp("py_trees")) / "run.mcap"
    with record(tree, path) as recorder:
        tick_and_watch(tree, recorder, ticks, asked, seen)
    assert recorder.result is not None and recorder.result.ticks == ticks
    assert_replay_equals_live(path, seen, asked)
    if shape is PREEMPTION:
        assert seen.statuses[2][1].name == "SUCCESS"
        assert seen.statuses[1][5].name == "RUNNING" and seen.statuses[2][5].name == "IDLE"


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(SHAPES, st.integers(1, 10), st.booleans())
@example(PREEMPTION, 5, True)
def test_random_py_trees_record_every_change_in_py_trees_order(
    tmp_path_factory, shape, ticks, interrupt
) -> None:
    """The recording holds exactly the changes py_trees makes to ``status``, in its
    order (a spy on the assignment itself says which), all seen where they are made: the
    end-of-tick sweep finds nothing left over."""
    py_trees.blackboard.Blackboard.clear()
    root = build(shape, itertools.count(1))
    spy = AssignmentSpy(root)
    tree = py_trees.trees.BehaviourTree(root)
    path = Path(tmp_path_factory.mktemp("py_trees")) / "run.mcap"
    with record(tree, path, answers=False) as recorder:
        for _ in range(ticks):
            tree.tick()
        if interrupt:  # every behaviour stopped between ticks
            tree.interrupt()
        uid = recorder.watch.uid_of
        expected = [(uid(b), STATUS[old], STATUS[new]) for b, old, new in spy.changes]
    assert recorder.swept == 0
    recorded = [(c.uid, c.prev, c.status) for c in open_recording(path).transitions]
    assert recorded == expected
    assert len(expected) > 0

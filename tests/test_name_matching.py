"""Logs whose entries name their nodes, without uids (Nav2 before Jazzy), matched to the
tree by its structure (``btlog.sources.name_matching``): Nav2's default trees, whose
RecoveryNodes share their actions' names, import exactly; a log that begins mid-run
imports with its first state inferred; what no structure can tell apart is refused,
naming the names; a long log is decided as it is read, in bounded memory (issue 27).

The bags are what Nav2 Humble records: SQLite storage, no message definitions, one
``/behavior_tree_log`` message per tick while the tree runs
(``tests/test_nav2_rosbag.nav2_messages``)."""

from __future__ import annotations

import json
import tracemalloc
from array import array
from collections import Counter
from collections.abc import Iterator
from io import BytesIO
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from btlog.executor.behavior import NodeExecutionError
from btlog.record.reader import Recording, open_recording
from btlog.runner import RunConfig, execute
from btlog.sources.builder import SourceError
from btlog.sources.name_matching import COMMIT_EVERY, Entry, match_names, match_names_to
from btlog.state import StateProjection
from btlog.status import IDLE, RUNNING
from tests.cli_support import assert_bad_input, btlog
from tests.oracle.random_trees import generate
from tests.rosbag2_support import HUMBLE, NAV2_LOG, write_sqlite_bag
from tests.test_nav2_rosbag import NAV2, nav2_messages, record, transitions

#: Larger than any log's entry count: the matcher never decides before the log's end,
#: as it read every log before issue 27 (the whole list held).
NEVER = 10**9
TREE_NAME = "navigate_to_pose.xml"

DEFINITIONS = {NAV2_LOG: HUMBLE}


def source_of(recording: Recording) -> dict:
    source = recording.metadata["source"]
    return json.loads(source) if isinstance(source, str) else source


@pytest.mark.parametrize("tree", ["navigate_to_pose.xml", "navigate_through_poses.xml"])
def test_nav2_default_trees_import_exactly_from_a_humble_bag(tmp_path: Path, tree: str) -> None:
    """Nav2's trees name a RecoveryNode after its action ("FollowPath") and leave several
    Sequences unnamed; the structure tells every entry's node. FollowPath fails once, so
    its local recovery runs, in each of two goals."""
    path = NAV2 / tree
    runs = [record(tmp_path, f"run{i}", path) for i in range(2)]
    write_sqlite_bag(tmp_path / "bag", nav2_messages(runs, uids=False), DEFINITIONS)
    result = btlog("import", str(tmp_path / "bag"), "--tree", str(path), "-o", "nav.mcap",
                   cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    first = open_recording(tmp_path / "nav-goal1.mcap")
    assert transitions(first) == transitions(runs[0])
    assert source_of(first)["matched_by"] == "name"
    second = transitions(open_recording(tmp_path / "nav-goal2.mcap"))  # its end never sent
    assert second == transitions(runs[1])[: len(second)] and len(second) > 10


AMBIGUOUS = (
    '<root BTCPP_format="4"><BehaviorTree ID="T"><Parallel success_count="2">'
    '<Action ID="MoveArm" name="move"/><Action ID="MoveBase" name="move"/>'
    "</Parallel></BehaviorTree></root>"
)


def test_what_no_structure_can_tell_apart_is_refused_naming_the_names(tmp_path: Path) -> None:
    """Two nodes named "move" under a Parallel both start, then one succeeds after 1 s and
    the other after 2 s: which finished first, no log without uids can say."""
    (tmp_path / "t.xml").write_text(AMBIGUOUS)

    def tick(t_s: int, changes: str) -> tuple:
        stamp = {"sec": t_s, "nanosec": 0}
        log = []
        for change in changes.split(", "):
            name, prev, new = change.split()
            entry = {"node_name": name, "previous_status": prev, "current_status": new}
            log.append({"timestamp": stamp, **entry})
        return ("/behavior_tree_log", NAV2_LOG, t_s * 10**9, {"timestamp": stamp, "event_log": log})

    messages = [
        tick(1, "move IDLE RUNNING, move IDLE RUNNING, Parallel IDLE RUNNING"),
        tick(2, "move RUNNING SUCCESS"),
        tick(
            3,
            "move RUNNING SUCCESS, move SUCCESS IDLE, move SUCCESS IDLE, Parallel RUNNING SUCCESS",
        ),
    ]
    write_sqlite_bag(tmp_path / "bag", messages, DEFINITIONS)
    assert_bad_input(
        btlog("import", str(tmp_path / "bag"), "--tree", "t.xml", cwd=tmp_path),
        str(tmp_path / "bag"),
        "no uids",
        "'move'",
        "cannot tell them apart",
    )


def test_a_log_that_begins_mid_run_imports_with_its_first_state_inferred(tmp_path: Path) -> None:
    """The recorder started 3 ticks after the goal: the state before the bag's first
    entry is inferred (each node's previous status in its first entry, RUNNING for their
    ancestors), recorded as tick 1, said in a warning and by ``explain``; the rest is
    the run's own."""
    path = NAV2 / "navigate_to_pose.xml"
    run = record(tmp_path, "run", path)
    messages = nav2_messages([run], uids=False)
    late = 3
    write_sqlite_bag(tmp_path / "bag", messages[late:], DEFINITIONS)
    result = btlog("import", str(tmp_path / "bag"), "--tree", str(path), "-o", "late.mcap",
                   cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "goal 1: the log begins mid-run" in result.stderr
    imported = open_recording(tmp_path / "late.mcap")
    assert "inferred" in imported.metadata["mid_run"]
    inferred = [e for e in imported.transitions if e.tick == 1]
    assert {e.prev.name for e in inferred} == {"IDLE"} and len(inferred) == 5
    skipped = sum(len(m[3]["event_log"]) for m in messages[:late])
    rest = [e[1:] for e in transitions(imported)[len(inferred) :]]
    assert rest == [e[1:] for e in transitions(run)[skipped : skipped + len(rest)]]
    # the inferred state is the run's own at the bag's first entry
    state = StateProjection(imported.tree)
    for event in inferred:
        state.on_status(event.seq, event.t_ns, event.tick, event.uid, event.prev, event.status)
    truth = StateProjection(run.tree)
    for event in run.transitions[:skipped]:
        truth.on_status(event.seq, event.t_ns, event.tick, event.uid, event.prev, event.status)

    def active(projection: StateProjection) -> dict:
        return {uid: s for uid, s in projection.state.status.items() if s is not IDLE}

    # what the bag tells is the truth (the selectors that succeeded before it began are
    # named by no entry of it: they stay IDLE)
    assert active(state).items() <= active(truth).items()
    named = {e.uid for e in imported.transitions if e.tick > 1}
    assert {u: s for u, s in active(truth).items() if u in named} == {
        u: s for u, s in active(state).items() if u in named
    }
    story = btlog("explain", str(tmp_path / "late.mcap"))
    assert "Note: the log begins mid-run" in story.stdout


def _anonymous_run(seed: int, folder: Path) -> Recording:
    case = generate(seed)
    tree = folder / f"t{seed}.xml"
    tree.write_text(case.xml)
    config = RunConfig(str(tree), outcomes=case.outcomes, max_ticks=case.max_ticks)
    try:
        recorded = execute(config, folder / f"r{seed}.mcap")
    except NodeExecutionError:  # a tree BT.CPP refuses too
        assume(False)
    run = open_recording(recorded.path)
    assume(run.transitions)
    return run


def _random_trees(test):
    """The random trees both properties read: a seed, and a log from the start or a
    later tick (12 examples, derandomized)."""
    return settings(
        max_examples=12,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    )(given(seed=st.integers(0, 100_000), late=st.sampled_from([0, 3]))(test))


@_random_trees
def test_anonymous_random_trees_are_matched_or_refused_never_misread(tmp_path, seed, late):
    """The worst case: random BT.CPP 4 trees whose every node is unnamed (BT.CPP logs
    its type), from the start or from a later tick. Each reading is the truth, or the
    truth with two same-tick transitions in another order, or a refusal."""
    run = _anonymous_run(seed, tmp_path)
    for node in run.tree:
        node.name = node.type
    ticks = sorted({e.tick for e in run.transitions})
    changes = [e for e in run.transitions if e.tick >= ticks[min(late, len(ticks) - 1)]]
    types = {node.uid: node.type for node in run.tree}
    entries = [Entry(types[e.uid], e.prev, e.status, e.tick) for e in changes]
    truth = [e.uid for e in changes]
    try:
        read = match_names(entries, run.tree, "log")
    except SourceError as error:
        assert "no uids" in str(error)
        return
    if read != truth:

        def by_tick(uids: list[int]) -> Counter:
            return Counter(
                (e.group, u, e.prev, e.status) for e, u in zip(entries, uids, strict=True)
            )

        assert by_tick(read) == by_tick(truth)


def test_an_ancestor_the_log_never_names_was_running_from_its_first_entry(tmp_path: Path) -> None:
    """A bag whose entries never name the root while the nodes under it run (as a public
    Nav2 Galactic bag: its recorder missed the root's start, or the tree given has a
    root the run's did not): the root is RUNNING from the first entry on, said in a
    warning and by ``explain``, and the goal is not told as "not started"."""
    path = NAV2 / "navigate_to_pose.xml"
    run = record(tmp_path, "run", path)
    root = run.tree.root
    messages = []
    for topic, kind, sent, message in nav2_messages([run], uids=False):
        kept = [e for e in message["event_log"] if e["node_name"] != root.description]
        if kept:
            messages.append((topic, kind, sent, {**message, "event_log": kept}))
    write_sqlite_bag(tmp_path / "bag", messages, DEFINITIONS)
    result = btlog("import", str(tmp_path / "bag"), "--tree", str(path), "-o", "no-root.mcap",
                   cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert f"goal 1: {root.description!r}: never in the log while nodes under it" in result.stderr
    imported = open_recording(tmp_path / "no-root.mcap")
    first = [(e.uid, e.prev, e.status) for e in imported.transitions if e.tick == 1]
    assert first == [(root.uid, IDLE, RUNNING)]
    rest = [e[1:] for e in transitions(imported)[1:]]
    assert rest == [e[1:] for e in transitions(run) if e[1] != root.uid][: len(rest)]
    story = btlog("explain", str(tmp_path / "no-root.mcap"))
    assert "not started" not in story.stdout.splitlines()[0], story.stdout
    assert f"Note: {root.description!r}: never in the log" in story.stdout


@_random_trees
def test_deciding_as_the_log_is_read_changes_no_reading_and_no_refusal(tmp_path, seed, late):
    """The anonymous random trees again (readings and refusals both), each read deciding
    the readings' common choices as early as it can (every entry or two) and never
    (the whole log held, as before issue 27): the same uids, or the same refusal, naming
    the same names."""
    run = _anonymous_run(seed, tmp_path)
    for node in run.tree:
        node.name = node.type
    ticks = sorted({e.tick for e in run.transitions})
    types = {node.uid: node.type for node in run.tree}
    entries = [
        Entry(types[e.uid], e.prev, e.status, e.tick)
        for e in run.transitions
        if e.tick >= ticks[min(late, len(ticks) - 1)]
    ]

    def read(every: int) -> list[int] | str:
        try:
            return match_names(entries, run.tree, "log", every)
        except SourceError as error:
            return str(error)

    whole = read(NEVER)
    assert read(1) == whole and read(2) == whole


def _long_navigation(folder: Path, seconds: float) -> Recording:
    """Nav2's navigate_to_pose: FollowPath fails once, then follows the path for
    ``seconds`` while the RateController replans at 1 Hz (about 21 changes a second)."""
    outcomes = {
        "default": {"status": "SUCCESS", "duration": 0},
        "nodes": {
            "GlobalUpdatedGoal": "FAILURE",
            "GoalUpdated": "FAILURE",
            "IsGoalNearby": "FAILURE",
            "FollowPath": [
                {"status": "FAILURE", "duration": 2},
                {"status": "SUCCESS", "duration": seconds},
            ],
        },
    }
    path = NAV2 / TREE_NAME
    return record(folder, f"long{seconds:.0f}", path, outcomes=outcomes, max_ticks=10**6)


def test_a_long_log_is_decided_as_it_is_read_in_bounded_memory(tmp_path: Path) -> None:
    """Issue 27: the readings of a long Nav2 log agree on all but its last entries, so
    the matcher writes the uids out as it reads and holds only the undecided entries
    (and their choices): as many for a log four times as long, and a few times
    ``every``. The uids are the run's, and those of the whole log held."""
    held = []
    for seconds in (300, 1200):
        run = _long_navigation(tmp_path, seconds)
        names = {node.uid: node.description for node in run.tree}
        entries = [Entry(names[e.uid], e.prev, e.status, e.tick) for e in run.transitions]
        truth = [e.uid for e in run.transitions]
        assert len(entries) > 20 * seconds
        out = BytesIO()
        held.append(match_names_to(entries, run.tree, "log", out, every=16))
        assert array("q", out.getvalue()).tolist() == truth
        assert match_names(entries, run.tree, "log", NEVER) == truth
    assert held[0] == held[1] <= 32, held


def test_a_long_humble_bag_imports_exactly(tmp_path: Path) -> None:
    """The same through ``btlog import`` of a Humble bag (uids in a temporary file,
    read back for each pass): more entries than the matcher holds before it decides."""
    run = _long_navigation(tmp_path, 600)
    assert len(run.transitions) > 3 * COMMIT_EVERY
    write_sqlite_bag(tmp_path / "bag", nav2_messages([run], uids=False), DEFINITIONS)
    path = NAV2 / "navigate_to_pose.xml"
    result = btlog("import", str(tmp_path / "bag"), "--tree", str(path), "-o", "long.mcap",
                   cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    imported = transitions(open_recording(tmp_path / "long.mcap"))  # its end never sent
    assert imported == transitions(run)[: len(imported)]
    assert len(imported) > len(run.transitions) - 100  # the last tick: never sent


class _Replayed:
    """A run's entries as a name-only log gives them, made anew each pass (as a bag's
    are decoded anew), none held."""

    def __init__(self, run: Recording) -> None:
        self.changes = run.transitions
        self.names = {node.uid: node.description for node in run.tree}

    def __iter__(self) -> Iterator[Entry]:
        names = self.names
        return (Entry(names[e.uid], e.prev, e.status, e.tick) for e in self.changes)


def test_matching_a_longer_log_takes_no_more_memory(tmp_path: Path) -> None:
    """Issue 27: the matcher's peak of Python allocations while it reads a name-only log
    (entries made as read, uids to a file) is no higher for a log four times as long;
    holding every entry for it took ~2 MB more here (0.69 MB, then 2.69 MB)."""
    peaks = []
    for seconds in (300, 1200):
        run = _long_navigation(tmp_path, seconds)
        log = _Replayed(run)
        with open(tmp_path / f"uids{seconds}", "w+b") as out:
            tracemalloc.start()
            try:
                match_names_to(log, run.tree, "log", out)
                _now, peak = tracemalloc.get_traced_memory()
            finally:
                tracemalloc.stop()
            out.seek(0)
            assert array("q", out.read()).tolist() == [e.uid for e in run.transitions]
        peaks.append(peak)
    assert peaks[1] - peaks[0] < 300_000, peaks

"""py_trees_ros snapshot bags: ``btlog import BAG`` of ``py_trees_ros_interfaces/msg/
BehaviourTree`` snapshots, made here from a real py_trees run (each tick's statuses and
blackboard activity as a message, written with mcap-ros2-support), in MCAP and SQLite
storage."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import py_trees
import pytest
from py_trees.common import Status as PtStatus

from btlog.events import TreeMutation
from btlog.record.reader import open_recording
from btlog.replay.database import open_runs
from btlog.sources.py_trees import STATUS
from btlog.sources.py_trees_ros_bag import SNAPSHOT_TYPE
from btlog.sources.py_trees_tree import behaviours
from btlog.sources.rosbag2 import shipped_definition
from tests.cli_support import assert_bad_input, btlog
from tests.rosbag2_support import Message, write_mcap_bag, write_sqlite_bag

DEFINITION = shipped_definition(SNAPSHOT_TYPE, "2.1").text
TOPIC = "/tree/snapshots"
START_NS = 1_700_000_000_000_000_000
PT_STATUS = {PtStatus.INVALID: 1, PtStatus.RUNNING: 2, PtStatus.SUCCESS: 3, PtStatus.FAILURE: 4}
TICKS = 6


def _uuid(behaviour: Any | None) -> dict:
    return {"uuid": behaviour.id.bytes if behaviour is not None else bytes(16)}


def _type(behaviour: Any) -> int:
    """The message's type constant, as py_trees_ros' conversions give it."""
    if isinstance(behaviour, py_trees.composites.Sequence):
        return 2
    if isinstance(behaviour, py_trees.composites.Selector):
        return 3
    if isinstance(behaviour, py_trees.composites.Parallel):
        return 4
    return 6 if isinstance(behaviour, py_trees.decorators.Decorator) else 1


def _detail(behaviour: Any) -> str:
    if isinstance(behaviour, py_trees.composites.Parallel):
        return type(behaviour.policy).__name__.replace("Success", "")
    return "WithMemory" if getattr(behaviour, "memory", False) else ""


def snapshot(root: Any, count: int, activity: list[Any]) -> dict:
    """A BehaviourTree message (as a mapping) of the tree now."""
    return {
        "behaviours": [
            {
                "name": b.name,
                "class_name": f"{type(b).__module__}.{type(b).__name__}",
                "own_id": _uuid(b),
                "parent_id": _uuid(b.parent),
                "child_ids": [_uuid(c) for c in b.children],
                "type": _type(b),
                "additional_detail": _detail(b),
                "status": PT_STATUS[b.status],
                "is_active": True,
            }
            for b in root.iterate()
        ],
        "changed": True,
        "blackboard_activity": [
            {
                "key": item.key,
                "client_name": item.client_name,
                "activity_type": item.activity_type,
                "previous_value": str(item.previous_value),
                "current_value": str(item.current_value),
            }
            for item in activity
        ],
        "statistics": {"count": count},
    }


def make_tree() -> Any:
    """A small tree: a reactive selector pre-empting a running lower-priority branch, a
    sequence with memory, a parallel, a retry, and a blackboard write."""
    names = itertools.count()

    def queue(outcomes: list[PtStatus], last: PtStatus) -> Any:
        return py_trees.behaviours.StatusQueue(f"Leaf{next(names)}", list(outcomes), last)

    R, S, F = PtStatus.RUNNING, PtStatus.SUCCESS, PtStatus.FAILURE
    guard = queue([F, F, S], S)  # succeeds at tick 3: "Work", RUNNING, is pre-empted
    work = py_trees.composites.Sequence(
        "Work",
        memory=True,
        children=[
            py_trees.behaviours.SetBlackboardVariable("Note", "/goal", 7, overwrite=True),
            py_trees.composites.Parallel(
                "Both",
                policy=py_trees.common.ParallelPolicy.SuccessOnAll(),
                children=[py_trees.decorators.Retry("Again", queue([R, S], S), 2)],
            ),
            py_trees.decorators.Inverter("Not", queue([R, F], F)),
        ],
    )
    root = py_trees.composites.Selector("Root", memory=False, children=[guard, work])
    return root


def run_snapshots() -> tuple[list[Message], list[dict[int, Any]]]:
    """Tick the tree; each tick's snapshot, and its statuses by pre-order uid."""
    py_trees.blackboard.Blackboard.clear()
    py_trees.blackboard.Blackboard.enable_activity_stream(100)
    tree = py_trees.trees.BehaviourTree(make_tree())
    stream = py_trees.blackboard.Blackboard.activity_stream
    messages: list[Message] = []
    seen: list[dict[int, Any]] = []
    try:
        for tick in range(1, TICKS + 1):
            assert stream is not None
            stream.clear()
            tree.tick()
            t = START_NS + tick * 100_000_000
            msg = snapshot(tree.root, tick, list(stream.data))
            messages.append((TOPIC, SNAPSHOT_TYPE, t, msg))
            order = list(behaviours(tree.root))
            seen.append({uid: STATUS[b.status] for uid, b in enumerate(order, start=1)})
    finally:
        py_trees.blackboard.Blackboard.disable_activity_stream()
    return messages, seen


def _check(bag: Path, out: Path, seen: list[dict[int, Any]]) -> None:
    result = btlog("import", bag, "-o", out)
    assert result.returncode == 0, result.stderr
    assert "not in the bag" in result.stderr  # what snapshots cannot tell is said
    expected = sum(
        sum(before.get(uid, STATUS[PtStatus.INVALID]) is not now[uid] for uid in now)
        for before, now in zip([{}, *seen], seen, strict=False)
    )
    assert f"{expected} transitions" in result.stdout, result.stdout
    database = open_runs(out, cache=False)
    try:
        run = database.run(str(out))
        for tick, statuses in enumerate(seen, start=1):
            _, state = run.state_at(f"tick:{tick}")
            assert {uid: state.status_of(uid) for uid in statuses} == statuses, tick
    finally:
        database.close()
    recording = open_recording(out)
    names = {node.name for node in recording.tree}
    assert {"Root", "Work", "Leaf0", "Not", "Note"} <= names
    types = {node.name: node.type for node in recording.tree}
    assert types["Root"] == "ReactiveFallback" and types["Work"] == "Sequence"
    assert types["Not"] == "Inverter" and types["Both"] == "Parallel"
    assert types["Again"] == "Retry"  # the snapshot lacks its attempts: its class, said
    assert "do not carry the parameters of 'Again'" in result.stderr
    explained = btlog("explain", out)
    assert explained.returncode == 0, explained.stderr
    assert explained.stdout.strip()


def test_mcap_snapshot_bag(tmp_path: Path) -> None:
    messages, seen = run_snapshots()
    write_mcap_bag(tmp_path / "bag", messages, {SNAPSHOT_TYPE: DEFINITION})
    out = tmp_path / "run.mcap"
    _check(tmp_path / "bag", out, seen)
    writes = btlog("sql", out, "SELECT DISTINCT key, value, writer_uid FROM blackboard")
    assert writes.returncode == 0, writes.stderr
    row = next(line for line in writes.stdout.splitlines() if "/goal" in line)
    # the value's text (py_trees_ros sends str(value)); the writer is the client's behaviour
    assert row.split("│")[2:4] == [' "7"   ', " 4          "], row


def test_sqlite_snapshot_bag_without_definitions(tmp_path: Path) -> None:
    messages, seen = run_snapshots()
    write_sqlite_bag(tmp_path / "bag", messages, {SNAPSHOT_TYPE: DEFINITION})
    _check(tmp_path / "bag", tmp_path / "run.mcap", seen)


def test_skipped_ticks_are_told(tmp_path: Path) -> None:
    messages, _seen = run_snapshots()
    kept = [messages[0], messages[3], *messages[4:]]
    write_mcap_bag(tmp_path / "bag", kept, {SNAPSHOT_TYPE: DEFINITION})
    result = btlog("import", tmp_path / "bag", "-o", tmp_path / "run.mcap")
    assert result.returncode == 0, result.stderr
    assert "2 ticks have no snapshot" in result.stderr


def test_tree_changes_between_snapshots_are_mutations(tmp_path: Path) -> None:
    """A subtree inserted into the running tree and a behaviour pruned from it show in
    the snapshots after; the import makes them insert and prune mutations, and the state
    at every tick is the live tree's, behaviour for behaviour."""
    py_trees.blackboard.Blackboard.clear()
    tree = py_trees.trees.BehaviourTree(make_tree())
    work = next(b for b in tree.root.iterate() if b.name == "Work")
    extra = py_trees.composites.Sequence(
        "Extra",
        memory=False,
        children=[py_trees.behaviours.Success("Check"), py_trees.behaviours.Running("Go")],
    )
    messages: list[Message] = []
    seen: list[dict[str, Any]] = []
    for tick in range(1, TICKS + 1):
        if tick == 2:
            tree.insert_subtree(extra, work.id, 1)
        if tick == 4:
            tree.prune_subtree(extra.children[0].id)
        tree.tick()
        t = START_NS + tick * 100_000_000
        messages.append((TOPIC, SNAPSHOT_TYPE, t, snapshot(tree.root, tick, [])))
        seen.append({b.name: STATUS[b.status] for b in tree.root.iterate()})
    write_mcap_bag(tmp_path / "bag", messages, {SNAPSHOT_TYPE: DEFINITION})
    out = tmp_path / "run.mcap"
    result = btlog("import", tmp_path / "bag", "-o", out)
    assert result.returncode == 0, result.stderr
    recording = open_recording(out)
    mutations = [e for e in recording.events if isinstance(e, TreeMutation)]
    assert [(m.op, m.tick, [n["name"] for n in m.nodes]) for m in mutations] == [
        ("insert", 2, ["Extra", "Check", "Go"]),
        ("prune", 4, ["Check"]),
    ]
    database = open_runs(out, cache=False)
    try:
        run = database.run(str(out))
        for tick, statuses in enumerate(seen, start=1):
            tree_then, state = run.state_at(f"tick:{tick}")
            replayed = {node.name: state.status_of(node.uid) for node in tree_then}
            assert replayed == statuses, tick
    finally:
        database.close()
    inserted = {n["name"]: n for n in mutations[0].nodes}
    previous = {node.uid: node.name for node in recording.tree}
    assert previous[mutations[0].after_uid] == "Note"  # at index 1, after Work's first
    assert min(n["uid"] for n in inserted.values()) > max(previous)


@pytest.mark.parametrize("damage", ["orphan child", "two roots"])
def test_bad_snapshot_bag_exits_2(tmp_path: Path, damage: str) -> None:
    messages, _seen = run_snapshots()
    first = dict(messages[0][3])
    items = [dict(b) for b in first["behaviours"]]
    if damage == "orphan child":
        items[0]["child_ids"] = [*items[0]["child_ids"], {"uuid": b"\x01" * 16}]
    else:
        items = [dict(items[-1], parent_id={"uuid": bytes(16)}, name="Other"), *items]
        items[0]["own_id"] = {"uuid": b"\x02" * 16}
    first["behaviours"] = items
    write_mcap_bag(
        tmp_path / "bag", [(TOPIC, SNAPSHOT_TYPE, START_NS, first)], {SNAPSHOT_TYPE: DEFINITION}
    )
    result = btlog("import", tmp_path / "bag", "-o", tmp_path / "run.mcap")
    assert_bad_input(result, "bag", TOPIC)
    assert not (tmp_path / "run.mcap").exists()

"""BT.CPP v3 ``FileLogger`` files (``.fbl``) through ``btlog import``: the tree from the
header, transitions mapped from BT.CPP 3's uids, ``--tree`` checked against the header,
a logger started mid-run, damage named by its byte.

The files are written by ``tests/fbl_support.py`` as BT.CPP 3.8 writes them (its header
is byte for byte a real BT.CPP 3 file's, checked by ``tests/test_real_logs.py``), for
runs btlog makes of a Nav2-Humble-like stand-in tree (``tests/data/logs``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from btlog.record.reader import Recording, open_recording
from btlog.record.recorder import start_time_ns
from btlog.runner import RunConfig, execute
from btlog.sources.btcpp_fbl import read_fbl
from btlog.sources.builder import SourceError
from btlog.status import Status
from btlog.tree.model import Tree
from tests.cli_support import ROOT, assert_bad_input, btlog
from tests.fbl_support import (
    ACTION,
    CONDITION,
    CONTROL,
    DECORATOR,
    SUBTREE,
    Model,
    Node,
    write_fbl,
)

STAND_IN = ROOT / "tests" / "data" / "logs" / "nav2-v3-stand-in.xml"
#: BT.CPP 3 numbers nodes from a process-wide counter: a second tree starts past the first.
UID_BASE = 24
KINDS = {"control": CONTROL, "decorator": DECORATOR, "subtree": SUBTREE, "action": ACTION,
         "condition": CONDITION}  # fmt: skip
V3_NAMES = {"SequenceWithMemory": "SequenceStar"}
OUTCOMES = {
    "default": {"status": "SUCCESS", "duration": 0.2},
    "nodes": {"FollowPath": [{"status": "FAILURE", "duration": 1.0}, "SUCCESS"]},
}


def header_of(tree: Tree, statuses: dict[int, int] | None = None) -> tuple[Node, list[Model]]:
    """The tree as BT.CPP 3 sees it: its uids, registration names and instance names."""
    statuses = statuses or {}

    def node(n) -> Node:
        kind = V3_NAMES.get(n.type, n.type)
        name = kind if n.name == n.type else n.name
        ports = [(key, port.value) for key, port in n.ports.items()]
        return Node(n.uid + UID_BASE, name, kind, ports, [node(c) for c in n.children],
                    statuses.get(n.uid, 0))  # fmt: skip

    models = {}
    for n in tree:
        kind = V3_NAMES.get(n.type, n.type)
        ports = [(key, 0, "std::string", "") for key in n.ports]
        models[kind] = Model(kind, KINDS[n.kind], ports)
    return node(tree.root), list(models.values())


def recorded(tmp_path: Path) -> Recording:
    config = RunConfig(str(STAND_IN), outcomes=OUTCOMES)
    return open_recording(execute(config, tmp_path / "run.mcap").path)


def fbl_of(run: Recording, path: Path, statuses: dict[int, int] | None = None, skip: int = 0):
    """What FileLogger writes for ``run`` (its first ``skip`` changes before the logger
    existed), at the run's wall-clock times."""
    start_us = start_time_ns(run.metadata["started_at"]) // 1000
    changes = [(start_us + e.t_ns // 1000, e.uid + UID_BASE, int(e.prev), int(e.status))
               for e in run.transitions[skip:]]  # fmt: skip
    root, models = header_of(run.tree, statuses)
    return write_fbl(path, root, models, changes)


def changes(recording: Recording) -> list[tuple]:
    """(µs since the first change, uid, prev, status)."""
    first = recording.transitions[0].t_ns
    return [((e.t_ns - first) // 1000, e.uid, e.prev, e.status) for e in recording.transitions]


def test_an_fbl_imports_with_its_tree_from_the_header(tmp_path: Path) -> None:
    run = recorded(tmp_path)
    fbl_of(run, tmp_path / "nav.fbl")
    result = btlog("import", "nav.fbl", "-o", "nav.mcap", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    imported = open_recording(tmp_path / "nav.mcap")
    assert changes(imported) == changes(run)
    mine = [(n.uid, n.kind, n.type, n.name, {k: p.value for k, p in n.ports.items()})
            for n in imported.tree]  # fmt: skip
    assert mine == [(n.uid, n.kind, n.type, n.name, {k: p.value for k, p in n.ports.items()})
                    for n in run.tree]  # fmt: skip
    assert imported.tree.nodes[9].type == "SequenceWithMemory"  # BT.CPP 3's SequenceStar
    source = imported.metadata["source"]
    source = json.loads(source) if isinstance(source, str) else source
    assert (source["format"], source["records"]) == ("btcpp-fbl", len(run.transitions))
    assert imported.metadata["started_at"] == run.metadata["started_at"]
    story = btlog("explain", "nav.mcap", cwd=tmp_path)
    assert "I could not follow path because follow path failed." in story.stdout
    lines = story.stdout.splitlines()
    for at, line in enumerate(lines):  # a heading is never left empty
        if line.endswith(":") and not line.startswith(" "):
            assert at + 1 < len(lines) and lines[at + 1].startswith("  "), story.stdout
    # the tree file, checked against the header; another tree is refused
    given = btlog("import", "nav.fbl", "--tree", str(STAND_IN), "-o", "given.mcap",
                  cwd=tmp_path)  # fmt: skip
    assert given.returncode == 0, given.stderr
    assert changes(open_recording(tmp_path / "given.mcap")) == changes(run)
    other = ROOT / "trees" / "nav2" / "navigate_to_pose.xml"
    assert_bad_input(btlog("import", "nav.fbl", "--tree", str(other), cwd=tmp_path),
                     str(other), "not the tree of this log")  # fmt: skip


def test_a_logger_created_while_the_tree_ran_begins_mid_run(tmp_path: Path) -> None:
    """The header holds each node's status when the logger was created."""
    run = recorded(tmp_path)
    skip = 20
    projection = {}
    for event in run.transitions[:skip]:
        projection[event.uid] = int(event.status)
    fbl_of(run, tmp_path / "late.fbl", projection, skip)
    result = btlog("import", "late.fbl", "-o", "late.mcap", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "the log begins mid-run" in result.stderr
    imported = open_recording(tmp_path / "late.mcap")
    inferred = {e.uid: e.status for e in imported.transitions if e.tick == 1}
    assert inferred == {u: Status(s) for u, s in projection.items() if s}
    rest = [(e.uid, e.prev, e.status) for e in imported.transitions if e.tick > 1]
    assert rest == [(e.uid, e.prev, e.status) for e in run.transitions[skip:]]


def test_damaged_fbl_files_are_refused_naming_the_byte_or_read_to_the_cut(tmp_path):
    run = recorded(tmp_path)
    data = fbl_of(run, tmp_path / "nav.fbl")
    size = int.from_bytes(data[:4], "little")
    cut = tmp_path / "cut.fbl"
    cut.write_bytes(data[: len(data) - 5])
    result = btlog("import", "cut.fbl", "-o", "cut.mcap", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "the file ends inside a transition (7 of 12 bytes)" in result.stderr
    assert len(open_recording(tmp_path / "cut.mcap").transitions) == len(run.transitions) - 1
    bad = tmp_path / "bad.fbl"
    bad.write_bytes(data[:4] + (size + 100).to_bytes(4, "little") + data[8:])  # root offset
    assert_bad_input(btlog("import", "bad.fbl", cwd=tmp_path), "bad.fbl", "byte",
                     "header is damaged")  # fmt: skip
    status = tmp_path / "status.fbl"
    status.write_bytes(data[: 4 + size + 11] + b"\x09" + data[4 + size + 12 :])
    assert_bad_input(btlog("import", "status.fbl", cwd=tmp_path), "status.fbl",
                     f"byte {4 + size}", "status 9")  # fmt: skip
    assert not (tmp_path / "status.mcap").exists()


def test_transitions_are_read_in_blocks_with_the_same_result_and_error_bytes(tmp_path):
    """The transitions are read a block at a time (the import holds none of them): blocks
    of 4 give what one read gives; a bad status in a later block and a file cut while it
    is read are named by their byte."""
    run = recorded(tmp_path)
    data = fbl_of(run, tmp_path / "nav.fbl")
    log = read_fbl(tmp_path / "nav.fbl")
    whole = list(log.transitions())
    assert len(whole) == len(log) == len(run.transitions) > 4 * 3
    assert list(log.transitions(block=4)) == whole
    at = log.records_offset + 9 * 12
    (tmp_path / "bad.fbl").write_bytes(data[: at + 11] + b"\x07" + data[at + 12 :])
    seen: list[tuple] = []
    with pytest.raises(SourceError, match=rf"bad\.fbl: byte {at}: status 7 is not 0-3"):
        seen.extend(read_fbl(tmp_path / "bad.fbl").transitions(block=4))
    assert seen == whole[:9]
    with open(tmp_path / "nav.fbl", "r+b") as stream:
        stream.truncate(log.records_offset + 6 * 12)
    cut_at = log.records_offset + 6 * 12
    with pytest.raises(SourceError, match=rf"nav\.fbl: byte {cut_at}: the file was cut while read"):
        list(log.transitions(block=4))

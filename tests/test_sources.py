"""Sources and sinks without BT.CPP: the builder's tick rule, the loader's import mode,
the FileLogger2 round trip, SQLite sessions and bad input, through the real CLI."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from btlog.events import StatusChange
from btlog.explain.questions import explain
from btlog.record.reader import open_recording
from btlog.replay.database import open_runs
from btlog.runner import RunConfig, execute
from btlog.sinks.btcpp_filelog import export_filelog, tree_xml
from btlog.sources.btcpp_filelog import import_filelog, read_filelog
from btlog.sources.btcpp_tree import tree_from_log_xml
from btlog.sources.builder import RecordingBuilder, Source
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS
from btlog.tree.loader import TreeError, load_nodes_model, load_tree_text
from tests.cli_support import ROOT, assert_bad_input, btlog
from tests.oracle.random_trees import generate

KITTING_RUN = ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"

ROBOT_XML = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence name="deliver">
      <GoalFilter name="update goal"><ComputePath name="plan"/></GoalFilter>
      <PipelineStep name="follow">
        <IsBatteryLow name="battery ok?"/>
        <FollowPath name="drive"/>
      </PipelineStep>
    </Sequence>
  </BehaviorTree>
</root>"""

ROBOT_MODEL = """<root BTCPP_format="4"><TreeNodesModel>
  <Decorator ID="GoalFilter"><input_port name="input_goal"/></Decorator>
  <Control ID="PipelineStep"/>
  <Condition ID="IsBatteryLow"/>
  <Action ID="ComputePath"><output_port name="path"/></Action>
</TreeNodesModel></root>"""


def _transitions(path: Path) -> list[tuple]:
    return [
        (e.t_ns, e.tick, e.uid, e.prev, e.status)
        for e in open_recording(path).events
        if isinstance(e, StatusChange)
    ]


def _renumbered(rows: list[tuple]) -> list[tuple]:
    numbers: dict[int, int] = {}
    return [(t, numbers.setdefault(k, len(numbers) + 1), *rest) for t, k, *rest in rows]


# -- the loader's import mode --------------------------------------------------------------
def test_unknown_types_are_refused_unless_importing() -> None:
    with pytest.raises(TreeError, match="GoalFilter"):
        load_tree_text(ROBOT_XML)
    tree = load_tree_text(ROBOT_XML, accept_unknown=True)
    kinds = {n.name: n.kind for n in tree}
    # without a model: one child -> decorator, more -> control, none -> action
    assert kinds["update goal"] == "decorator" and kinds["follow"] == "control"
    assert kinds["battery ok?"] == "action"


def test_nodes_model_gives_kinds_and_ports(tmp_path: Path) -> None:
    model = tmp_path / "model.xml"
    model.write_text(ROBOT_MODEL)
    registry = load_nodes_model(model)
    tree = load_tree_text(ROBOT_XML, registry, accept_unknown=True)
    plan = tree.lookup("plan")[0]
    assert tree.lookup("battery ok?")[0].kind == "condition"
    assert plan.kind == "action"
    assert "path" not in plan.ports  # declared ports are not invented
    (tmp_path / "empty.xml").write_text("<root/>")
    with pytest.raises(TreeError, match="no <TreeNodesModel>"):
        load_nodes_model(tmp_path / "empty.xml")


# -- the builder's tick rule ---------------------------------------------------------------
def test_tick_rule_root_reset_and_gaps(tmp_path: Path) -> None:
    tree = load_tree_text(ROBOT_XML, accept_unknown=True)
    root, plan, drive = 1, tree.lookup("plan")[0].uid, tree.lookup("drive")[0].uid
    builder = RecordingBuilder(tmp_path / "r.mcap", tree, Source("test", "mem"))
    ms = 1_000_000
    builder.transition(0, root, RUNNING)  # tick 1
    builder.transition(10, plan, RUNNING)
    builder.transition(100 * ms, plan, SUCCESS)  # tick 2: a new timestamp group
    builder.transition(100 * ms + 5, drive, FAILURE)  # same group
    builder.transition(100 * ms + 9, root, FAILURE)
    builder.transition(100 * ms + 9, root, IDLE)  # the reset ends tick 2
    builder.transition(100 * ms + 10, root, RUNNING)  # tick 3 at once: root left IDLE
    builder.write(100 * ms + 11, "", "goal", {"x": 1}, plan)
    result = builder.close()
    assert result.ticks == 3 and result.transitions == 7 and result.writes == 1
    recording = open_recording(tmp_path / "r.mcap")
    assert [e.tick for e in recording.events] == [1, 1, 2, 2, 2, 2, 3, 3]
    assert [r.root_status.name for r in recording.ticks] == ["RUNNING", "FAILURE", "RUNNING"]
    source = {"format": "test", "file": "mem", "sha256": "", "blackboard": False}
    assert recording.metadata["source"] == source


@settings(max_examples=25, deadline=None)
@given(st.lists(st.sampled_from([RUNNING, SUCCESS, FAILURE, IDLE]), min_size=1, max_size=40))
def test_builder_numbers_events_and_keeps_prev_consistent(tmp_path_factory, statuses) -> None:
    tree = load_tree_text(ROBOT_XML, accept_unknown=True)
    out = tmp_path_factory.mktemp("b") / "p.mcap"
    with RecordingBuilder(out, tree, Source("test", "mem")) as builder:
        for i, status in enumerate(statuses):
            builder.transition(i * 7_000_000, 2 + i % 3, status)
    events = open_recording(out).events
    assert [e.seq for e in events] == list(range(len(statuses)))
    last: dict[int, object] = {}
    for event in events:
        assert event.prev == last.get(event.uid, IDLE)
        last[event.uid] = event.status


# -- FileLogger2 round trip ------------------------------------------------------------------
def test_export_then_import_gives_the_same_run(tmp_path: Path) -> None:
    out = tmp_path / "k.btlog"
    result = btlog("export", str(KITTING_RUN), "--to", "btlog", str(out))
    assert result.returncode == 0, result.stderr
    assert "blackboard writes left out" in result.stderr
    assert read_filelog(out).xml.startswith(b'<root BTCPP_format="4">')
    result = btlog("import", str(out), "-o", str(tmp_path / "k.mcap"))
    assert result.returncode == 0, result.stderr
    original, imported = _transitions(KITTING_RUN), _transitions(tmp_path / "k.mcap")
    assert imported == _renumbered(original)  # empty ticks leave no trace in a .btlog
    shape = [(n.uid, n.kind, n.type, n.name, n.path) for n in open_recording(KITTING_RUN).tree]
    assert [
        (n.uid, n.kind, n.type, n.name, n.path) for n in open_recording(tmp_path / "k.mcap").tree
    ] == shape
    copy = tmp_path / "original.mcap"  # its read model is cached beside it
    copy.write_bytes(KITTING_RUN.read_bytes())
    with open_runs(copy, tmp_path / "k.mcap") as db:
        for at in ("10.4s", "30s", "60s", "end"):
            ours = [a.text for a in explain(*db.run(copy).state_at(at))]
            theirs = [a.text for a in explain(*db.run(tmp_path / "k.mcap").state_at(at))]
            assert theirs == ours


def test_exported_tree_xml_reads_back_with_bt_cpp_uids() -> None:
    tree = open_recording(KITTING_RUN).tree
    back = tree_from_log_xml(tree_xml(tree), "export")
    assert [(n.uid, n.type, n.name, n.scope) for n in back] == [
        (n.uid, n.type, n.name, n.scope) for n in tree
    ]


def test_export_refuses_a_run_whose_tree_changed(tmp_path: Path) -> None:
    result = btlog(
        "export", str(ROOT / "recordings" / "kitting-can-you.mcap"), "--to", "btlog", "x.btlog"
    )
    assert_bad_input(result, "tree changed")
    assert not (tmp_path / "x.btlog").exists()


# -- SQLite sessions -------------------------------------------------------------------------
def _sqlite_from(btlog_file: Path, db: Path, sessions: int) -> None:
    """A SqliteLogger file with the tables and columns BT.CPP creates, holding the run of
    ``btlog_file`` ``sessions`` times (as ``append`` does)."""
    log = read_filelog(btlog_file)
    con = sqlite3.connect(db)
    con.executescript(
        "CREATE TABLE Transitions (timestamp INTEGER PRIMARY KEY NOT NULL, "
        "session_id INTEGER NOT NULL, node_uid INTEGER NOT NULL, duration INTEGER, "
        "state INTEGER NOT NULL, extra_data VARCHAR);"
        "CREATE TABLE Nodes (session_id INTEGER NOT NULL, fullpath VARCHAR, "
        "node_uid INTEGER NOT NULL);"
        "CREATE TABLE Definitions (session_id INTEGER PRIMARY KEY AUTOINCREMENT, "
        "date TEXT NOT NULL, xml_tree TEXT NOT NULL);"
    )
    tree = tree_from_log_xml(log.xml, "x")
    last = 0
    for session in range(1, sessions + 1):
        con.execute(
            "INSERT INTO Definitions (date, xml_tree) VALUES (?, ?)",
            ("2026-11-30 12:00:00", log.xml.decode()),
        )
        con.executemany(
            "INSERT INTO Nodes VALUES (?, ?, ?)", [(session, n.path, n.uid) for n in tree]
        )
        base = log.start_us + session * 10_000_000
        for t_us, uid, status in log.transitions():
            last = max(last + 1, base + t_us)
            extra = f"s{session}" if uid == 1 else ""
            con.execute(
                "INSERT INTO Transitions VALUES (?, ?, ?, 0, ?, ?)",
                (last, session, uid, int(status), extra),
            )
    con.commit()
    con.close()


def test_sqlite_sessions_import_one_recording_each(tmp_path: Path) -> None:
    exported = tmp_path / "k.btlog"
    export_filelog(open_recording(KITTING_RUN), exported)
    db = tmp_path / "robot.db3"
    _sqlite_from(exported, db, sessions=2)
    result = btlog("import", str(db), "-o", str(tmp_path / "run.mcap"))
    assert result.returncode == 0, result.stderr
    assert not result.stderr  # the Nodes paths agree with the tree
    first, second = tmp_path / "run-session1.mcap", tmp_path / "run-session2.mcap"
    statuses = [r[2:] for r in _transitions(KITTING_RUN)]
    assert [r[2:] for r in _transitions(first)] == statuses
    assert [r[2:] for r in _transitions(second)] == statuses
    recording = open_recording(second)
    assert recording.metadata["source"]["session"] == 2
    extra = [e for e in recording.events if not isinstance(e, StatusChange)]
    assert extra and {e.value for e in extra} == {"s2"}
    assert {e.scope for e in extra} == {"btcpp.extra_data"}
    only = btlog("import", str(db), "--session", "2", "-o", str(tmp_path / "two.mcap"))
    assert only.returncode == 0 and (tmp_path / "two.mcap").exists()
    assert_bad_input(btlog("import", str(db), "--session", "7"), "no session 7")


# -- bad input -------------------------------------------------------------------------------
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path) -> None:
    wrong = tmp_path / "wrong.btlog"
    wrong.write_bytes(b"BTCPP3-FileLogger\x01" + b"\0" * 40)
    assert_bad_input(btlog("import", str(wrong)), "not a BT.CPP log")
    empty_db = tmp_path / "other.db3"
    sqlite3.connect(empty_db).execute("CREATE TABLE Something (x)").connection.close()
    assert_bad_input(btlog("import", str(empty_db)), "no table Definitions")
    exported = tmp_path / "k.btlog"
    export_filelog(open_recording(KITTING_RUN), exported)
    mismatch = btlog("import", str(exported), "--tree", str(ROOT / "trees" / "taxi.xml"))
    assert_bad_input(mismatch, "not the tree of this log")
    assert not Path(ROOT / "k.mcap").exists()
    header_only = tmp_path / "h.btlog"
    header_only.write_bytes(exported.read_bytes()[:30])
    assert_bad_input(btlog("import", str(header_only)), "does not fit")


def test_import_with_the_users_tree_file(tmp_path: Path) -> None:
    exported = tmp_path / "k.btlog"
    export_filelog(open_recording(KITTING_RUN), exported)
    out = tmp_path / "k.mcap"
    result = btlog(
        "import", str(exported), "--tree", str(ROOT / "trees" / "kitting.xml"), "-o", str(out)
    )
    assert result.returncode == 0, result.stderr
    assert open_recording(out).tree.lookup("look at chuck")[0].line > 0  # from the user's file


@pytest.mark.parametrize("seed", range(6000, 6020))
def test_random_trees_survive_export_and_import(tmp_path: Path, seed: int) -> None:
    """Every built-in node, subtrees with remapping, pre/post conditions: a btlog run of a
    random tree, exported to FileLogger2 and imported, has the same tree and transitions."""
    case = generate(seed)
    tree_file = tmp_path / "t.xml"
    tree_file.write_text(case.xml)
    config = RunConfig(tree=str(tree_file), outcomes=case.outcomes, max_ticks=case.max_ticks)
    run = execute(config, tmp_path / "run.mcap").path
    export_filelog(open_recording(run), tmp_path / "run.btlog")
    import_filelog(tmp_path / "run.btlog", tmp_path / "back.mcap")
    original, back = open_recording(run), open_recording(tmp_path / "back.mcap")

    def shape(tree) -> list[tuple]:
        return [(n.uid, n.kind, n.type, n.name, n.path, n.scope, n.ports) for n in tree]

    assert shape(back.tree) == shape(original.tree)
    assert [r[2:] for r in _transitions(tmp_path / "back.mcap")] == [
        r[2:] for r in _transitions(run)
    ]

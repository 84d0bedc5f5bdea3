"""BT.CPP's own logs imported into btlog recordings, checked against BT.CPP itself.

Random trees with scripted leaves run in BehaviorTree.CPP (behaviortreepy) with its
``FileLogger2`` and ``StdCoutLogger``; the ``.btlog`` is imported and its transitions must
equal the ``StdCoutLogger`` stream and btlog's own run of the same tree and outcomes.
"""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from btlog.explain.questions import explain
from btlog.record.reader import open_recording
from btlog.runner import RunConfig, execute
from btlog.sources.btcpp_filelog import import_filelog, read_filelog
from btlog.sources.btcpp_tree import tree_from_log_xml
from btlog.state import StateProjection
from btlog.tree.loader import load_tree_text
from btlog.tree.model import CONDITION
from btlog.tree.registry import NodeType, Registry
from tests.cli_support import btlog as cli
from tests.oracle.random_trees import generate
from tests.oracle.runner import have_behaviortreepy, run_oracle, tick_boundaries
from tests.test_differential import btlog_transitions

CASES = int(os.environ.get("BTLOG_IMPORT_CASES", "30"))
TICK_SLEEP_MS = 8  # ticks this far apart in time, so the tick rule can find them
TICK_GAP_NS = 3_000_000
needs_btcpp = pytest.mark.skipif(not have_behaviortreepy(), reason="behaviortreepy missing")


def _btcpp_run(seed: int, folder: Path) -> tuple[object, dict | None, Path]:
    case = generate(seed)
    log = folder / f"case{seed}.btlog"
    payload = {**dataclasses.asdict(case), "file_log": str(log), "tick_sleep_ms": TICK_SLEEP_MS}
    return case, run_oracle(payload), log


@pytest.fixture(scope="module")
def btcpp_logs(tmp_path_factory) -> list[tuple[object, dict, Path]]:
    """(case, BT.CPP's StdCoutLogger result, its FileLogger2 file) for each random tree."""
    if not have_behaviortreepy():
        pytest.skip("behaviortreepy missing")
    folder = tmp_path_factory.mktemp("btcpp-logs")
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(lambda s: _btcpp_run(s, folder), range(5000, 5000 + CASES)))
    return [(c, r, p) for c, r, p in runs if r is not None and not r.get("error")]


def _imported(log: Path, out: Path) -> tuple[list[list], object]:
    result = import_filelog(log, out, tick_gap_ns=TICK_GAP_NS)
    assert not result.warnings, result.warnings
    recording = open_recording(out)
    names = {n.uid: n.name for n in recording.tree}
    rows = [
        [e.tick, names[e.uid], e.prev.name, e.status.name]
        for e in recording.events
        if hasattr(e, "uid")
    ]
    return rows, recording


@needs_btcpp
def test_imported_filelogger2_equals_btcpp_stream_and_btlog_run(btcpp_logs, tmp_path) -> None:
    assert len(btcpp_logs) >= CASES * 0.9
    ticks = splits = 0
    for case, result, log in btcpp_logs:
        rows, recording = _imported(log, tmp_path / f"{log.stem}.mcap")
        theirs = result["transitions"]
        assert [r[1:] for r in rows] == [t[1:] for t in theirs], f"seed {case.seed}"
        assert [r[1:] for r in rows] == [t[1:] for t in btlog_transitions(case)]
        # Ticks are TICK_SLEEP_MS apart, more than the gap: every real tick is found. A
        # process preempted mid-tick on a loaded machine may split a tick in two.
        inferred, real = tick_boundaries(rows), tick_boundaries(theirs)
        assert real <= inferred, f"seed {case.seed}: a tick was not found"
        ticks, splits = ticks + len(real), splits + len(inferred - real)
        assert recording.metadata["source"]["format"] == "btcpp-filelog2"
        assert len(recording.metadata["source"]["sha256"]) == 64
    print(f"import differential: {len(btcpp_logs)} runs, {ticks} ticks, {splits} split")
    assert splits <= 2 + ticks // 20


@needs_btcpp
def test_embedded_tree_equals_btlog_load_of_the_same_xml(btcpp_logs) -> None:
    registry = Registry()
    registry.register(NodeType("ScriptedCondition", CONDITION, declared_only=True))

    def shape(tree) -> list[tuple]:
        return [(n.uid, n.kind, n.type, n.name, n.path, n.scope) for n in tree]

    for case, _result, log in btcpp_logs:
        parsed = read_filelog(log)
        ours = load_tree_text(case.xml, registry)
        theirs = tree_from_log_xml(parsed.xml, str(log))
        assert shape(theirs) == shape(ours), f"seed {case.seed}"


@needs_btcpp
def test_truncated_btlog_imports_whole_records_with_a_warning(btcpp_logs, tmp_path) -> None:
    _case, _result, log = max(btcpp_logs, key=lambda item: item[2].stat().st_size)
    data = log.read_bytes()
    cut = tmp_path / "cut.btlog"
    cut.write_bytes(data[:-4])
    whole = len(read_filelog(log))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "btlog.cli.main",
            "import",
            str(cut),
            "-o",
            str(tmp_path / "c.mcap"),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "ends inside a record" in proc.stderr
    assert f"{whole - 1} transitions" in proc.stdout
    assert len(open_recording(tmp_path / "c.mcap").events) == whole - 1


def _kitting_for_btcpp() -> tuple[str, dict[str, list[str]]]:
    """The kitting tree as a BT.CPP process can run it with scripted leaves: leaf types
    without spaces (BT.CPP writes types as XML tags) and without ports (behaviortreepy
    registers leaves without ports). Names, and so the explanations, are unchanged."""
    xml = (Path(__file__).resolve().parent.parent / "trees" / "kitting.xml").read_text()
    ids: dict[str, set[str]] = {"actions": set(), "conditions": set()}

    def leaf(match: re.Match) -> str:
        tag, type_id, rest = match.groups()
        ids["actions" if tag == "Action" else "conditions"].add(type_id.replace(" ", "_"))
        rest = re.sub(r'\s(?!name=)[A-Za-z_]+="[^"]*"', "", rest)
        return f'<{tag} ID="{type_id.replace(" ", "_")}"{rest}'

    xml = re.sub(r'<(Action|Condition) ID="([^"]+)"([^>]*)', leaf, xml)
    return xml, {kind: sorted(types) for kind, types in ids.items()}


KITTING_OUTCOMES = {
    "default": {"status": "SUCCESS", "ticks": 1},
    "nodes": {
        "look at chuck": [{"status": "FAILURE", "ticks": 1}, {"status": "SUCCESS", "ticks": 1}]
    },
}


@pytest.fixture(scope="module")
def kitting_btlog(tmp_path_factory) -> tuple[Path, Path]:
    """BT.CPP's FileLogger2 log of the kitting tree ("look at chuck" fails once), and the
    tree file it ran."""
    if not have_behaviortreepy():
        pytest.skip("behaviortreepy missing")
    folder = tmp_path_factory.mktemp("kitting")
    xml, leaf_ids = _kitting_for_btcpp()
    log, tree_file = folder / "robot.btlog", folder / "kitting.xml"
    tree_file.write_text(xml)
    payload = {"xml": xml, "outcomes": KITTING_OUTCOMES, "max_ticks": 500, "file_log": str(log)}
    payload |= {"tick_sleep_ms": TICK_SLEEP_MS, "leaf_ids": leaf_ids}
    result = run_oracle(payload, 60)
    assert result is not None and not result["error"], result
    return log, tree_file


def test_explanations_on_imported_kitting_run_equal_btlogs_own(kitting_btlog, tmp_path) -> None:
    log, tree_file = kitting_btlog
    import_filelog(log, tmp_path / "imported.mcap", tick_gap_ns=TICK_GAP_NS)
    execute(RunConfig(tree=str(tree_file), outcomes=KITTING_OUTCOMES), tmp_path / "own.mcap")
    imported, own = (
        open_recording(tmp_path / "imported.mcap"),
        open_recording(tmp_path / "own.mcap"),
    )
    assert len(imported.events) == len(own.events) > 200
    folds = StateProjection(imported.tree), StateProjection(own.tree)
    failures = 0
    for theirs, ours in zip(imported.events, own.events, strict=True):
        folds[0].apply(theirs)
        folds[1].apply(ours)
        answers = [[a.text for a in explain(f.tree, f.state)] for f in folds]
        assert answers[0] == answers[1], f"after event {ours.seq}"
        failures += "look at chuck failed" in answers[1][-1]
    assert failures > 0  # the failure was explained, in both


def test_readme_three_commands_on_a_btcpp_log(kitting_btlog, tmp_path) -> None:
    log, _tree = kitting_btlog
    run = str(tmp_path / "robot.mcap")
    imported = cli("import", str(log), "-o", run)
    assert imported.returncode == 0, imported.stderr
    failed = cli("timeline", run, "--status", "FAILURE", "--plain")
    lines = failed.stdout.splitlines()
    assert "look at chuck" in lines[0]
    seq = lines[-1].split()[0]  # the failure as far as it went
    asked = cli("ask", run, "--at", f"seq:{seq}", "What went wrong?")
    assert asked.stdout.strip().endswith("because look at chuck failed."), asked.stdout


def test_imported_run_works_with_diff_check_sql_and_show(kitting_btlog, tmp_path) -> None:
    log, tree_file = kitting_btlog
    run, own = tmp_path / "robot.mcap", tmp_path / "own.mcap"
    import_filelog(log, run, tick_gap_ns=TICK_GAP_NS)
    execute(RunConfig(tree=str(tree_file), outcomes=KITTING_OUTCOMES), own)
    diff = cli("diff", str(own), str(run), "--plain")
    assert diff.returncode == 0, diff.stdout + diff.stderr
    expect = tmp_path / "robot.expect.yaml"
    expect.write_text(
        "final_status: SUCCESS\n"
        "answers:\n"
        '  - {at: "seq:47", ask: "What went wrong?", answer: "I am retrying for attempt 1 to '
        'go insert large gear. I could not insert large gear because look at chuck failed."}\n'
        "statuses:\n"
        '  - {at: "seq:31", node: "look at chuck", status: FAILURE}\n'
    )
    check = cli("check", str(run), "--expect", str(expect))
    assert check.returncode == 0, check.stdout + check.stderr
    sql = cli("sql", str(run), "SELECT count(*) AS n FROM transitions", "--format", "csv")
    assert sql.stdout.split() == ["n", str(len(open_recording(run).events))]
    shown = cli("show", str(run), "--at", "seq:47", "--blackboard", "--plain")
    assert "the blackboard was not recorded: btcpp-filelog2" in shown.stdout

"""The read model (design §5) and the state at any moment (§6), from real recordings.

Runs are executed with scripted outcomes and recorded by the real ``Recorder`` into MCAP
files; ``open_runs`` ingests them into a real DuckDB. The central property: for random
outcomes on the paper's kitting tree and on the taxi tree, the state rebuilt from the
database after *every* event equals the live ``StateProjection`` state at that event,
and every node's status equals the executor's own at every tick boundary — with
snapshots every 7 events, so that snapshot + tail is what is exercised. Then: the
tables and columns, every moment form and its errors, several runs in one database, a
cut recording, the cache, mutations, blackboard values, and the slow decoding path.
"""

from __future__ import annotations

import json
import shutil
import struct
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import EventLog, Subscriber, TickRecord
from btlog.executor.engine import Executor
from btlog.explain.questions import answer
from btlog.record import columns
from btlog.record import format as fmt
from btlog.record.reader import RecordingError, iter_messages, open_recording, read_metadata
from btlog.record.recorder import Recorder
from btlog.replay.database import ReplayError, open_runs
from btlog.replay.moments import MomentError, parse_moment
from btlog.replay.scan import McapScan
from btlog.status import FAILURE, IDLE, RUNNING, SUCCESS
from btlog.tree.loader import load_tree
from tests.mcap_support import (
    rewrite_as_version_2,
    stored_metadata,
    version_2_payload,
    write_messages,
)

ROOT = Path(__file__).resolve().parent.parent
KITTING = ROOT / "trees" / "kitting.xml"
TAXI = ROOT / "trees" / "taxi.xml"
DEFAULT = {"status": "SUCCESS", "ticks": 1}


# -- recording runs ---------------------------------------------------------------------------
def canonical(state) -> dict:
    """A state as the JSON a recording can hold (tuples become lists, …)."""
    return orjson.loads(orjson.dumps(state.to_json(), default=repr))


@dataclass
class Live:
    """What the executor and the live projection said during a recorded run."""

    states: list[dict] = field(default_factory=list)  # after event seq, by seq
    statuses: list[dict] = field(default_factory=list)  # the executor's, after event seq
    ticks: list[tuple[int, dict]] = field(default_factory=list)  # (events, statuses)
    shapes: dict[int, dict] = field(default_factory=dict)  # events → tree, at mutations
    log: EventLog = field(default_factory=EventLog)


class Capture(Subscriber):
    """Keeps the live state and the executor's own statuses after each event and each
    tick (subscribed after the projection, so it sees the state with the event applied;
    the executor sets a status before it reports it)."""

    def __init__(self, projection, executor: Executor, live: Live) -> None:
        self.projection, self.executor, self.live = projection, executor, live

    def _event(self, *_args) -> None:
        self.live.states.append(canonical(self.projection.state))
        self.live.statuses.append(dict(self.executor.statuses()))

    on_status = on_write = _event

    def on_mutation(self, mutation) -> None:
        self._event()
        self.live.shapes[mutation.seq + 1] = self.projection.tree.describe()

    def on_tick(self, record: TickRecord) -> None:
        self.live.ticks.append((self.executor.seq, dict(self.executor.statuses())))


def record(
    path: Path,
    tree_file: Path,
    outcomes: dict,
    max_ticks: int,
    flush_interval: float = 1.0,
    mutate_at: int | None = None,
) -> Live:
    """Run ``tree_file`` with ``outcomes`` into the recording ``path``."""
    from btlog.state import StateProjection

    tree = load_tree(tree_file)
    executor = Executor(
        tree, leaf_factory=scripted_leaf_factory(tree, Outcomes.from_mapping(outcomes))
    )
    projection, live = StateProjection(tree), Live()
    recorder = Recorder(
        path, tree, {"domain": "scripted", "seed": 5}, flush_interval=flush_interval
    )
    for subscriber in (recorder, projection, Capture(projection, executor, live), live.log):
        executor.subscribe(subscriber)

    def before_tick(ex: Executor) -> None:
        if ex.runtime.tick + 1 == mutate_at:
            plan = answer(projection.tree, projection.state, "Can you detect chuck?").insertion
            ex.insert_after(
                plan.parent.uid,
                plan.after.uid,
                ex.tree.node(plan.source.uid),
                "Can you detect chuck?",
            )

    executor.run(max_ticks, before_tick)
    executor.close()
    return live


def assert_replay_equals_live(run, live: Live, events: int | None = None) -> None:
    """The rebuilt state after every event equals the live one, and its statuses the
    executor's own, there and at every tick boundary; the tree's shape equals the live
    one at mutations."""
    events = len(live.states) if events is None else events
    assert run.info.events == events
    for count in range(1, events + 1):
        tree, state = run.state_after(count)
        assert state.seq == count
        assert canonical(state) == live.states[count - 1], f"state after {count} events"
        statuses = live.statuses[count - 1]
        assert {uid: state.status_of(uid) for uid in statuses} == statuses
        if count in live.shapes:
            assert tree.describe() == live.shapes[count]
    for count, statuses in live.ticks:
        if count <= events:
            _tree, state = run.state_after(count)
            assert {uid: state.status_of(uid) for uid in statuses} == statuses


@pytest.fixture(scope="module")
def kitting(tmp_path_factory) -> tuple[Path, Live]:
    """A kitting run with failures, a retry and a fallback, recorded once."""
    path = tmp_path_factory.mktemp("kitting") / "kitting.mcap"
    live = record(
        path,
        KITTING,
        {
            "default": DEFAULT,
            "nodes": {
                "look at chuck": ["FAILURE", "SUCCESS"],
                "detect chuck": [{"status": "FAILURE", "ticks": 2}, "SUCCESS"],
                "trial and error insert": ["FAILURE", "FAILURE", "SUCCESS"],
            },
        },
        max_ticks=150,
    )
    return path, live


# -- the property -----------------------------------------------------------------------------
def leaf_keys(tree_file: Path) -> list[str]:
    """Outcomes keys of a tree's execution nodes: names, or types of nameless ones."""
    return sorted({n.name or n.type for n in load_tree(tree_file) if n.is_execution})


entry = st.fixed_dictionaries(
    {"status": st.sampled_from(["SUCCESS", "FAILURE"]), "ticks": st.integers(0, 3)}
)
PROPERTY = settings(
    max_examples=6,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def scripts_for(tree_file: Path):
    return st.dictionaries(
        st.sampled_from(leaf_keys(tree_file)), st.lists(entry, min_size=1, max_size=3), max_size=6
    )


@PROPERTY
@given(scripts=scripts_for(KITTING), default_ticks=st.integers(0, 2))
def test_kitting_state_at_every_seq_equals_the_live_state(tmp_path_factory, scripts, default_ticks):
    path = tmp_path_factory.mktemp("prop") / "run.mcap"
    live = record(
        path,
        KITTING,
        {"default": {"status": "SUCCESS", "ticks": default_ticks}, "nodes": scripts},
        max_ticks=120,
    )
    with open_runs(path, cache=False, snapshot_every=7) as database:
        assert_replay_equals_live(database.run(), live)


@PROPERTY
@given(scripts=scripts_for(TAXI))
def test_taxi_state_at_every_seq_equals_the_live_state(tmp_path_factory, scripts):
    path = tmp_path_factory.mktemp("prop") / "run.mcap"
    live = record(path, TAXI, {"default": DEFAULT, "nodes": scripts}, max_ticks=80)
    with open_runs(path, cache=False, snapshot_every=7) as database:
        assert_replay_equals_live(database.run(), live)


def test_cached_database_gives_the_same_states(kitting, tmp_path):
    path, live = kitting
    with open_runs(path, cache_dir=tmp_path, snapshot_every=16) as database:
        assert_replay_equals_live(database.run(), live)


# -- the tables -------------------------------------------------------------------------------
SECTION_5 = {
    "runs": [
        "run_id",
        "file",
        "tree_name",
        "started_at",
        "duration_ns",
        "final_status",
        "domain",
        "seed",
        "metadata",
    ],
    "nodes": [
        "run_id",
        "uid",
        "parent_uid",
        "idx",
        "depth",
        "kind",
        "type",
        "name",
        "path",
        "ports",
        "added_seq",
    ],
    "transitions": ["run_id", "seq", "t_ns", "tick", "uid", "prev_status", "status"],
    "blackboard": ["run_id", "seq", "t_ns", "tick", "scope", "key", "value", "type", "writer_uid"],
    "ticks": ["run_id", "tick", "start_ns", "end_ns", "root_status", "teardown"],
    "mutations": [
        "run_id",
        "seq",
        "t_ns",
        "op",
        "parent_uid",
        "after_uid",
        "inserted_root_uid",
        "question",
    ],
}
STATUS_ENUM = "ENUM('IDLE', 'RUNNING', 'SUCCESS', 'FAILURE', 'SKIPPED')"


@pytest.mark.parametrize("cache", [True, False])
def test_tables_and_columns_are_those_of_section_5(kitting, tmp_path, cache):
    path, _live = kitting
    with open_runs(path, cache=cache, cache_dir=tmp_path) as database:
        _columns, rows = database.sql(
            "SELECT table_name, column_name, data_type FROM information_schema.columns "
            "WHERE table_catalog = current_database() AND table_schema = 'main' "
            "ORDER BY table_name, ordinal_position"
        )
    found: dict[str, list[str]] = {}
    types = {}
    for table, column, data_type in rows:
        found.setdefault(table, []).append(column)
        types[table, column] = data_type
    assert found == SECTION_5
    for table, column in [
        ("transitions", "prev_status"),
        ("transitions", "status"),
        ("ticks", "root_status"),
        ("runs", "final_status"),
    ]:
        assert types[table, column] == STATUS_ENUM
    for table, column in [
        ("transitions", "t_ns"),
        ("blackboard", "t_ns"),
        ("ticks", "start_ns"),
        ("ticks", "end_ns"),
        ("mutations", "t_ns"),
        ("runs", "duration_ns"),
        ("transitions", "seq"),
    ]:
        assert types[table, column] == "BIGINT"
    for table, column in [("runs", "metadata"), ("nodes", "ports"), ("blackboard", "value")]:
        assert types[table, column] == "JSON"


def test_tables_hold_the_run(kitting, tmp_path):
    path, live = kitting
    transitions = live.log.transitions
    with open_runs(path, cache_dir=tmp_path) as database:
        run = database.run()
        _c, rows = database.sql(
            "SELECT seq, t_ns, tick, uid, prev_status, status FROM transitions ORDER BY seq"
        )
        assert rows == [
            (e.seq, e.t_ns, e.tick, e.uid, e.prev.name, e.status.name) for e in transitions
        ]
        _c, ticks = database.sql(
            "SELECT tick, start_ns, end_ns, root_status, teardown FROM ticks ORDER BY tick"
        )
        assert ticks == [
            (t.tick, t.start_ns, t.end_ns, t.root_status.name, t.teardown) for t in live.log.ticks
        ]
        assert [t[-1] for t in ticks[-2:]] == [False, True]
        _c, [(final, duration, domain, seed, tree_name)] = database.sql(
            "SELECT final_status, duration_ns, domain, seed, tree_name FROM runs"
        )
        assert final == live.log.ticks[-2].root_status.name  # the teardown's is IDLE
        assert duration == max(live.log.ticks[-1].end_ns, transitions[-1].t_ns)
        assert (domain, seed, tree_name) == ("scripted", 5, "MainTree")
        _c, nodes = database.sql(
            "SELECT uid, parent_uid, idx, depth, kind, type, name, path, "
            "added_seq FROM nodes ORDER BY uid"
        )
        assert nodes == [
            (
                n.uid,
                None if n.parent is None else n.parent.uid,
                n.index,
                n.depth,
                n.kind,
                n.type,
                n.name,
                n.path,
                None,
            )
            for n in run.tree
        ]
        assert run.info.run_id == run.info.metadata["run_id"][:8]


# -- moments ----------------------------------------------------------------------------------
def events_up_to(live: Live, predicate) -> int:
    """How many events (a prefix, since times and ticks never decrease) satisfy it."""
    return sum(1 for e in live.log.events if predicate(e))


def test_every_moment_form(kitting, tmp_path):
    path, live = kitting
    events = live.log.events
    duration = max(live.log.ticks[-1].end_ns, events[-1].t_ns)
    with open_runs(path, cache_dir=tmp_path) as database:
        run = database.run()
        started = datetime.fromisoformat(run.info.metadata["started_at"])
        middle = duration // 2 + 1234
        cases = {
            f"{middle / 1e9:.9f}": middle,
            f"{middle / 1e9:.9f}s": middle,
            f"{middle / 1e6:.6f}ms": middle,
            f"{middle / 1e3:.3f}us": middle,
            f"{middle}ns": middle,
            "1500ms": 1_500_000_000,
            "2": 2_000_000_000,
            "0": 0,
            "-2s": duration - 2_000_000_000,
            "-0s": duration,
            (started + timedelta(microseconds=middle // 1000)).isoformat(): middle // 1000 * 1000,
            (started + timedelta(seconds=3)).astimezone(UTC).isoformat(): 3_000_000_000,
            (started + timedelta(seconds=3))
            .astimezone(UTC)
            .replace(tzinfo=None)
            .isoformat(): 3_000_000_000,
        }
        for text, t_ns in cases.items():
            resolved = run.resolve(text)
            assert resolved.count == events_up_to(live, lambda e, t=t_ns: e.t_ns <= t), text
            assert resolved.t_ns == t_ns, text
        for n in (0, 1, 7, len(live.log.ticks) // 2, len(live.log.ticks)):
            assert run.resolve(f"tick:{n}").count == events_up_to(live, lambda e, n=n: e.tick <= n)
        for n in (0, 5, len(events) - 1):
            resolved = run.resolve(f"seq:{n}")
            assert (resolved.count, resolved.t_ns) == (n + 1, events[n].t_ns)
        assert run.resolve("end").count == len(events)
        assert run.resolve(" END ").count == len(events)
        _tree, state = run.state_at("tick:10")
        assert state.tick == 10 and state.seq == run.resolve("tick:10").count


@pytest.mark.parametrize(
    ("moment", "message"),
    [
        ("99s", "moment '99s' is after the end of the run ({seconds} s)"),
        ("-99s", "moment '-99s' is before the start of the run (it lasts {seconds} s)"),
        ("tick:999", "moment 'tick:999' is after the end of the run (last tick {ticks})"),
        ("seq:99999", "moment 'seq:99999' is after the end of the run (last event seq:{last})"),
        (
            "1999-01-01T00:00:00+00:00",
            "moment '1999-01-01T00:00:00+00:00' is before the start of the run (",
        ),
        ("abc", "unparseable moment 'abc': expected seconds"),
        ("12 parsecs", "unparseable moment '12 parsecs'"),
        ("tick:-1", "unparseable moment 'tick:-1'"),
        ("seq:x", "unparseable moment 'seq:x'"),
        ("2025-13-45T00:00:00", "unparseable moment '2025-13-45T00:00:00': not a valid ISO-8601"),
    ],
)
def test_moments_outside_the_run_or_unreadable_are_clear_errors(kitting, tmp_path, moment, message):
    path, live = kitting
    with open_runs(path, cache_dir=tmp_path) as database:
        run = database.run()
        with pytest.raises(MomentError) as raised:
            run.state_at(moment)
    duration = max(live.log.ticks[-1].end_ns, live.log.events[-1].t_ns)
    expected = message.format(
        seconds=f"{duration / 1e9:.6g}", ticks=len(live.log.ticks), last=len(live.log.events) - 1
    )
    assert expected in str(raised.value)
    assert "\n" not in str(raised.value)
    assert isinstance(raised.value, ValueError)


def test_moment_parsing_units():
    assert parse_moment("12.5").value == parse_moment("12.5s").value == 12_500_000_000
    assert parse_moment("1500ms").value == 1_500_000_000
    assert parse_moment("250us").value == parse_moment("250µs").value == 250_000
    assert parse_moment("100ns").value == 100
    assert parse_moment("0.000000001s").value == 1
    assert (parse_moment("-2s").kind, parse_moment("-2s").value) == ("before_end", 2 * 10**9)
    assert (parse_moment("tick:4").kind, parse_moment("seq:9").value) == ("tick", 9)
    assert parse_moment("2025-01-02T03:04:05Z").naive is False
    assert parse_moment("2025-01-02T03:04:05").naive is True
    with pytest.raises(MomentError, match="unparseable moment ''"):
        parse_moment("")


# -- several runs -----------------------------------------------------------------------------
def test_two_runs_share_one_database(kitting, tmp_path):
    kitting_path, kitting_live = kitting
    taxi_path = tmp_path / "taxi.mcap"
    taxi_live = record(taxi_path, TAXI, {"default": DEFAULT}, max_ticks=60)
    with open_runs(kitting_path, taxi_path, cache_dir=tmp_path) as database:
        ids = [info.run_id for info in database.runs]
        assert len(set(ids)) == 2
        _c, counts = database.sql(
            "SELECT run_id, count(*) FROM transitions GROUP BY run_id ORDER BY run_id"
        )
        expected = {
            ids[0]: len(kitting_live.log.transitions),
            ids[1]: len(taxi_live.log.transitions),
        }
        assert dict(counts) == expected
        _c, [(n,)] = database.sql("SELECT count(*) FROM transitions WHERE run_id = ?", [ids[1]])
        assert n == len(taxi_live.log.transitions)
        for table in SECTION_5:
            _c, rows = database.sql(f"SELECT DISTINCT run_id FROM {table} ORDER BY 1")
            assert {r[0] for r in rows} <= set(ids)
        assert database.run(taxi_path) is database.run(ids[1])
        taxi = database.run(ids[1])
        _tree, state = taxi.state_at("end")
        assert canonical(state) == taxi_live.states[-1]
        _tree, state = database.run(ids[0]).state_at("seq:40")
        assert canonical(state) == kitting_live.states[40]
        with pytest.raises(ReplayError, match="no run 'nope'"):
            database.run("nope")
        with pytest.raises(ReplayError, match="2 runs are open"):
            database.run()


def test_the_same_run_twice_gets_distinct_ids(kitting, tmp_path):
    path, _live = kitting
    copy = tmp_path / "copy.mcap"
    shutil.copyfile(path, copy)
    with open_runs(path, copy, cache_dir=tmp_path) as database:
        first, second = (info.run_id for info in database.runs)
        assert second == f"{first}_2"
        _c, rows = database.sql("SELECT run_id, count(*) FROM runs GROUP BY 1 ORDER BY 1")
        assert rows == [(first, 1), (second, 1)]


# -- cut recordings ---------------------------------------------------------------------------
def data_end(data: bytes) -> int:
    """The offset of an MCAP file's data end record (its summary follows)."""
    position = 8
    while True:
        opcode, length = struct.unpack_from("<BQ", data, position)
        if opcode == 0x0F:
            return position
        position += 9 + length


def test_a_truncated_recording_ingests_its_readable_prefix(tmp_path):
    whole = tmp_path / "whole.mcap"
    live = record(
        whole,
        KITTING,
        {"default": DEFAULT, "nodes": {"look at chuck": ["FAILURE", "SUCCESS"]}},
        max_ticks=100,
        flush_interval=0,
    )
    data = whole.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: data_end(data) * 6 // 10])
    with open_runs(cut, cache_dir=tmp_path, snapshot_every=5) as database:
        run = database.run()
        events = run.info.events
        assert run.info.truncated
        assert 0 < events < len(live.states)
        assert any("truncated" in w for w in run.info.warnings)
        assert_replay_equals_live(run, live, events)
        _c, [(count, last)] = database.sql("SELECT count(*), max(seq) FROM transitions")
        assert last < events and count == sum(1 for e in live.log.transitions if e.seq < events)
        with pytest.raises(MomentError, match="after the end of the run"):
            run.state_at(f"seq:{events}")


# -- the cache --------------------------------------------------------------------------------
def test_without_cache_nothing_is_written(kitting, tmp_path):
    original, live = kitting
    path = tmp_path / "run.mcap"
    shutil.copyfile(original, path)
    with open_runs(path, cache=False) as database:
        assert database.run().info.events == len(live.states)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]


# -- mutations, values, decoding --------------------------------------------------------------
def test_a_mutation_changes_the_tree_from_its_seq_on(tmp_path):
    path = tmp_path / "mutated.mcap"
    live = record(path, KITTING, {"default": DEFAULT}, max_ticks=60, mutate_at=30)
    [count] = live.shapes
    with open_runs(path, cache_dir=tmp_path, snapshot_every=9) as database:
        run = database.run()
        assert_replay_equals_live(run, live)
        before, after = run.state_after(count - 1)[0], run.tree_at(f"seq:{count - 1}")
        assert len(after) > len(before) == len(run.tree)
        _c, [(seq, op, question, root)] = database.sql(
            "SELECT seq, op, question, inserted_root_uid FROM mutations"
        )
        assert (seq, op, question) == (count - 1, "insert", "Can you detect chuck?")
        _c, added = database.sql(
            "SELECT uid, added_seq, depth FROM nodes WHERE added_seq IS NOT NULL ORDER BY uid"
        )
        assert [uid for uid, _s, _d in added] == sorted(
            n.uid for n in after if n.uid not in before.nodes
        )
        assert {s for _u, s, _d in added} == {seq}
        assert added[0][0] == root and added[0][2] == after.node(root).depth
        kinds = [e.kind for e in run.timeline(start=f"seq:{seq}", end=f"seq:{seq}")]
        assert kinds == ["mutation"]


TRICKY = [
    0,
    -1,
    2**62,
    1.5,
    1e-300,
    "",
    "a\nb",
    '"],"writes":[',
    "],[",
    "é ü 漢",
    {"tick": 1, "status": [[1, 2]], "writes": []},
    [1, [2, [3]]],
    None,
    True,
    {"nested": {"]}": '{"tick":'}},
]


def test_blackboard_values_round_trip(tmp_path):
    from btlog.tree.loader import load_tree_text

    tree = load_tree_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M">'
        '<AlwaysSuccess name="writer"/></BehaviorTree></root>'
    )
    path = tmp_path / "values.mcap"
    recorder = Recorder(path, tree, {"domain": "test"})
    log = EventLog()
    for target in (recorder, log):
        for seq, value in enumerate(TRICKY):
            target.on_write(
                seq,
                seq * 10,
                1,
                "scope/x" if seq % 2 else "",
                f"k{seq}",
                value,
                type(value).__name__,
                1,
            )
        target.on_write(len(TRICKY), 999, 1, "", "k0", None, "unset", None)
        target.on_status(len(TRICKY) + 1, 1000, 1, 1, IDLE, SUCCESS)
        target.on_tick(TickRecord(1, 0, 1000, SUCCESS))
    recorder.close()
    with open_runs(path, cache=False, snapshot_every=3) as database:
        _c, rows = database.sql(
            "SELECT seq, scope, key, value, type, writer_uid FROM blackboard ORDER BY seq"
        )
        assert [orjson.loads(r[3]) for r in rows[:-1]] == TRICKY
        assert rows[-1][4] == "unset" and rows[-1][5] is None
        _tree, state = database.run().state_at("end")
    assert state.blackboard == {
        "": {f"k{i}": v for i, v in enumerate(TRICKY) if i % 2 == 0 and i != 0},
        "scope/x": {f"k{i}": v for i, v in enumerate(TRICKY) if i % 2},
    }
    assert [e.seq for e in log.events] == list(range(len(TRICKY) + 2))


def test_a_gap_in_the_seqs_is_reported_and_moments_count_seqs(tmp_path):
    from btlog.tree.loader import load_tree_text

    tree = load_tree_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M">'
        '<AlwaysSuccess name="a"/></BehaviorTree></root>'
    )
    path = tmp_path / "gap.mcap"
    recorder = Recorder(path, tree, {"domain": "test"})
    for seq in (0, 1, 3, 4):  # seq 2 is missing
        recorder.on_status(
            seq,
            seq * 100,
            1,
            1,
            IDLE if seq % 2 == 0 else RUNNING,
            RUNNING if seq % 2 == 0 else SUCCESS,
        )
    recorder.on_tick(TickRecord(1, 0, 400, SUCCESS))
    recorder.close()
    with open_runs(path, cache=False, snapshot_every=2) as database:
        run = database.run()
        assert any("not gap-free" in w for w in run.info.warnings)
        assert run.info.events == 5
        assert run.resolve("250ns").count == 2
        assert run.resolve("300ns").count == 4
        _tree, state = run.state_at("seq:3")
        assert state.seq == 4 and state.status_of(1) is SUCCESS


def write_spaced_recording(source: Path, target: Path) -> None:
    """``source`` rewritten with every message re-encoded with spaces and reordered keys
    (still valid JSON of the same layout), so that only the general decoding reads it."""
    from btlog.record.reader import iter_messages

    metadata = stored_metadata(source) | {"schema_version": "2"}
    messages = []
    for topic, log_time, data in iter_messages(source):
        message = orjson.loads(version_2_payload(topic, data))
        spaced = {k: message[k] for k in reversed(list(message))}
        messages.append((topic, log_time, json.dumps(spaced).encode()))
    write_messages(target, metadata, messages)


def test_rows_that_break_the_format_are_a_replay_error(kitting, tmp_path):
    from btlog.record.reader import iter_messages

    path, _live = kitting
    metadata = stored_metadata(path)
    tree = next(m for m in iter_messages(path) if m[0] == fmt.TREE_TOPIC)
    broken = tmp_path / "broken.mcap"
    write_messages(
        broken,
        metadata | {"schema_version": "2"},
        [tree, (fmt.EVENTS_TOPIC, 1, b'{"tick":1,"status":[[0,0,1]],"writes":[]}')],
    )
    with pytest.raises(ReplayError, match=r"broken\.mcap.*do not follow the btlog format"):
        open_runs(broken, cache=False)


@pytest.mark.parametrize(
    ("payload", "problem"),
    [
        (columns.pack_event_rows(1, [(0, 0, 1, 1, 0, 1)], [])[:-1], "expected 54"),
        (columns.pack_event_rows(1, [(0, 0, 1, 1, 0, 7)], []), "status code 7, not a status"),
        (b"BTzz" + bytes(20), "JSONDecodeError"),  # neither a binary head nor JSON
        (b"BTev", "shorter than its head"),
    ],
)
def test_binary_messages_that_break_the_layout_are_a_replay_error(
    kitting, tmp_path, payload, problem
):
    path, _live = kitting
    tree = next(m for m in iter_messages(path) if m[0] == fmt.TREE_TOPIC)
    broken = write_messages(
        tmp_path / "broken.mcap", stored_metadata(path), [tree, (fmt.EVENTS_TOPIC, 1, payload)]
    )
    with pytest.raises(ReplayError, match=rf"broken\.mcap: .*{problem}"):
        open_runs(broken, cache=False)
    with pytest.raises(RecordingError, match=r"broken\.mcap: a message does not follow"):
        open_recording(broken)


def test_unusual_payloads_are_decoded_by_the_general_path(kitting, tmp_path):
    path, live = kitting
    spaced = tmp_path / "spaced.mcap"
    write_spaced_recording(path, spaced)
    walked = McapScan(str(spaced), lambda batch: None).run()
    assert walked.other_events and walked.other_ticks, "the fast path must not apply"
    with open_runs(spaced, cache=False, snapshot_every=11) as database:
        assert_replay_equals_live(database.run(), live)
        _c, rows = database.sql("SELECT count(*) FROM ticks")
        assert rows == [(len(live.log.ticks),)]


# -- errors, SQL, timeline --------------------------------------------------------------------
def test_unreadable_recordings_are_replay_errors(tmp_path):
    missing = tmp_path / "missing.mcap"
    with pytest.raises(ReplayError, match=r"missing\.mcap"):
        open_runs(missing)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(ReplayError, match=r"junk\.mcap.*not an MCAP file"):
        open_runs(junk)
    with pytest.raises(ReplayError, match="at least one"):
        open_runs()


def test_sql_is_parameterised_and_errors_are_one_line(kitting, tmp_path):
    path, live = kitting
    with open_runs(path, cache_dir=tmp_path) as database:
        columns, rows = database.sql(
            "SELECT uid, status FROM transitions WHERE seq = $seq", {"seq": 3}
        )
        event = live.log.transitions[3]
        assert columns == ["uid", "status"] and rows == [(event.uid, event.status.name)]
        with pytest.raises(ReplayError) as raised:
            database.sql("SELEC nonsense")
        assert str(raised.value).startswith("SQL error:") and "\n" not in str(raised.value)
        with pytest.raises(ReplayError):
            database.sql("DELETE FROM transitions")


def test_timeline_filters_by_node_status_and_moments(kitting, tmp_path):
    path, live = kitting
    with open_runs(path, cache_dir=tmp_path) as database:
        run = database.run()
        tree = run.tree
        [chuck] = tree.lookup("look at chuck")
        entries = run.timeline(node="look at chuck")
        assert [(e.seq, e.status) for e in entries] == [
            (e.seq, e.status.name) for e in live.log.transitions if e.uid == chuck.uid
        ]
        assert {e.node for e in entries} == {"look at chuck"}
        failures = run.timeline(status="failure")
        assert [e.seq for e in failures] == [
            e.seq for e in live.log.transitions if e.status is FAILURE
        ]
        window = run.timeline(start="1s", end="2s")
        assert [e.seq for e in window] == [
            e.seq for e in live.log.events if 1_000_000_000 <= e.t_ns <= 2_000_000_000
        ]
        ticks = run.timeline(start="tick:3", end="tick:4")
        assert [e.seq for e in ticks] == [e.seq for e in live.log.events if 3 <= e.tick <= 4]
        assert run.timeline(status=RUNNING, node=chuck.uid)[0].prev_status == "IDLE"
        with pytest.raises(ReplayError, match="no node"):
            run.timeline(node="no such node")
        with pytest.raises(ReplayError, match="unknown status"):
            run.timeline(status="sleeping")


def test_a_version_2_recording_reads_as_its_version_3_original(kitting, tmp_path):
    """Recordings written before the binary columns (JSON rows) read the same."""
    path, live = kitting
    old = rewrite_as_version_2(path, tmp_path / "v2.mcap")
    assert read_metadata(old)["schema_version"] == "2"
    assert read_metadata(path)["schema_version"] == "3"
    new_recording, old_recording = open_recording(path), open_recording(old)
    assert old_recording.events == new_recording.events == live.log.events
    assert old_recording.ticks == new_recording.ticks
    assert McapScan(str(old), lambda batch: None).run().other_ticks  # the teardown, as JSON
    query = "SELECT * EXCLUDE (run_id) FROM {} ORDER BY ALL"
    with open_runs(path, cache=False) as new, open_runs(old, cache=False) as older:
        assert_replay_equals_live(older.run(), live)
        for table in ("transitions", "blackboard", "ticks"):
            assert older.sql(query.format(table)) == new.sql(query.format(table))


def test_a_timeline_read_in_windows_is_the_whole_timeline(kitting, tmp_path, monkeypatch):
    """``iter_timeline`` reads a few seqs a query (bounded memory on a day-long run): the
    windows joined are the timeline, filters and bounds included."""
    path, live = kitting
    with open_runs(path, cache_dir=tmp_path) as database:
        run = database.run()
        whole = run.timeline()
        failures = run.timeline(status="failure")
        window = run.timeline(start="tick:3", end="tick:9")
        monkeypatch.setattr("btlog.replay.run.TIMELINE_WINDOW", 7)
        assert list(run.iter_timeline()) == whole
        assert [e.seq for e in whole] == [e.seq for e in live.log.events]
        assert run.timeline(status="failure") == failures and failures
        assert run.timeline(start="tick:3", end="tick:9") == window and window
        with pytest.raises(ReplayError, match="no node"):
            run.iter_timeline(node="no such node")

"""Tests of the recording: real runs written to real MCAP files and read back.

Round trip (events, ticks, tree, metadata, attachments equal what the executor emitted),
gap-free seqs, reading files cut at arbitrary offsets, recovery into a valid indexed file,
blackboard values that are not JSON, the message layouts against the JSON Schemas, and the
errors bad input raises.
"""

from __future__ import annotations

import errno
import io
import json
import os
import random
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import SeekingReader
from mcap.writer import CompressionType, Writer

import btlog
from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.events import (
    BlackboardWrite,
    EventLog,
    StatusBatch,
    StatusChange,
    TreeMutation,
    change_rows,
)
from btlog.executor.actions import SyncAction
from btlog.executor.clock import SimClock, WallClock
from btlog.executor.engine import Executor
from btlog.record import (
    Recorder,
    RecordingError,
    columns,
    iter_messages,
    open_recording,
    read_metadata,
    recover,
    schema_text,
)
from btlog.record import format as fmt
from btlog.record.background import BackgroundWriter
from btlog.status import IDLE, RUNNING, SUCCESS, Status
from btlog.tree.loader import load_tree, load_tree_text
from btlog.tree.model import CONDITION
from btlog.tree.registry import NodeType, Registry
from tests.mcap_support import version_2_payload
from tests.oracle.random_trees import generate

KITTING = Path(__file__).resolve().parent.parent / "trees" / "kitting.xml"


METADATA = {
    "domain": "outcomes",
    "seed": 7,
    "tree_file": "kitting-tree.xml",
    "outcomes": {"default": {"status": "SUCCESS", "duration": 0.5}},
    "argv": ["btlog", "run", "kitting-tree.xml"],
}


def record_kitting(
    path: Path,
    flush_interval: float = 1.0,
    mutate_at: int | None = None,
    max_tick_events: int | None = None,
) -> EventLog:
    """Record a scripted kitting run into ``path``; returns the events the executor emitted.

    With ``mutate_at``, a copy of the first leaf is inserted under the root at that tick.
    """
    tree = load_tree(KITTING)
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, Outcomes()))
    log = EventLog()
    recorder = Recorder(
        path,
        tree,
        METADATA,
        [(KITTING.name, KITTING.read_bytes())],
        flush_interval=flush_interval,
        max_tick_events=max_tick_events,
    )
    executor.subscribe(log)
    executor.subscribe(recorder)

    def before_tick(ex: Executor) -> None:
        if mutate_at is not None and ex.runtime.tick == mutate_at:
            leaf = next(n for n in ex.tree if n.is_execution)
            ex.insert_after(
                ex.tree.root.uid, ex.tree.root.children[0].uid, leaf, question="Can you look again?"
            )

    executor.run(max_ticks=5000, before_tick=before_tick)
    executor.close()
    return log


@pytest.fixture(scope="module")
def kitting_file(tmp_path_factory) -> tuple[Path, EventLog]:
    path = tmp_path_factory.mktemp("rec") / "kitting.mcap"
    return path, record_kitting(path, flush_interval=0)


def first_chunk_end(data: bytes) -> int:
    """The offset just past the first chunk (the head: metadata, attachment, tree)."""
    position = 8
    while True:
        opcode, length = struct.unpack_from("<BQ", data, position)
        position += 9 + length
        if opcode == 0x06:  # Chunk
            return position


# -- round trip ------------------------------------------------------------------------------
def test_round_trip_equals_the_executor_events(kitting_file):
    path, log = kitting_file
    recording = open_recording(path)
    assert recording.events == log.events
    assert recording.ticks == log.ticks
    assert recording.tree.describe() == load_tree(KITTING).describe()
    assert recording.attachments == {KITTING.name: KITTING.read_bytes()}
    assert not recording.truncated and recording.warnings == []
    assert recording.metadata["outcomes"] == METADATA["outcomes"]
    assert recording.metadata["argv"] == METADATA["argv"]
    assert recording.metadata["seed"] == "7"
    assert recording.metadata["schema_version"] == btlog.SCHEMA_VERSION
    assert recording.metadata["btlog_version"] == btlog.__version__
    assert read_metadata(path) == recording.metadata


def test_seqs_are_gap_free_from_zero(kitting_file):
    path, log = kitting_file
    seqs = [event.seq for event in open_recording(path).events]
    assert seqs == list(range(len(log.events)))
    assert len(seqs) > 100


def test_mutations_keep_their_place_in_the_seq_order(tmp_path):
    path = tmp_path / "mutated.mcap"
    log = record_kitting(path, mutate_at=5)
    recording = open_recording(path)
    assert recording.events == log.events
    mutations = [e for e in recording.events if isinstance(e, TreeMutation)]
    assert len(mutations) == 1 and mutations[0].question == "Can you look again?"
    assert [e.seq for e in recording.events] == list(range(len(log.events)))


def test_iter_messages_streams_every_message_in_file_order(kitting_file):
    path, log = kitting_file
    stream = iter_messages(path)
    messages = list(stream)
    assert messages[0][0] == fmt.TREE_TOPIC
    events = [
        row[0]
        for topic, _, data in messages
        if topic == fmt.EVENTS_TOPIC
        for row in fmt.parse_events(data).status
    ]
    assert events == [e.seq for e in log.events]
    assert not stream.truncated


def test_answers_are_recorded(tmp_path):
    tree = load_tree(KITTING)
    path = tmp_path / "answers.mcap"
    with Recorder(path, tree, {}) as recorder:
        recorder.on_answer(0, 10, 0, "What are you doing?", "doing", "I wait.")
    recorder.close()  # idempotent
    assert open_recording(path).answers == [
        {
            "seq": 0,
            "t_ns": 10,
            "tick": 0,
            "question": "What are you doing?",
            "intent": "doing",
            "answer": "I wait.",
        }
    ]


def test_a_huge_tick_is_written_in_parts(tmp_path):
    whole, parts = tmp_path / "whole.mcap", tmp_path / "parts.mcap"
    record_kitting(whole)
    log = record_kitting(parts, max_tick_events=3)
    assert open_recording(parts).events == log.events

    def sizes(path: Path) -> list[int]:
        return [
            len(fmt.parse_events(d).status)
            for topic, _, d in iter_messages(path)
            if topic == fmt.EVENTS_TOPIC
        ]

    assert max(sizes(whole)) > 4 and max(sizes(parts)) == 4
    assert sum(sizes(parts)) == sum(sizes(whole))


# -- truncation and recovery -----------------------------------------------------------------
def test_a_file_cut_anywhere_reads_as_a_gap_free_prefix(kitting_file, tmp_path):
    path, log = kitting_file
    data = path.read_bytes()
    head = first_chunk_end(data)
    cut_path = tmp_path / "cut.mcap"
    counts = set()
    for offset in sorted(random.Random(42).sample(range(head, len(data)), 40)):
        cut_path.write_bytes(data[:offset])
        recording = open_recording(cut_path)
        n = len(recording.events)
        assert recording.events == log.events[:n]
        assert [e.seq for e in recording.events] == list(range(n))
        assert recording.ticks == log.ticks[: len(recording.ticks)]
        assert recording.truncated
        assert recording.warnings[0].startswith(f"{cut_path}: truncated recording; read {n}")
        assert recording.tree.describe() == load_tree(KITTING).describe()
        counts.add(n)
    assert len(counts) > 10  # the cuts really landed at different places


def test_a_file_cut_before_the_tree_is_a_clear_error(kitting_file, tmp_path):
    path, _ = kitting_file
    data = path.read_bytes()
    cut_path = tmp_path / "head.mcap"
    for offset in (9, 100, first_chunk_end(data) - 1):
        cut_path.write_bytes(data[:offset])
        with pytest.raises(RecordingError, match=r"head\.mcap: .*no /btlog/tree"):
            open_recording(cut_path)


def test_an_unfinished_file_is_readable_after_each_flush(tmp_path):
    tree = load_tree(KITTING)
    path = tmp_path / "live.mcap"
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, Outcomes()))
    recorder = Recorder(path, tree, {}, flush_interval=3600)
    log = EventLog()
    executor.subscribe(log)
    executor.subscribe(recorder)
    for _ in range(20):
        executor.tick()
    assert open_recording(path).events == []  # nothing flushed yet: only the head
    recorder.flush()
    live = open_recording(path)  # as a reader would see it after kill -9
    assert live.truncated and live.events == log.events and live.ticks == log.ticks
    recorder.close()


ENDLESS_XML = """<root BTCPP_format="4"><BehaviorTree ID="MainTree">
  <KeepRunningUntilFailure><Sequence name="work">
    <Action ID="Look" name="look"/><Action ID="Grasp" name="grasp"/>
    <Action ID="Place" name="place"/>
  </Sequence></KeepRunningUntilFailure>
</BehaviorTree></root>"""

ENDLESS_RUN = """
import sys
from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.executor.clock import SimClock, WallClock
from btlog.executor.engine import Executor
from btlog.record import Recorder
from btlog.tree.loader import load_tree_text
tree = load_tree_text(sys.argv[2])
outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
executor.subscribe(Recorder(sys.argv[1], tree, {}, flush_interval=0.02))
while True:
    executor.tick()
"""


def endless_events(ticks: int) -> EventLog:
    """The events of the first ``ticks`` ticks of the endless run (the sim clock makes
    them the same every time)."""
    tree = load_tree_text(ENDLESS_XML)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    log = EventLog()
    executor.subscribe(log)
    for _ in range(ticks):
        executor.tick()
    return log


def test_kill_9_leaves_a_readable_prefix(tmp_path):
    path = tmp_path / "killed.mcap"
    source = Path(btlog.__file__).resolve().parents[1]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(source), os.environ.get("PYTHONPATH")])),
    }
    process = subprocess.Popen([sys.executable, "-c", ENDLESS_RUN, str(path), ENDLESS_XML], env=env)
    try:
        deadline = time.monotonic() + 30
        while (
            (not path.exists() or path.stat().st_size < 50_000)
            and time.monotonic() < deadline
            and process.poll() is None
        ):
            time.sleep(0.05)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert process.returncode == -signal.SIGKILL
    recording = open_recording(path)
    assert recording.truncated and recording.warnings
    assert len(recording.events) > 1000
    expected = endless_events(recording.ticks[-1].tick + 5)
    assert recording.events == expected.events[: len(recording.events)]
    assert recording.ticks == expected.ticks[: len(recording.ticks)]


def test_recover_rewrites_a_cut_file_into_an_indexed_one(kitting_file, tmp_path):
    path, log = kitting_file
    data = path.read_bytes()
    for offset in (first_chunk_end(data), len(data) // 2, len(data) - 3):
        broken, fixed = tmp_path / "broken.mcap", tmp_path / "fixed.mcap"
        broken.write_bytes(data[:offset])
        cut = open_recording(broken)
        report = recover(broken, fixed)
        assert report.truncated and report.events == len(cut.events)
        assert report.ticks == sum(not tick.teardown for tick in cut.ticks)  # as `run` counts
        assert report.last_seq == (cut.events[-1].seq if cut.events else None)
        with fixed.open("rb") as file:
            reader = SeekingReader(file)
            summary = reader.get_summary()
            assert summary is not None and summary.chunk_indexes
            indexed = sum(1 for _ in reader.iter_messages())
        assert indexed == report.messages
        recovered = open_recording(fixed)
        assert not recovered.truncated and recovered.warnings == []
        assert recovered.events == cut.events == log.events[: len(cut.events)]
        assert recovered.metadata == cut.metadata
        assert recovered.attachments == {KITTING.name: KITTING.read_bytes()}


def test_recover_in_place(kitting_file, tmp_path):
    path, log = kitting_file
    broken = tmp_path / "in-place.mcap"
    broken.write_bytes(path.read_bytes()[:-100])
    report = recover(broken, broken)
    assert report.truncated and report.events == len(log.events)
    assert open_recording(broken).events == log.events
    assert [p.name for p in tmp_path.iterdir()] == ["in-place.mcap"]


# -- blackboard values -------------------------------------------------------------------------
class Opaque:
    def __repr__(self) -> str:
        return "Opaque()"


class WriteOddValues(SyncAction):
    """Writes values JSON cannot hold, and one it can."""

    def tick(self):
        self.blackboard.set("object", Opaque())
        self.blackboard.set("set", {3})
        self.blackboard.set("huge", 2**80)
        self.blackboard.set("nan", float("nan"))
        self.blackboard.set("int_keys", {1: "a"})
        self.blackboard.set("pose", {"x": 1.5, "tags": ["a", "b"]})
        return SUCCESS


def test_values_that_are_not_json_are_recorded_as_repr(tmp_path):
    registry = Registry()
    registry.register_leaf(WriteOddValues)
    tree = load_tree_text(
        '<root BTCPP_format="4"><BehaviorTree ID="MainTree">'
        "<Sequence><WriteOddValues/></Sequence></BehaviorTree></root>",
        registry,
    )
    executor = Executor(tree, registry=registry)
    path = tmp_path / "values.mcap"
    executor.subscribe(Recorder(path, tree, {}))
    assert executor.run(max_ticks=3) is SUCCESS
    executor.close()
    writes = {e.key: e for e in open_recording(path).events if isinstance(e, BlackboardWrite)}
    leaf_uid = tree.root.children[0].uid
    expected = {
        "object": ("Opaque()", "Opaque"),
        "set": ("{3}", "set"),
        "huge": (repr(2**80), "int"),
        "nan": ("nan", "float"),
        "int_keys": ("{1: 'a'}", "dict"),
        "pose": ({"x": 1.5, "tags": ["a", "b"]}, "dict"),
    }
    assert {k: (w.value, w.type) for k, w in writes.items()} == expected
    assert {w.writer_uid for w in writes.values()} == {leaf_uid}


# -- schemas -----------------------------------------------------------------------------------
def schema_for(topic: str) -> dict:
    """The JSON Schema of ``topic``'s messages (events and ticks: as version 2 wrote them)."""
    return json.loads(schema_text(schema_of(topic)[1]))


def schema_of(topic: str) -> tuple[str, str]:
    """(schema name, JSON Schema file) of ``topic``'s JSON messages."""
    return fmt.JSON_SCHEMAS.get(topic) or fmt.TOPICS[topic][:2]


def messages_by_topic(path: Path) -> dict[str, list[dict]]:
    """Every message of ``path`` as JSON; events and ticks as version 2 wrote them."""
    found: dict[str, list[dict]] = {}
    for topic, _, data in iter_messages(path):
        found.setdefault(topic, []).append(orjson.loads(version_2_payload(topic, data)))
    return found


def test_events_and_ticks_are_binary_columns_on_channels_that_say_so(tmp_path):
    path = tmp_path / "columns.mcap"
    record_kitting(path, mutate_at=5)
    with path.open("rb") as file:
        summary = SeekingReader(file).get_summary()
    assert summary is not None
    channels = {c.topic: c for c in summary.channels.values()}
    for topic in (fmt.EVENTS_TOPIC, fmt.TICKS_TOPIC):
        channel = channels[topic]
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == schema.encoding == columns.ENCODING
        assert schema.data == schema_text("columns.md")
        assert schema.name == "btlog.Columns"
    assert {channels[t].message_encoding for t in fmt.TOPICS} == {"json", columns.ENCODING}
    for topic, _, data in iter_messages(path):
        if topic in (fmt.EVENTS_TOPIC, fmt.TICKS_TOPIC):
            magic = columns.EVENTS_MAGIC if topic == fmt.EVENTS_TOPIC else columns.TICKS_MAGIC
            located = columns.locate(data, 0, len(data))  # the length checks out
            assert located.magic == magic and data[:4] == magic


def test_messages_have_exactly_the_fields_of_their_schemas(tmp_path):
    path = tmp_path / "schemas.mcap"
    record_kitting(path, mutate_at=5)
    with Recorder(tmp_path / "answer.mcap", load_tree(KITTING), {}) as recorder:
        recorder.on_answer(1, 2, 3, "q", "i", "a")
    found = messages_by_topic(path) | messages_by_topic(tmp_path / "answer.mcap")
    assert set(found) == set(fmt.TOPICS)
    for topic, messages in found.items():
        schema = schema_for(topic)
        assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        assert schema["title"] == schema_of(topic)[0]
        optional = {"teardown"} if topic == fmt.TICKS_TOPIC else set()
        assert set(schema["properties"]) == set(schema["required"]) | optional
        for message in messages:
            assert set(schema["required"]) <= set(message) <= set(schema["properties"])
    # The run's last ticks message is its teardown, marked; no other message is.
    assert [m.get("teardown", False) for m in found[fmt.TICKS_TOPIC]][-2:] == [False, True]
    row_lengths = {"status": 6, "writes": 8}
    for name, length in row_lengths.items():
        assert (
            len(schema_for(fmt.EVENTS_TOPIC)["properties"][name]["items"]["prefixItems"]) == length
        )
    rows = [row for m in found[fmt.EVENTS_TOPIC] for row in m["status"]]
    assert rows and {len(row) for row in rows} == {6}
    assert len(schema_for(fmt.TICKS_TOPIC)["properties"]["ticks"]["items"]["prefixItems"]) == 4


def test_messages_validate_against_their_schemas(tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    path = tmp_path / "valid.mcap"
    record_kitting(path, mutate_at=5)
    for topic, messages in messages_by_topic(path).items():
        validator = jsonschema.Draft202012Validator(schema_for(topic))
        for message in messages:
            validator.validate(message)


# -- bad input ---------------------------------------------------------------------------------
def write_plain_mcap(
    path: Path, metadata: dict[str, str] | None = None, tree: bool = False
) -> None:
    """A valid MCAP file with a foreign topic (and optionally btlog pieces)."""
    with path.open("wb") as file:
        writer = Writer(file)
        writer.start()
        schema = writer.register_schema("x", "jsonschema", b"{}")
        channel = writer.register_channel("/other", "json", schema)
        writer.add_message(channel, 1, b"{}", 1)
        if metadata is not None:
            writer.add_metadata(fmt.METADATA_NAME, metadata)
        if tree:
            tree_channel = writer.register_channel(fmt.TREE_TOPIC, "json", schema)
            writer.add_message(tree_channel, 2, fmt.dumps(load_tree(KITTING).describe()), 2)
        writer.finish()


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (None, "no such file"),
        (b"", "empty file"),
        (b"just some text\n", "not an MCAP file"),
    ],
)
def test_bad_files_raise_a_recording_error_naming_the_file(tmp_path, content, problem):
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    for read in (open_recording, read_metadata, iter_messages, recover):
        args = (path, tmp_path / "out.mcap") if read is recover else (path,)
        with pytest.raises(RecordingError, match=rf"^{path}: {problem}"):
            read(*args)


def test_a_directory_is_not_a_recording(tmp_path):
    with pytest.raises(RecordingError, match="is a directory"):
        open_recording(tmp_path)


def test_an_mcap_without_btlog_topics_is_refused(tmp_path):
    path = tmp_path / "foreign.mcap"
    write_plain_mcap(path)
    with pytest.raises(
        RecordingError, match=r"foreign\.mcap: not a btlog recording: no /btlog/tree"
    ):
        open_recording(path)
    with pytest.raises(RecordingError, match=r"foreign\.mcap: not a btlog recording"):
        read_metadata(path)


def test_another_schema_version_is_refused(tmp_path):
    path = tmp_path / "future.mcap"
    write_plain_mcap(path, {"schema_version": "999"}, tree=True)
    with pytest.raises(RecordingError, match=r"future\.mcap: schema version '999'"):
        open_recording(path)
    with pytest.raises(RecordingError, match="schema version '999'"):
        read_metadata(path)


def test_a_gap_in_the_seqs_is_reported(tmp_path):
    path = tmp_path / "gap.mcap"
    with Recorder(path, load_tree(KITTING), {}) as recorder:
        for seq in (0, 1, 3):
            recorder.on_status(seq, seq, 1, 1, IDLE, RUNNING)
    recording = open_recording(path)
    assert [e.seq for e in recording.events] == [0, 1, 3]
    assert recording.warnings == [f"{path}: the events' seqs are not 0, 1, 2, … without gaps"]


def test_status_changes_are_rows_of_the_columns(kitting_file):
    path, log = kitting_file
    first = next(fmt.parse_events(d) for t, _, d in iter_messages(path) if t == fmt.EVENTS_TOPIC)
    event = log.events[0]
    assert isinstance(event, StatusChange)
    assert first.status[0] == (
        event.seq,
        event.t_ns,
        event.tick,
        event.uid,
        event.prev,
        event.status,
    )
    assert type(first.status[0][4]) is Status


SMALL_TREE = (
    '<root BTCPP_format="4" main_tree_to_execute="Main"><BehaviorTree ID="Main">'
    '<Sequence name="root"><Script name="init" code="n := 0"/><Fallback name="f">'
    '<AlwaysFailure name="no"/><Script name="count" code="n := n + 1"/></Fallback>'
    '<AlwaysSuccess name="yes"/></Sequence></BehaviorTree></root>'
)


@pytest.mark.parametrize("clock", ["simulated", "wall"])
def test_a_recorder_alone_records_what_the_executor_emits(tmp_path, clock):
    """A recorder as the only subscriber takes status changes in batches (appended by
    the nodes, numbered by the executor); what it records is what ``on_status`` would see."""

    def executor() -> Executor:
        chosen = SimClock(0.01) if clock == "simulated" else WallClock(0.01, paced=False)
        return Executor(load_tree_text(SMALL_TREE), clock=chosen)

    recorded, logged = executor(), executor()
    recorder = Recorder(tmp_path / "alone.mcap", recorded.tree, METADATA)
    recorded.subscribe(recorder)
    assert recorder.takes_status_batches()
    log = EventLog()
    logged.subscribe(log)
    for _ in range(7):
        recorded.tick()
        logged.tick()
    recorded.close()
    logged.close()
    events = open_recording(tmp_path / "alone.mcap").events
    assert [e.seq for e in events] == list(range(len(log.events)))
    assert any(isinstance(e, BlackboardWrite) for e in events)
    if clock == "simulated":
        assert events == log.events
    else:  # wall times differ between the two runs; everything else is the same
        assert [e._replace(t_ns=0) for e in events] == [e._replace(t_ns=0) for e in log.events]
        times = [e.t_ns for e in events]
        assert times == sorted(times) and times[-1] > 0


class _BatchedLog(EventLog):
    """An event log that takes status changes in batches, through the default
    ``on_status_batch`` (which decodes each change for ``on_status``)."""

    def takes_status_batches(self) -> bool:
        return True


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.integers(0, 10_000), st.sampled_from(["simulated", "wall"]), st.integers(1, 6))
def test_batched_status_changes_are_numbered_as_they_happened(tmp_path, seed, clock, halt_at):
    """Random trees with blackboard writes, a halt between ticks and a teardown: a recorder
    alone and a batch-taking log (both fed in batches, numbered by the executor's
    ``settle``) see exactly the events a plain log sees, one ``on_status`` a change."""
    case = generate(seed)
    registry = Registry()
    registry.register(NodeType("ScriptedCondition", CONDITION, declared_only=True))
    tree = load_tree_text(case.xml, registry)
    outcomes = Outcomes.from_mapping(case.outcomes)

    def run(subscriber) -> None:
        chosen = SimClock(0.01) if clock == "simulated" else WallClock(0.01, paced=False)
        executor = Executor(
            tree, clock=chosen, leaf_factory=scripted_leaf_factory(tree, outcomes, seed=3)
        )
        executor.subscribe(subscriber)
        for tick in range(1, case.max_ticks + 1):
            if executor.tick() in (SUCCESS, Status.FAILURE):
                break
            if tick == halt_at:
                executor.halt()  # changes between ticks: numbered in this tick
        executor.close()

    path = tmp_path / f"batched-{seed}-{clock}.mcap"
    plain, batched = EventLog(), _BatchedLog()
    run(Recorder(path, tree, METADATA))
    run(plain)
    run(batched)
    recorded = open_recording(path)

    def untimed(events) -> list:
        return [e if isinstance(e, TreeMutation) else e._replace(t_ns=0) for e in events]

    if clock == "simulated":
        assert recorded.events == plain.events == batched.events
    else:  # wall times differ between runs; each run's own times never go back
        assert untimed(recorded.events) == untimed(plain.events) == untimed(batched.events)
        for events in (recorded.events, batched.events):
            times = [e.t_ns for e in events]
            assert times == sorted(times)
    assert [e.seq for e in recorded.events] == list(range(len(plain.events)))

    def ticks(records) -> list:
        return [(t.tick, t.root_status, t.teardown) for t in records]

    assert ticks(recorded.ticks) == ticks(plain.ticks) == ticks(batched.ticks)


def test_a_bounded_recorder_is_called_per_event(tmp_path):
    """With ``max_tick_events`` the recorder must see each event (to write long ticks in
    parts), so it offers no row buffer to the executor."""
    recorder = Recorder(tmp_path / "bounded.mcap", load_tree(KITTING), METADATA, max_tick_events=3)
    assert not recorder.takes_status_batches()
    recorder.close()


class _FailingFile(io.RawIOBase):
    """A file that takes ``room`` bytes, then fails as a full disk does."""

    def __init__(self, room: int) -> None:
        self.room = room
        self.position = 0

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        assert (offset, whence) == (0, io.SEEK_CUR)  # tell() only
        return self.position

    def write(self, data: Any) -> int:
        if len(data) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(data)
        self.position += len(data)
        return len(data)


def test_an_error_of_the_writer_thread_reaches_the_run_once(tmp_path):
    """The MCAP writer runs on the recorder's thread: its error (a full disk) is raised
    in the run's thread by the next wait (a recorder's flush or close), the calls after it
    are dropped, and stopping still ends the thread."""
    writer = BackgroundWriter(Writer(_FailingFile(room=64), compression=CompressionType.NONE))
    writer.add_message(1, 0, b"x" * 1000, 0)
    writer.flush()  # the chunk reaches the file, which is full
    with pytest.raises(OSError, match="No space"):
        writer.wait()
    writer.add_message(1, 1, b"y", 1)  # dropped: the writer failed
    writer.wait()
    writer.stop()
    assert not writer.running


def test_the_recorders_own_thread_reports_its_cpu_time(tmp_path):
    """What recording costs beyond the run's thread is measurable (``bench_tick.py``)."""
    executor = Executor(load_tree_text(SMALL_TREE), clock=SimClock(0.01))
    recorder = Recorder(tmp_path / "cpu.mcap", executor.tree, METADATA)
    executor.subscribe(recorder)
    for _ in range(50):
        executor.tick()
    recorder.flush()  # the writer thread has packed and written something by now
    used = recorder.writer_cpu_seconds
    assert used is not None and 0 < used < 60
    executor.close()
    assert recorder.writer_cpu_seconds is None  # the thread has ended


def test_a_change_cut_from_its_time_is_dropped_not_misaligned():
    """Ctrl-C between a change and its time (a wall clock, an importer): the batch hands
    over the whole changes only, each with its own time, and counts only those."""
    seen = EventLog()
    batch = StatusBatch(seen, timed=True)
    rows = change_rows(4)
    batch.changes += [rows[IDLE][RUNNING], rows[RUNNING][SUCCESS]]
    batch.times.append(1_000)  # the second change's time was never noted
    assert batch.count() == 1
    assert batch.hand_over(7, 2, 0) == 1
    assert seen.events == [StatusChange(7, 1_000, 2, 4, IDLE, RUNNING)]
    assert batch.changes == [] and batch.times == []


def test_subscribers_changing_mid_run_leave_the_recording_whole(tmp_path):
    """A recorder first alone (batches, one time a tick), then beside another subscriber
    (one ``on_status`` a change, each with its time), then alone again: the messages mix
    both kinds of segments, and the recording equals a plain log of the same run."""

    def executor() -> Executor:
        return Executor(load_tree_text(SMALL_TREE), clock=SimClock(0.01))

    recorded, logged = executor(), executor()
    recorder = Recorder(tmp_path / "mixed.mcap", recorded.tree, METADATA)
    recorded.subscribe(recorder)
    log = EventLog()
    logged.subscribe(log)
    beside = EventLog()
    for tick in range(1, 10):
        if tick == 4:
            recorded.subscribe(beside)
            assert not recorded.runtime.append_row  # one call a change now
        if tick == 7:
            recorded.unsubscribe(beside)
        recorded.tick()
        logged.tick()
    recorded.close()
    logged.close()
    recording = open_recording(tmp_path / "mixed.mcap")
    assert recording.events == log.events
    assert beside.events == [e for e in log.events if 4 <= e.tick <= 6]

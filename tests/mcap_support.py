"""Recordings for the tests: a small looping run, and a recording re-written message by
message (crafted content, valid CRCs)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import orjson
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.executor.engine import Executor
from btlog.record import Recorder
from btlog.record import format as fmt
from btlog.record.columns import pack_event_rows, pack_ticks
from btlog.record.reader import iter_messages, read_metadata
from btlog.schema import schema_text
from btlog.status import Status
from btlog.tree.loader import load_tree_text

Message = tuple[str | int, int, bytes]
#: A tree that loops forever over two actions (each RUNNING for one tick).
LOOP = """<root BTCPP_format="4"><BehaviorTree ID="MainTree">
  <KeepRunningUntilFailure><Sequence name="work">
    <Action ID="Look" name="look"/><Action ID="Place" name="place"/>
  </Sequence></KeepRunningUntilFailure>
</BehaviorTree></root>"""


def record_loop(path: Path, ticks: int = 40) -> Path:
    """A recording of ``LOOP`` run for ``ticks`` ticks."""
    return record_tree(path, LOOP, ticks)


def record_tree(path: Path, xml: str, ticks: int = 40) -> Path:
    """A recording of the tree ``xml`` run for ``ticks`` ticks (actions scripted to
    succeed after one tick)."""
    tree = load_tree_text(xml)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    executor.subscribe(Recorder(path, tree, {"domain": "loop"}))
    executor.run(max_ticks=ticks)
    executor.close()
    return path


def wide_tree(siblings: int) -> str:
    """A legal wide tree: one Sequence of ``siblings`` AlwaysSuccess leaves."""
    leaves = "<AlwaysSuccess/>" * siblings
    return (
        '<root BTCPP_format="4"><BehaviorTree ID="MainTree">'
        f'<Sequence name="wide">{leaves}</Sequence></BehaviorTree></root>'
    )


def subtrees_tree(count: int) -> str:
    """A tree of ``count`` SubTrees under one Sequence, each of one action."""
    calls = "".join(f'<SubTree ID="S{i}"/>' for i in range(count))
    bodies = "".join(
        f'<BehaviorTree ID="S{i}"><AlwaysSuccess name="a{i}"/></BehaviorTree>' for i in range(count)
    )
    return (
        '<root BTCPP_format="4" main_tree_to_execute="MainTree"><BehaviorTree ID="MainTree">'
        f'<Sequence name="many">{calls}</Sequence></BehaviorTree>{bodies}</root>'
    )


def stored_metadata(source: Path) -> dict[str, str]:
    """The recording's metadata as MCAP stores it (every value a string, JSON if not one)."""
    return {
        k: v if isinstance(v, str) else orjson.dumps(v).decode()
        for k, v in read_metadata(source).items()
    }


def write_messages(
    target: Path,
    metadata: dict[str, str],
    messages: Iterable[Message],
    compression: CompressionType = CompressionType.ZSTD,
    chunked: bool = True,
    chunk_size: int = 1 << 20,
) -> Path:
    """An MCAP file with btlog's channels holding ``(topic, log_time, bytes)`` messages
    (a topic given as a number: a message of that channel id, which the file does not
    define); the events and ticks channels are JSON ones when ``metadata`` says schema
    version 2 (or 1), binary columns otherwise, as btlog writes them. Not ``chunked``:
    every record at the top level (no CRC guards them)."""
    json_rows = metadata.get("schema_version") in ("1", "2")
    with open(target, "wb") as file:
        writer = Writer(file, compression=compression, use_chunking=chunked, chunk_size=chunk_size)
        writer.start()
        channels = {}
        for topic, (name, schema, encoding) in fmt.TOPICS.items():
            if json_rows and topic in fmt.JSON_SCHEMAS:
                (name, schema), encoding = fmt.JSON_SCHEMAS[topic], MessageEncoding.JSON
            schema_encoding = (
                SchemaEncoding.JSONSchema if encoding == MessageEncoding.JSON else encoding
            )
            schema_id = writer.register_schema(name, schema_encoding, schema_text(schema))
            channels[topic] = writer.register_channel(topic, encoding, schema_id)
        writer.add_metadata(fmt.METADATA_NAME, metadata)
        for topic, log_time, data in messages:
            channel = topic if isinstance(topic, int) else channels[topic]
            writer.add_message(channel, log_time, data, log_time)
        writer.finish()
    return target


def version_2_payload(topic: str, data: bytes) -> bytes:
    """An events or ticks message (of any version) as schema version 2 wrote it: JSON
    rows with status names; any other message as it is."""
    if topic == fmt.EVENTS_TOPIC:
        events = fmt.parse_events(data)
        rows = [[*row[:4], row[4].name, row[5].name] for row in events.status]
        return orjson.dumps({"tick": events.tick, "status": rows, "writes": events.writes})
    if topic == fmt.TICKS_TOPIC:
        ticks = fmt.decode_ticks(data)
        body: dict = {"ticks": [[t.tick, t.start_ns, t.end_ns, t.root_status.name] for t in ticks]}
        if any(t.teardown for t in ticks):
            body["teardown"] = True
        return orjson.dumps(body)
    return data


def rewrite_as_version_2(source: Path, target: Path) -> Path:
    """``source`` as btlog wrote recordings before schema version 3 (JSON rows)."""
    metadata = stored_metadata(source) | {"schema_version": "2"}
    messages = (
        (topic, log_time, version_2_payload(topic, data))
        for topic, log_time, data in iter_messages(source)
    )
    return write_messages(target, metadata, messages)


def write_blackboard_dump(target: Path, keys: int, value_bytes: int) -> Path:
    """A recording of ``LOOP``'s tree whose one events message writes ``keys`` entries
    of about ``value_bytes`` each (a blackboard dump: tiny on disk, large in memory),
    followed by one tick."""
    source = record_loop(target.with_name(f".{target.name}.source.mcap"), ticks=1)
    metadata = stored_metadata(source)
    tree = next(data for topic, _time, data in iter_messages(source) if topic == fmt.TREE_TOPIC)
    source.unlink()
    value = "v" * value_bytes
    writes = [[seq, 1000, 1, "", f"key{seq}", f"{value}{seq}", "str", None] for seq in range(keys)]
    start = 10**18
    messages = [
        (fmt.TREE_TOPIC, start, tree),
        (fmt.EVENTS_TOPIC, start + 1000, pack_event_rows(1, [], writes)),
        (fmt.TICKS_TOPIC, start + 1000, pack_ticks([(1, 0, 1000, Status.RUNNING)])),
    ]
    return write_messages(target, metadata, messages)

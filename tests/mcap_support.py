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
from btlog.record.reader import read_metadata
from btlog.schema import schema_text
from btlog.tree.loader import load_tree_text

Message = tuple[str, int, bytes]
#: A tree that loops forever over two actions (each RUNNING for one tick).
LOOP = """<root BTCPP_format="4"><BehaviorTree ID="MainTree">
  <KeepRunningUntilFailure><Sequence name="work">
    <Action ID="Look" name="look"/><Action ID="Place" name="place"/>
  </Sequence></KeepRunningUntilFailure>
</BehaviorTree></root>"""


def record_loop(path: Path, ticks: int = 40) -> Path:
    """A recording of ``LOOP`` run for ``ticks`` ticks."""
    tree = load_tree_text(LOOP)
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "ticks": 1}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    executor.subscribe(Recorder(path, tree, {"domain": "loop"}))
    executor.run(max_ticks=ticks)
    executor.close()
    return path


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
) -> Path:
    """An MCAP file with btlog's channels holding ``(topic, log_time, bytes)`` messages."""
    with open(target, "wb") as file:
        writer = Writer(file, compression=compression)
        writer.start()
        channels = {}
        for topic, (name, schema) in fmt.TOPICS.items():
            schema_id = writer.register_schema(name, SchemaEncoding.JSONSchema, schema_text(schema))
            channels[topic] = writer.register_channel(topic, MessageEncoding.JSON, schema_id)
        writer.add_metadata(fmt.METADATA_NAME, metadata)
        for topic, log_time, data in messages:
            writer.add_message(channels[topic], log_time, data, log_time)
        writer.finish()
    return target

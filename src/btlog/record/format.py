"""The recording's wire format: topics, message layouts, metadata keys.

One MCAP file per run. The tree, mutations and answers are JSON objects described by a
JSON Schema in ``schemas/`` (encoding ``json``, schema encoding ``jsonschema``); events
and ticks are binary columns (``btlog.record.columns``, documented in
``schemas/columns.md``), read here in every schema version:

``/btlog/tree`` (``btlog.Tree``), once, first: ``{"tree_name", "format", "nodes": [node…]}``
with each node ``{"uid", "parent_uid", "idx", "kind", "type", "name", "path", "scope",
"ports": {name: {"value", "direction"}}, "attributes", "file", "line"}``.

``/btlog/events``, messages grouping the events of one or more ticks
(a message is written once about a thousand events have gathered, and at every flush):
``tick``, the last tick the message covers; the status changes, each ``seq, t_ns, tick,
uid, prev, status``; the blackboard writes, each ``[seq, t_ns, tick, scope, key, value,
type, writer_uid]``. Since schema version 3 the message is binary (channel message
encoding ``btlog.columns``): the status changes as fixed-width columns, the writes as
JSON, laid out in ``btlog.record.columns``. Versions 1 and 2 wrote a JSON object
``{"tick", "status": [[seq, t_ns, tick, uid, prev, status], …], "writes": […]}`` with
statuses as names; both are read. Every row keeps its own seq, time and tick; the
status changes and writes interleave by ``seq``, which is global and gap-free across
all event kinds, mutations included. A ``value`` that is not JSON is its ``repr`` with
``type`` naming its Python type; a removed entry has type ``"unset"`` and value null.

``/btlog/mutations`` (``btlog.Mutation``), one per change of the tree: ``{"seq", "t_ns",
"tick", "op", "parent_uid", "after_uid", "inserted_root_uid", "nodes": [node…],
"question"}``.

``/btlog/ticks``, batched tick records ``tick, start_ns, end_ns,
root_status``; the run's teardown is a message of its own, marked. Binary columns since
schema version 3 (``btlog.record.columns``); before, ``{"ticks": [[…], …], "teardown"}``.

``/btlog/answers`` (``btlog.Answer``), questions asked live: ``{"seq", "t_ns", "tick",
"question", "intent", "answer"}`` where ``seq`` is the number of events before the answer.

Metadata ``btlog.run`` (string values; JSON for structured ones) and one attachment per
tree file read (``application/xml``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import orjson
from mcap.well_known import MessageEncoding

from btlog.events import BlackboardWrite, StatusChange, TickRecord, TreeMutation
from btlog.record import columns
from btlog.status import Status

TREE_TOPIC = "/btlog/tree"
EVENTS_TOPIC = "/btlog/events"
MUTATIONS_TOPIC = "/btlog/mutations"
TICKS_TOPIC = "/btlog/ticks"
ANSWERS_TOPIC = "/btlog/answers"

#: topic → (schema name, schema file in schemas/, message encoding) of new recordings
TOPICS = {
    TREE_TOPIC: ("btlog.Tree", "tree.schema.json", MessageEncoding.JSON),
    EVENTS_TOPIC: ("btlog.Columns", "columns.md", columns.ENCODING),
    MUTATIONS_TOPIC: ("btlog.Mutation", "mutation.schema.json", MessageEncoding.JSON),
    TICKS_TOPIC: ("btlog.Columns", "columns.md", columns.ENCODING),
    ANSWERS_TOPIC: ("btlog.Answer", "answer.schema.json", MessageEncoding.JSON),
}
#: (schema name, JSON Schema file) of the events and ticks of schema versions 1 and 2.
JSON_SCHEMAS = {
    EVENTS_TOPIC: ("btlog.Events", "events.schema.json"),
    TICKS_TOPIC: ("btlog.Ticks", "ticks.schema.json"),
}

METADATA_NAME = "btlog.run"
#: Metadata values stored as JSON text (the others are plain strings).
JSON_METADATA = ("outcomes", "fail", "questions", "argv", "source")

_STATUS_BY_NAME = {s.name: s for s in Status}


def dumps(message: dict) -> bytes:
    """Encode a message (JSON; values orjson cannot encode become their repr)."""
    return orjson.dumps(message, default=repr)


def loads(data: bytes) -> Any:
    """Decode a message."""
    return orjson.loads(data)


@dataclass(frozen=True)
class EventsMessage:
    """One ``/btlog/events`` message decoded: its tick, its status rows ``(seq, t_ns,
    tick, uid, prev, status)`` with ``Status`` values, and its write rows."""

    tick: int
    status: list[tuple[int, int, int, int, Status, Status]]
    writes: list[list]


def parse_events(data: bytes) -> EventsMessage:
    """An ``/btlog/events`` message of any schema version (binary or JSON)."""
    if columns.is_binary(data):
        message, rows = columns.unpack(data, columns.EVENTS_MAGIC)
        status = [(s, t, k, u, Status(p), Status(n)) for s, t, k, u, p, n in rows]
        return EventsMessage(message.tick, status, columns.writes_of(data, message))
    body = orjson.loads(data)
    status = [
        (s, t, k, u, _STATUS_BY_NAME[p], _STATUS_BY_NAME[n])
        for s, t, k, u, p, n in body.get("status", ())
    ]
    return EventsMessage(body.get("tick", 0), status, list(body.get("writes", ())))


def encode_events(message: EventsMessage) -> bytes:
    """The binary ``/btlog/events`` message of ``message`` (what the recorder writes)."""
    return columns.pack_event_rows(message.tick, message.status, message.writes)


def decode_events(data: bytes) -> list[StatusChange | BlackboardWrite]:
    """The events of one ``/btlog/events`` message, in seq order."""
    message = parse_events(data)
    events: list[StatusChange | BlackboardWrite] = [StatusChange(*row) for row in message.status]
    events.extend(BlackboardWrite(*row) for row in message.writes)
    events.sort(key=lambda e: e.seq)
    return events


def decode_mutation(message: dict) -> TreeMutation:
    """The mutation of one ``/btlog/mutations`` message."""
    return TreeMutation(
        message["seq"],
        message["t_ns"],
        message["tick"],
        message["op"],
        message["parent_uid"],
        message.get("after_uid"),
        message["nodes"],
        message.get("question", ""),
    )


def encode_mutation(mutation: TreeMutation) -> dict:
    """The ``/btlog/mutations`` message of a mutation."""
    return {
        "seq": mutation.seq,
        "t_ns": mutation.t_ns,
        "tick": mutation.tick,
        "op": mutation.op,
        "parent_uid": mutation.parent_uid,
        "after_uid": mutation.after_uid,
        "inserted_root_uid": mutation.inserted_root_uid,
        "nodes": mutation.nodes,
        "question": mutation.question,
    }


def decode_ticks(data: bytes) -> list[TickRecord]:
    """The tick records of one ``/btlog/ticks`` message of any schema version."""
    if columns.is_binary(data):
        message, rows = columns.unpack(data, columns.TICKS_MAGIC)
        teardown = message.teardown
        return [TickRecord(t, s, e, Status(r), teardown) for t, s, e, r in rows]
    body = orjson.loads(data)
    teardown = bool(body.get("teardown", False))
    return [
        TickRecord(tick, start, end, _STATUS_BY_NAME[status], teardown)
        for tick, start, end, status in body.get("ticks", ())
    ]

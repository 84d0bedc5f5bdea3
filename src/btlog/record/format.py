"""The recording's wire format: topics, message layouts, metadata keys.

One MCAP file per run. Every message is a JSON object described by a JSON Schema in
``schemas/`` (encoding ``json``, schema encoding ``jsonschema``):

``/btlog/tree`` (``btlog.Tree``), once, first: ``{"tree_name", "format", "nodes": [node…]}``
with each node ``{"uid", "parent_uid", "idx", "kind", "type", "name", "path", "scope",
"ports": {name: {"value", "direction"}}, "attributes", "file", "line"}``.

``/btlog/events`` (``btlog.Events``), messages grouping the events of one or more ticks
(a message is written once about a thousand events have gathered, and at every flush)::

    {"tick": 7,
     "status": [[seq, t_ns, tick, uid, prev, status], …],
     "writes": [[seq, t_ns, tick, scope, key, value, type, writer_uid], …]}

``tick`` is the last tick the message covers; every row keeps its own seq, time and tick.
Rows are arrays (compact and fast to encode); statuses are names (``"RUNNING"``). The
two lists interleave by ``seq``, which is global and gap-free across all event kinds,
mutations included. A ``value`` that is not JSON is its ``repr`` with ``type`` naming
its Python type; a removed entry has type ``"unset"`` and value null.

``/btlog/mutations`` (``btlog.Mutation``), one per change of the tree: ``{"seq", "t_ns",
"tick", "op", "parent_uid", "after_uid", "inserted_root_uid", "nodes": [node…],
"question"}``.

``/btlog/ticks`` (``btlog.Ticks``), batched: ``{"ticks": [[tick, start_ns, end_ns,
root_status], …]}``.

``/btlog/answers`` (``btlog.Answer``), questions asked live: ``{"seq", "t_ns", "tick",
"question", "intent", "answer"}`` where ``seq`` is the number of events before the answer.

Metadata ``btlog.run`` (string values; JSON for structured ones) and one attachment per
tree file read (``application/xml``).
"""

from __future__ import annotations

from typing import Any

import orjson

from btlog.events import BlackboardWrite, StatusChange, TickRecord, TreeMutation
from btlog.status import Status

TREE_TOPIC = "/btlog/tree"
EVENTS_TOPIC = "/btlog/events"
MUTATIONS_TOPIC = "/btlog/mutations"
TICKS_TOPIC = "/btlog/ticks"
ANSWERS_TOPIC = "/btlog/answers"

#: topic → (schema name, schema file in schemas/)
TOPICS = {
    TREE_TOPIC: ("btlog.Tree", "tree.schema.json"),
    EVENTS_TOPIC: ("btlog.Events", "events.schema.json"),
    MUTATIONS_TOPIC: ("btlog.Mutation", "mutation.schema.json"),
    TICKS_TOPIC: ("btlog.Ticks", "ticks.schema.json"),
    ANSWERS_TOPIC: ("btlog.Answer", "answer.schema.json"),
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


def decode_events(message: dict) -> list[StatusChange | BlackboardWrite]:
    """The events of one ``/btlog/events`` message, in seq order."""
    events: list[StatusChange | BlackboardWrite] = [
        StatusChange(seq, t, tick, uid, _STATUS_BY_NAME[prev], _STATUS_BY_NAME[new])
        for seq, t, tick, uid, prev, new in message.get("status", ())
    ]
    events.extend(BlackboardWrite(*row) for row in message.get("writes", ()))
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


def decode_ticks(message: dict) -> list[TickRecord]:
    """The tick records of one ``/btlog/ticks`` message."""
    teardown = bool(message.get("teardown", False))
    return [
        TickRecord(tick, start, end, _STATUS_BY_NAME[status], teardown)
        for tick, start, end, status in message.get("ticks", ())
    ]

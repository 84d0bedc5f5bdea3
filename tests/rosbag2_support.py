"""Writers of rosbag2 bags as ROS 2 writes them, for the tests (no ROS needed).

- ``write_sqlite_bag``: a bag folder in SQLite storage as ROS 2 Humble's
  ``rosbag2_storage_default_plugins`` writes it (database schema version 3: tables
  ``schema``, ``metadata``, ``topics``, ``messages``; no message definitions), with its
  ``metadata.yaml`` (version 5); ``jazzy=True`` writes Jazzy's layout instead (schema
  version 4, whose ``message_definitions`` table holds each type's definition, and
  ``type_description_hash`` columns). Splits, per-message zstd compression and a
  folder without ``metadata.yaml`` (a recorder killed before writing it) are options.
- ``write_mcap_bag``: a bag folder in MCAP storage (one or several ``.mcap`` files).

Messages are ``(topic, type, log_time_ns, mapping)``, encoded in CDR with the
definition given per type (``mcap-ros2-support``'s encoder).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Mapping
from pathlib import Path

import yaml
import zstandard
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.writer import Writer

from btlog.sources.rosbag2 import shipped_definition

Message = tuple[str, str, int, Mapping]
HUMBLE_QOS = (
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n"
    "    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n"
    "    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n"
    "    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false"
)
NAV2_LOG = "nav2_msgs/msg/BehaviorTreeLog"
HUMBLE = shipped_definition(NAV2_LOG, "humble").text
JAZZY = shipped_definition(NAV2_LOG, "jazzy").text


def encode(type_name: str, definition: str, message: Mapping) -> bytes:
    """The CDR bytes of ``message`` (a mapping of fields) of ``type_name``."""
    return serialize_dynamic(type_name, definition)[type_name](message)


def _splits(messages: list[Message], files: int) -> list[list[Message]]:
    size = max(1, -(-len(messages) // files))
    return [messages[i * size : (i + 1) * size] for i in range(files)]


def _metadata(
    storage: str, names: list[str], parts: list[list[Message]], compression: str, version: int
) -> dict:
    everything = [m for part in parts for m in part]
    times = [m[2] for m in everything] or [0]
    topics: dict[str, tuple[str, int]] = {}
    for topic, type_name, _t, _m in everything:
        topics[topic] = (type_name, topics.get(topic, (type_name, 0))[1] + 1)
    return {
        "rosbag2_bagfile_information": {
            "version": version,
            "storage_identifier": storage,
            "duration": {"nanoseconds": max(times) - min(times)},
            "starting_time": {"nanoseconds_since_epoch": min(times)},
            "message_count": len(everything),
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": topic,
                        "type": type_name,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": HUMBLE_QOS,
                    },
                    "message_count": count,
                }
                for topic, (type_name, count) in topics.items()
            ],
            "compression_format": "zstd" if compression else "",
            "compression_mode": compression,
            "relative_file_paths": names,
            "files": [
                {
                    "path": name,
                    "starting_time": {"nanoseconds_since_epoch": min(m[2] for m in part)},
                    "duration": {"nanoseconds": max(m[2] for m in part) - min(m[2] for m in part)},
                    "message_count": len(part),
                }
                for name, part in zip(names, parts, strict=True)
                if part
            ],
        }
    }


def write_sqlite_bag(
    folder: Path,
    messages: Iterable[Message],
    definitions: Mapping[str, str],
    *,
    jazzy: bool = False,
    files: int = 1,
    compress_messages: bool = False,
    metadata: bool = True,
) -> list[Path]:
    """Write the bag folder ``folder``; returns its ``.db3`` files."""
    folder.mkdir(parents=True, exist_ok=True)
    messages = list(messages)
    parts = _splits(messages, files)
    names = [f"{folder.name}_{i}.db3" for i in range(files)]
    version = 9 if jazzy else 5
    info = _metadata("sqlite3", names, parts, "MESSAGE" if compress_messages else "", version)
    written = []
    for name, part in zip(names, parts, strict=True):
        path = folder / name
        con = sqlite3.connect(path)
        hash_column = ", type_description_hash TEXT NOT NULL" if jazzy else ""
        con.executescript(
            "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);"
            "CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL,"
            " metadata TEXT NOT NULL);"
            "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,"
            " serialization_format TEXT NOT NULL,"
            f" offered_qos_profiles TEXT NOT NULL{hash_column});"
            + (
                "CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL,"
                " encoding TEXT NOT NULL, encoded_message_definition TEXT NOT NULL,"
                " type_description_hash TEXT NOT NULL);"
                if jazzy
                else ""
            )
            + "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,"
            " timestamp INTEGER NOT NULL, data BLOB NOT NULL);"
            "CREATE INDEX timestamp_idx ON messages (timestamp ASC);"
        )
        con.execute(
            "INSERT INTO schema VALUES (?, ?)", (4 if jazzy else 3, "jazzy" if jazzy else "humble")
        )
        con.execute(
            "INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)",
            (version, yaml.safe_dump(info)),
        )
        ids: dict[str, int] = {}
        compressor = zstandard.ZstdCompressor()
        for topic, type_name, t_ns, fields in part:
            if topic not in ids:
                extra = ", ''" if jazzy else ""
                cursor = con.execute(
                    "INSERT INTO topics (name, type, serialization_format, offered_qos_profiles"
                    + (", type_description_hash" if jazzy else "")
                    + f") VALUES (?, ?, 'cdr', ?{extra})",
                    (topic, type_name, HUMBLE_QOS),
                )
                ids[topic] = int(cursor.lastrowid or 0)
                if (
                    jazzy
                    and not con.execute(
                        "SELECT 1 FROM message_definitions WHERE topic_type = ?", (type_name,)
                    ).fetchone()
                ):
                    con.execute(
                        "INSERT INTO message_definitions (topic_type, encoding,"
                        " encoded_message_definition, type_description_hash)"
                        " VALUES (?, 'ros2msg', ?, '')",
                        (type_name, definitions[type_name]),
                    )
            data = encode(type_name, definitions[type_name], fields)
            if compress_messages:
                data = compressor.compress(data)
            con.execute(
                "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
                (ids[topic], t_ns, data),
            )
        con.commit()
        con.close()
        written.append(path)
    if metadata:
        (folder / "metadata.yaml").write_text(yaml.safe_dump(info), encoding="utf-8")
    return written


def write_mcap_bag(
    folder: Path,
    messages: Iterable[Message],
    definitions: Mapping[str, str],
    *,
    files: int = 1,
    chunk_size: int = 1 << 20,
) -> list[Path]:
    """Write the bag folder ``folder`` in MCAP storage; returns its ``.mcap`` files."""
    folder.mkdir(parents=True, exist_ok=True)
    messages = list(messages)
    parts = _splits(messages, files)
    names = [f"{folder.name}_{i}.mcap" for i in range(files)]
    for name, part in zip(names, parts, strict=True):
        with open(folder / name, "wb") as stream:
            writer = Writer(stream, chunk_size=chunk_size)
            schemas = {}
            for topic, type_name, t_ns, fields in part:
                if type_name not in schemas:
                    schemas[type_name] = writer.register_msgdef(type_name, definitions[type_name])
                writer.write_message(topic, schemas[type_name], dict(fields), t_ns, t_ns)
            writer.finish()
    info = _metadata("mcap", names, parts, "", 5)
    (folder / "metadata.yaml").write_text(yaml.safe_dump(info), encoding="utf-8")
    return [folder / name for name in names]

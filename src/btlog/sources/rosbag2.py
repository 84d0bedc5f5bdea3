"""Read rosbag2 bags without ROS: MCAP or SQLite storage, a bag folder or one file.

The one reader of bags, for every importer of ROS 2 topics (Nav2's behavior tree log,
py_trees_ros snapshots...)::

    with open_bag("my_bag/") as bag:          # a folder, a .mcap or a .db3
        bag.storage                           # "mcap" or "sqlite3"
        bag.files                             # its storage files, in order (splits)
        bag.topics                            # {name: Topic(name, type, serialization_format)}
        for message in bag.messages({"/behavior_tree_log"}):
            message.topic, message.type, message.log_time_ns, message.decoded
        bag.warnings                          # what could not be read (after iterating)
        bag.used                              # {topic: the Definition that decoded it}

``messages`` yields the messages of the topics asked for (all when None), decoded into
objects with the message's fields as attributes (``mcap-ros2-support``'s dynamic CDR
decoder), in the storage's order: the order of the records in each MCAP file, the
order of the rows (as rosbag2 wrote them) in each SQLite file, file after file. A
folder's files are those its ``metadata.yaml`` lists (``relative_file_paths``), else
its ``*.mcap`` or ``*.db3`` files in the order of their split number; ``.zstd``
files (rosbag2's file compression) are decompressed to a temporary file, and the
messages of a bag with ``compression_mode: MESSAGE`` (zstd frames) one by one.

Message definitions. An MCAP bag stores each topic's definition (its Schema record); a
SQLite bag written by ROS 2 Jazzy or later stores them in ``message_definitions``; both
are used. Older SQLite bags (Humble's default storage) store only each topic's type
name: the definitions btlog ships (``btlog/sources/ros2msg``, ``shipped_definitions``)
and those the caller passes (``extra``) are candidates, and a topic is decoded by one
that reads its messages *exactly*: each decodes and, encoded again, gives back its
bytes (a wrong layout often decodes into garbage without an error, so decoding alone
proves nothing). A SQLite topic's messages are checked before it is read, until one
candidate is left; when several read them all (a field whose bytes are all alignment
padding, such as Nav2's ``uid`` after some names), the one with the fewest fields. A
bag's own definition is used as it is.

Damage is told, never hidden: an MCAP bag is walked by ``btlog.record.walk``, as btlog's
own recordings are (a damaged chunk is skipped with a warning naming the file and the
chunk's offset; a file cut short is read up to its last whole record); a message that
does not decode is skipped and counted in one warning per topic; a SQLite file damaged
part way is read up to the damage, with a warning. What cannot be read at all raises
``SourceError``, one line naming the file (and the offset or table).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sqlite3
import struct
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from types import TracebackType
from typing import Any

import zstandard
from mcap.exceptions import McapError
from mcap.opcode import Opcode

from btlog import documents
from btlog.record.walk import RecordingError, Walk, mapped, parse, records
from btlog.sources.builder import SourceError

MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
#: A topic none of whose first PROBE messages any known layout reads exactly is refused.
PROBE = 16
#: Bytes a ``.zstd`` storage file may decompress to, per byte of it (a bomb is refused).
MAX_ZSTD_RATIO = 64
#: Bytes one compressed message may decompress to.
MAX_MESSAGE = 1 << 30
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_SPLIT = re.compile(r"_(\d+)\.(?:mcap|db3)(?:\.zstd)?$")
_DECODE_ERRORS = (ValueError, IndexError, KeyError, TypeError, struct.error, OverflowError)


class _DefinitionError(ValueError):
    """A message definition the ``ros2msg`` parser cannot read."""


@dataclass(frozen=True)
class Definition:
    """A message type's full ``ros2msg`` definition (its dependencies after ``MSG:``
    lines) and where it came from (``bag``, or the releases of a shipped one)."""

    type: str
    text: str
    origin: str


@dataclass(frozen=True)
class Topic:
    """A topic of the bag: its name, message type and serialization format (``cdr``)."""

    name: str
    type: str
    serialization_format: str = "cdr"


@dataclass(frozen=True)
class BagMessage:
    """One decoded message: its topic, type name, log time (ns since the epoch, the
    time the recorder received it) and the decoded message."""

    topic: str
    type: str
    log_time_ns: int
    decoded: Any


def shipped_definitions(type_name: str) -> list[Definition]:
    """The definitions btlog ships for ``type_name`` (``pkg/msg/Type``), newest layout
    first; empty when it ships none."""
    parts = type_name.split("/")
    if len(parts) != 3 or not all(re.fullmatch(r"[A-Za-z0-9_]+", p) for p in parts):
        return []
    folder = resources.files("btlog.sources").joinpath("ros2msg", *parts)
    if not folder.is_dir():
        return []
    found = [
        Definition(type_name, item.read_text(encoding="utf-8"), item.name.removesuffix(".msg"))
        for item in folder.iterdir()
        if item.name.endswith(".msg")
    ]
    return sorted(found, key=lambda d: d.origin, reverse=True)


def shipped_definition(type_name: str, release: str) -> Definition:
    """The shipped definition of ``type_name`` that ROS 2 release ``release`` used."""
    for definition in shipped_definitions(type_name):
        if release in definition.origin.split("-") or definition.origin == "all":
            return definition
    raise LookupError(f"btlog ships no definition of {type_name} for {release}")


def _is_field(line: str) -> bool:
    """Whether a line of a ``ros2msg`` definition declares a field (not a comment, a
    constant, a dependency's header or the separator)."""
    text = line.split("#", 1)[0].strip()
    return bool(text) and "=" not in text and not text.startswith("MSG:")


class _Codec:
    """Decodes one topic's messages with one definition; ``exact`` checks a message
    reads back to its own bytes."""

    def __init__(self, definition: Definition) -> None:
        from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

        try:  # its parser prints what it cannot read on stderr, then raises: the error says it
            with contextlib.redirect_stderr(io.StringIO()):
                decoders = generate_dynamic(definition.type, definition.text)
                encoders = serialize_dynamic(definition.type, definition.text)
            self.decode: Callable[[bytes], Any] = decoders[definition.type]
            self._encode: Callable[[Any], bytes] = encoders[definition.type]
        except Exception as error:  # a hostile definition may break the parser anywhere
            raise _DefinitionError(f"{type(error).__name__}: {error}") from None
        self.definition = definition
        self.fields = sum(1 for line in definition.text.splitlines() if _is_field(line))

    def exact(self, data: bytes) -> bool:
        """True when ``data`` decodes and encodes back to itself (up to the final
        alignment padding, at most 3 zero bytes, that DDS implementations add)."""
        try:
            again = self._encode(self.decode(data))
        except (*_DECODE_ERRORS, RecursionError, AttributeError):
            return False
        tail = data[len(again) :]
        return data[4 : len(again)] == again[4:] and len(tail) < 4 and not tail.strip(b"\0")


class _TopicDecoder:
    """Decodes one topic's messages: with the bag's own definition when it has one, else
    with the candidates that have read every message so far exactly (the module
    docstring); the first of them decodes."""

    def __init__(self, path: str, topic: Topic, candidates: list[Definition], own: bool) -> None:
        self.topic = topic
        self.own = own
        self.codecs: list[_Codec] = []
        for definition in candidates:
            try:
                self.codecs.append(_Codec(definition))
            except _DefinitionError as error:
                if own:
                    raise SourceError(
                        f"{path}: the bag's definition of {topic.type} ({topic.name}) "
                        f"cannot be read: {error}"
                    ) from None
        self.tried = ", ".join(d.origin for d in candidates)
        self.decoded = self.failed = 0
        if not self.codecs:
            raise SourceError(f"{path}: no readable definition of {topic.type} ({topic.name})")
        self.codecs.sort(key=lambda codec: codec.fields)

    def settle(self, messages: Iterable[bytes]) -> None:
        """Keep the candidates that read each of ``messages`` exactly (a message none
        reads is damaged and tells nothing), until one is left."""
        for data in messages:
            if len(self.codecs) == 1:
                return
            with contextlib.suppress(zstandard.ZstdError, ValueError):
                exact = [codec for codec in self.codecs if codec.exact(_uncompressed(data))]
                self.codecs = exact or self.codecs

    @property
    def definition(self) -> Definition:
        """The definition decoding the topic now."""
        return self.codecs[0].definition

    def decode(self, data: bytes) -> Any:
        """The decoded message (``ValueError`` when no candidate reads it exactly)."""
        data = _uncompressed(data)
        if len(self.codecs) > 1:
            exact = [codec for codec in self.codecs if codec.exact(data)]
            if not exact:
                self.failed += 1
                raise ValueError(f"no layout ({self.tried}) reads it exactly")
            self.codecs = exact
        message = self.codecs[0].decode(data)
        self.decoded += 1
        return message


@dataclass
class _Undecodable:
    count: int = 0
    first_ns: int = 0
    reason: str = ""


class Bag:
    """An open bag (see the module docstring); use ``open_bag``, and close it (or use
    it as a context manager) to remove temporary files."""

    def __init__(
        self,
        path: str,
        storage: str,
        files: list[str],
        metadata: dict[str, Any],
        extra: Iterable[Definition] = (),
        warnings: Iterable[str] = (),
    ) -> None:
        self.path = path
        self.storage = storage
        self.files = files
        self.metadata = metadata
        self.extra = list(extra)
        self.warnings: list[str] = list(warnings)
        self.used: dict[str, Definition] = {}
        self._topics: dict[str, Topic] | None = None
        self._temporary: dict[str, str] = {}

    def __enter__(self) -> Bag:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Remove the temporary files of decompressed storage files."""
        for name in self._temporary.values():
            with contextlib.suppress(OSError):
                os.unlink(name)
        self._temporary.clear()

    @property
    def topics(self) -> dict[str, Topic]:
        """Every topic of the bag's files, by name."""
        if self._topics is None:
            topics: dict[str, Topic] = {}
            for file in self.files:
                topics.update(_TOPIC_READERS[self.storage](self._local(file)))
            self._topics = topics
        return self._topics

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """The messages of ``topics`` (every topic when None), decoded, in storage order."""
        wanted = None if topics is None else set(topics)
        undecodable: dict[str, _Undecodable] = {}
        read = _mcap_messages if self.storage == "mcap" else _sqlite_messages
        for file in self.files:
            yield from read(self, file, self._local(file), wanted, undecodable)
        for topic, skipped in undecodable.items():
            self.warnings.append(
                f"{self.path}: {skipped.count} message(s) on {topic} could not be decoded "
                f"(the first logged at {skipped.first_ns} ns: {skipped.reason}); skipped"
            )

    # -- files ---------------------------------------------------------------------------
    def _local(self, file: str) -> str:
        """The storage file to read: ``file``, or its decompressed copy."""
        if not file.endswith(".zstd"):
            return file
        if file in self._temporary:
            return self._temporary[file]
        size = os.path.getsize(file)
        handle, name = tempfile.mkstemp(
            suffix=Path(file).suffixes[-2] if len(Path(file).suffixes) > 1 else ""
        )
        self._temporary[file] = name
        limit = max(size, 1 << 20) * MAX_ZSTD_RATIO
        written = 0
        try:
            with open(file, "rb") as source, os.fdopen(handle, "wb") as target:
                reader = zstandard.ZstdDecompressor().stream_reader(source)
                while block := reader.read(1 << 20):
                    written += len(block)
                    if written > limit:
                        raise SourceError(
                            f"{file}: decompresses to more than {limit} bytes "
                            f"({MAX_ZSTD_RATIO} times its size); refused"
                        )
                    target.write(block)
        except (zstandard.ZstdError, SourceError) as error:
            os.unlink(self._temporary.pop(file))
            if isinstance(error, SourceError):
                raise
            raise SourceError(f"{file}: not a readable zstd file ({error})") from None
        return name

    def _decoder(
        self, topic: Topic, own: Definition | None, strict: bool = True
    ) -> _TopicDecoder | None:
        """The decoder of ``topic``: its definition in the bag, else the caller's and the
        shipped ones for its type. When there is none: ``SourceError`` if ``strict`` (the
        caller asked for the topic), else a warning and None (the topic is skipped)."""
        try:
            return self._new_decoder(topic, own)
        except SourceError as error:
            if strict:
                raise
            self.warnings.append(f"{error}; its messages are skipped")
            return None

    def _new_decoder(self, topic: Topic, own: Definition | None) -> _TopicDecoder:
        if topic.serialization_format != "cdr":
            raise SourceError(
                f"{self.path}: {topic.name} is serialized as {topic.serialization_format!r}; "
                "btlog reads cdr"
            )
        if own is not None:
            return _TopicDecoder(self.path, topic, [own], own=True)
        candidates = [d for d in self.extra if d.type == topic.type]
        candidates += shipped_definitions(topic.type)
        if not candidates:
            raise SourceError(
                f"{self.path}: the bag holds no definition of {topic.type} ({topic.name}) "
                "and btlog ships none"
            )
        return _TopicDecoder(self.path, topic, candidates, own=False)

    def _decode(
        self, decoder: _TopicDecoder, data: bytes, t_ns: int, skipped: dict[str, _Undecodable]
    ) -> BagMessage | None:
        """The message, or None (counted in ``skipped``) when it does not decode; a topic
        none of whose first ``PROBE`` messages any known layout reads is refused."""
        topic = decoder.topic
        try:
            message = BagMessage(topic.name, topic.type, t_ns, decoder.decode(data))
        except (*_DECODE_ERRORS, zstandard.ZstdError, RecursionError, MemoryError) as error:
            if not decoder.own and decoder.decoded == 0 and decoder.failed >= PROBE:
                raise SourceError(
                    f"{self.path}: no known layout of {topic.type} reads the messages on "
                    f"{topic.name} (tried {decoder.tried})"
                ) from None
            note = skipped.setdefault(topic.name, _Undecodable(first_ns=t_ns))
            note.count += 1
            note.reason = note.reason or f"{type(error).__name__}: {error}"[:120]
            return None
        self.used[topic.name] = decoder.definition
        return message


# -- MCAP ------------------------------------------------------------------------------------
def _mcap_topics(file: str) -> dict[str, Topic]:
    """The channels of an MCAP file: from its summary, else (a bag cut short has none)
    from every record."""
    from mcap.reader import make_reader

    try:
        with open(file, "rb") as stream:
            summary = make_reader(stream).get_summary()
    except Exception:  # any damage: the walk below tells it
        summary = None
    if summary is not None:
        names = {i: s.name for i, s in summary.schemas.items()}
        return {
            c.topic: Topic(c.topic, names.get(c.schema_id, ""), c.message_encoding)
            for c in summary.channels.values()
        }
    topics: dict[str, Topic] = {}
    schemas: dict[int, str] = {}
    read = 0
    with _mcap_open(file) as (data, size):
        for opcode, buffer, body, end in records(data, size, Walk(file)):
            read += 1
            if opcode not in (Opcode.SCHEMA, Opcode.CHANNEL):
                continue
            record = _parsed(opcode, buffer, body, end)
            if record is None:
                continue
            if opcode == Opcode.SCHEMA:
                schemas[record.id] = record.name
            elif record.topic not in topics:
                name = schemas.get(record.schema_id, "")
                topics[record.topic] = Topic(record.topic, name, record.message_encoding)
    if read == 0:
        raise SourceError(f"{file}: not a readable rosbag2 MCAP file (no whole record)")
    return topics


@contextlib.contextmanager
def _mcap_open(file: str) -> Iterator[tuple[Any, int]]:
    try:
        with mapped(file) as (data, size):
            yield data, size
    except RecordingError as error:
        raise SourceError(str(error)) from None
    except OSError as error:
        raise SourceError(f"{file}: cannot read the bag: {error.strerror}") from None


def _parsed(opcode: int, buffer: Any, body: int, end: int) -> Any:
    """The record, or None when its body does not parse (no CRC guards records outside
    chunks; the caller counts it)."""
    try:
        return parse(opcode, buffer, body, end)
    except (McapError, ValueError, struct.error, EOFError, IndexError):
        return None


def _mcap_messages(
    bag: Bag, file: str, local: str, wanted: set[str] | None, skipped: dict[str, _Undecodable]
) -> Iterator[BagMessage]:
    walk = Walk(file)
    schemas: dict[int, Any] = {}
    channels: dict[int, tuple[Topic, Any]] = {}
    decoders: dict[int, _TopicDecoder] = {}
    unparsed = read = 0
    with _mcap_open(local) as (data, size):
        for opcode, buffer, body, end in records(data, size, walk):
            read += 1
            if opcode == Opcode.MESSAGE:
                if end - body < _MESSAGE_HEAD.size:
                    unparsed += 1
                    continue
                channel_id, _seq, log_time, _published = _MESSAGE_HEAD.unpack_from(buffer, body)
                known = channels.get(channel_id)
                if known is None or (wanted is not None and known[0].name not in wanted):
                    continue
                topic, schema = known
                payload = bytes(buffer[body + _MESSAGE_HEAD.size : end])
                decoder = decoders.get(channel_id)
                if decoder is None:
                    decoder = _mcap_decoder(bag, topic, schema, strict=wanted is not None)
                    if decoder is None:
                        channels.pop(channel_id)
                        continue
                    decoders[channel_id] = decoder
                message = bag._decode(decoder, payload, log_time, skipped)
                if message is not None:
                    yield message
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                record = _parsed(opcode, buffer, body, end)
                if record is None:
                    unparsed += 1
                elif opcode == Opcode.SCHEMA:
                    schemas[record.id] = record
                elif record.id not in channels:
                    schema = schemas.get(record.schema_id)
                    name = schema.name if schema is not None else ""
                    channels[record.id] = (
                        Topic(record.topic, name, record.message_encoding),
                        schema,
                    )
    if read == 0:
        raise SourceError(f"{file}: not a readable rosbag2 MCAP file (no whole record)")
    bag.warnings.extend(walk.warnings)
    if unparsed:
        bag.warnings.append(f"{file}: {unparsed} damaged record(s) outside chunks skipped")
    if walk.truncated:
        bag.warnings.append(
            f"{file}: the bag ends inside a record (a recording cut short?); "
            "read every whole message before the cut"
        )


def _mcap_decoder(bag: Bag, topic: Topic, schema: Any, strict: bool) -> _TopicDecoder | None:
    """The decoder of an MCAP topic: its schema's definition (``ros2msg``), else known ones."""
    own = None
    if schema is not None and schema.encoding == "ros2msg" and schema.data:
        try:
            text = bytes(schema.data).decode("utf-8")
        except UnicodeDecodeError:
            raise SourceError(f"{bag.path}: the schema of {topic.name} is not UTF-8 text") from None
        own = Definition(topic.type, text, "bag")
    return bag._decoder(topic, own, strict)


# -- SQLite ----------------------------------------------------------------------------------
def _connect(file: str) -> sqlite3.Connection:
    try:
        con = sqlite3.connect(Path(file).resolve().as_uri() + "?mode=ro", uri=True)
        names = {row[0] for row in con.execute("SELECT name FROM sqlite_master")}
    except sqlite3.Error as error:
        raise SourceError(f"{file}: not a readable SQLite file ({error})") from None
    missing = [t for t in ("topics", "messages") if t not in names]
    if missing:
        con.close()
        raise SourceError(f"{file}: no table {', '.join(missing)}: not a rosbag2 SQLite file")
    return con


def _sqlite_topics(file: str) -> dict[str, Topic]:
    return {topic.name: topic for topic in _sqlite_topic_ids(file).values()}


def _sqlite_topic_ids(file: str, con: sqlite3.Connection | None = None) -> dict[int, Topic]:
    own = con is None
    con = con or _connect(file)
    try:
        rows = con.execute("SELECT id, name, type, serialization_format FROM topics").fetchall()
    except sqlite3.Error as error:
        raise SourceError(f"{file}: table topics cannot be read ({error})") from None
    finally:
        if own:
            con.close()
    return {int(i): Topic(str(n), str(t), str(f)) for i, n, t, f in rows}


def _sqlite_definitions(con: sqlite3.Connection) -> dict[str, Definition]:
    """The bag's own definitions (Jazzy and later), ``ros2msg`` ones only."""
    try:
        rows = con.execute(
            "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
        ).fetchall()
    except sqlite3.Error:
        return {}
    return {
        str(t): Definition(str(t), str(text), "bag")
        for t, encoding, text in rows
        if encoding == "ros2msg" and text
    }


def _sqlite_messages(
    bag: Bag, file: str, local: str, wanted: set[str] | None, skipped: dict
) -> Iterator[BagMessage]:
    con = _connect(local)
    try:
        topics = _sqlite_topic_ids(file, con)
        chosen = {i: t for i, t in topics.items() if wanted is None or t.name in wanted}
        if not chosen:
            return
        own = _sqlite_definitions(con)
        decoders = {}
        for topic_id, topic in chosen.items():
            decoder = bag._decoder(topic, own.get(topic.type), strict=wanted is not None)
            if decoder is not None:
                decoders[topic_id] = decoder
                with contextlib.suppress(sqlite3.Error):
                    query = "SELECT data FROM messages WHERE topic_id = ? ORDER BY id"
                    decoder.settle(row[0] for row in con.execute(query, (topic_id,)))
        chosen = {i: t for i, t in chosen.items() if i in decoders}
        if not chosen:
            return
        marks = ",".join("?" * len(chosen))
        query = f"SELECT topic_id, timestamp, data FROM messages WHERE topic_id IN ({marks}) "
        rows = 0
        try:
            for topic_id, timestamp, data in con.execute(query + "ORDER BY id", list(chosen)):
                rows += 1
                if not isinstance(data, bytes) or not isinstance(timestamp, int):
                    note = skipped.setdefault(chosen[topic_id].name, _Undecodable())
                    note.count += 1
                    note.reason = note.reason or "not a message row"
                    continue
                message = bag._decode(decoders[topic_id], data, timestamp, skipped)
                if message is not None:
                    yield message
        except sqlite3.Error as error:
            if rows == 0:
                raise SourceError(f"{file}: table messages cannot be read ({error})") from None
            bag.warnings.append(
                f"{file}: the database is damaged after {rows} message(s) ({error}); "
                "read the messages before the damage"
            )
    finally:
        con.close()


def _uncompressed(data: bytes) -> bytes:
    """A message's bytes, decompressed when rosbag2 compressed it (``compression_mode:
    MESSAGE``: a zstd frame, which CDR's header ``00 0x`` never starts like)."""
    if data[:4] == ZSTD_MAGIC:
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=MAX_MESSAGE)
    return data


_TOPIC_READERS: dict[str, Callable[[str], dict[str, Topic]]] = {
    "mcap": _mcap_topics,
    "sqlite3": _sqlite_topics,
}


# -- opening -------------------------------------------------------------------------------
def storage_of(file: str | os.PathLike) -> str | None:
    """``"mcap"`` or ``"sqlite3"`` from a storage file's first bytes (a ``.zstd`` file by
    its name), None for anything else."""
    name = os.fspath(file)
    try:
        with open(name, "rb") as stream:
            head = stream.read(16)
    except OSError:
        return None
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(SQLITE_MAGIC):
        return "sqlite3"
    if head.startswith(ZSTD_MAGIC):
        inner = name.removesuffix(".zstd")
        return "mcap" if inner.endswith(".mcap") else "sqlite3" if inner.endswith(".db3") else None
    return None


def is_rosbag2_sqlite(file: str | os.PathLike) -> bool:
    """True when the SQLite file has rosbag2's tables (``topics`` and ``messages``)."""
    try:
        con = sqlite3.connect(Path(file).resolve().as_uri() + "?mode=ro", uri=True)
        try:
            names = {row[0] for row in con.execute("SELECT name FROM sqlite_master")}
        finally:
            con.close()
    except sqlite3.Error:
        return False
    return {"topics", "messages"} <= names


def open_bag(path: str | os.PathLike, extra: Iterable[Definition] = ()) -> Bag:
    """Open the bag at ``path``: a rosbag2 folder, or one ``.mcap``/``.db3`` file.
    ``extra`` definitions are tried before the shipped ones for SQLite bags."""
    name = os.fspath(path)
    warnings: list[str] = []
    if os.path.isdir(name):
        metadata, files, warnings = _folder_files(name)
    elif os.path.exists(name):
        metadata, files = {}, [name]
    else:
        raise SourceError(f"{name}: no such file or folder")
    kinds = {storage_of(f) for f in files}
    if None in kinds:
        odd = next(f for f in files if storage_of(f) is None)
        raise SourceError(f"{odd}: not an MCAP or SQLite file")
    if len(kinds) != 1:
        raise SourceError(f"{name}: a bag with both MCAP and SQLite files")
    (storage,) = kinds
    return Bag(name, str(storage), files, metadata, extra, warnings)


def _folder_files(folder: str) -> tuple[dict[str, Any], list[str], list[str]]:
    """The bag information of ``metadata.yaml`` (empty without one), the storage files
    and warnings about files it lists that are missing."""
    meta_path = os.path.join(folder, "metadata.yaml")
    if os.path.exists(meta_path):
        try:
            data, _lines = documents.read(meta_path, "bag metadata file")
        except documents.DocumentError as error:
            raise SourceError(str(error)) from None
        info = data.get("rosbag2_bagfile_information") if isinstance(data, dict) else None
        listed = info.get("relative_file_paths") if isinstance(info, dict) else None
        if not isinstance(listed, list) or not all(isinstance(f, str) for f in listed):
            raise SourceError(f"{meta_path}: no rosbag2_bagfile_information.relative_file_paths")
        files = []
        for relative in listed:
            if os.path.isabs(relative) or ".." in Path(relative).parts:
                raise SourceError(f"{meta_path}: file {relative!r} is outside the bag folder")
            file = os.path.join(folder, relative)
            if not os.path.exists(file) and os.path.exists(file + ".zstd"):
                file += ".zstd"
            files.append(file)
        present = [f for f in files if os.path.isfile(f)]
        if not present:
            raise SourceError(f"{meta_path}: none of the bag's files is in the folder")
        warnings = [f"{meta_path}: the bag's file {f} is missing; skipped" for f in files
                    if f not in present]  # fmt: skip
        return dict(info), present, warnings  # type: ignore[arg-type]
    found = [
        os.path.join(folder, f)
        for f in os.listdir(folder)
        if f.endswith((".mcap", ".db3", ".mcap.zstd", ".db3.zstd"))
    ]
    if not found:
        raise SourceError(f"{folder}: a folder with no metadata.yaml, .mcap or .db3 file")

    def split(file: str) -> tuple[int, str]:
        number = _SPLIT.search(file)
        return (int(number.group(1)) if number else 0, file)

    return {}, sorted(found, key=split), []

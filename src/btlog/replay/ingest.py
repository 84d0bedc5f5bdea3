"""Bulk ingestion: one recording into the DuckDB read model (design §5).

The read model is a projection of the MCAP file, rebuilt from it at will, so ingestion is
a pure function of the file's bytes. It must be fast (millions of events a second), which
rules out anything done per row in Python: ``executemany`` manages a few thousand rows a
second, and even decoding each event into Python objects costs a microsecond or more.
So Python only touches each *message* (one per tick or per ~1000 grouped events) and
C++ parsers touch each *row*:

1. **Walk** the file's records with ``struct`` (``_McapScan``): chunk headers, zstd/lz4
   decompression, the records inside each chunk. A cut file stops at its last whole
   record, as ``btlog.record.reader`` does; this walk is ~10x faster than the ``mcap``
   package's per-message objects, which is why that reader is not used here.
2. **Cut** each ``/btlog/events`` payload into its two row lists without decoding it.
   Status rows hold only integers and the four status names, so the status list is the
   bytes between ``,"status":[`` and the first ``],"writes":[``. Joined, with ``[``
   turned into a newline and ``"`` and ``]`` deleted (one ``bytes.translate``), status
   rows *are* CSV: ``seq,t_ns,tick,uid,PREV,STATUS,``. Tick rows likewise. Blackboard
   rows carry arbitrary JSON values, so each message's write list becomes one line of
   newline-delimited JSON.
3. **Load**, in batches of ~48 MB, while the walk goes on (``_Loader``): status and tick
   rows through Arrow's multithreaded CSV reader into the tables, write rows through
   DuckDB's ``read_json``, each in its own worker thread (both parsers release the GIL).
   Anything the fast path does not recognise (another key order, whitespace, an unknown
   status) is decoded with orjson and loaded through Arrow instead: slower, never wrong.

Then the small tables (runs, nodes, mutations) and the **snapshots**: one fold of the
whole run with ``StateProjection`` (the only fold) storing, every ``snapshot_every``
events, the state at that point *and* the block of events up to the next snapshot
(compressed). The state at any moment is then one row plus a fold of at most
``snapshot_every`` events (``btlog.replay.database``). Building them runs every event
through Python once: the dominant cost of a long run, timed and reported separately.

Internal tables start with ``_``: ``_snapshots``, ``_mutations`` (the full mutation
messages, to rebuild inserted nodes), ``_answers`` (questions asked live) and
``_ingest`` (what was read and from which file version, for the cache).
"""

from __future__ import annotations

import mmap
import os
import struct
import tempfile
import time
from bisect import bisect_left, bisect_right
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import duckdb
import lz4.frame
import orjson
import pyarrow as pa
import pyarrow.compute as pa_compute
import pyarrow.csv as pa_csv
import zstandard

import btlog
from btlog.events import BlackboardWrite, TreeMutation
from btlog.record import format as fmt
from btlog.record.reader import RecordingError, decode_metadata, open_mcap, read_metadata
from btlog.state import State, StateProjection
from btlog.status import Status
from btlog.tree.model import Tree

#: The layout of the read model; part of the cache key (bump when a table changes).
INGEST_VERSION = "2"
#: Events between two snapshots. ``state_at`` reads one snapshot row and decodes and
#: folds at most this many events (~2.5 µs each, all told), on top of a fixed ~2.5 ms
#: (the query, the tree copy). Measured (``bench_replay.py --sweep``, 2M events): median
#: 2.8-3.1 ms at K = 256 and 512, 4.0 at 1024, 4.7 at 2048, 6.3 at 4096, for the same
#: build time; 512 keeps most of the gain with a quarter of the snapshot rows of 256.
DEFAULT_SNAPSHOT_EVERY = 512
#: Events fetched from DuckDB per query while building snapshots.
FOLD_BATCH = 1 << 18

STATUS_VALUES = ("IDLE", "RUNNING", "SUCCESS", "FAILURE", "SKIPPED")
_STATUS_BY_CODE = tuple(Status)
#: Status is numbered as BT.CPP numbers it; the ENUM must use the same order.
assert [s.name for s in Status] == list(STATUS_VALUES)

SCHEMA = (
    "CREATE TYPE status AS ENUM ('IDLE', 'RUNNING', 'SUCCESS', 'FAILURE', 'SKIPPED')",
    """CREATE TABLE runs (run_id VARCHAR, file VARCHAR, tree_name VARCHAR,
        started_at TIMESTAMP, duration_ns BIGINT, final_status status, domain VARCHAR,
        seed BIGINT, metadata JSON)""",
    """CREATE TABLE nodes (run_id VARCHAR, uid INTEGER, parent_uid INTEGER, idx INTEGER,
        depth INTEGER, kind VARCHAR, type VARCHAR, name VARCHAR, path VARCHAR, ports JSON,
        added_seq BIGINT)""",
    """CREATE TABLE transitions (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        uid INTEGER, prev_status status, status status)""",
    """CREATE TABLE blackboard (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        scope VARCHAR, key VARCHAR, value JSON, type VARCHAR, writer_uid INTEGER)""",
    """CREATE TABLE ticks (run_id VARCHAR, tick BIGINT, start_ns BIGINT, end_ns BIGINT,
        root_status status)""",
    """CREATE TABLE mutations (run_id VARCHAR, seq BIGINT, t_ns BIGINT, op VARCHAR,
        parent_uid INTEGER, after_uid INTEGER, inserted_root_uid INTEGER, question VARCHAR)""",
    """CREATE TABLE _mutations (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        message JSON)""",
    """CREATE TABLE _answers (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        question VARCHAR, intent VARCHAR, answer VARCHAR)""",
    """CREATE TABLE _snapshots (run_id VARCHAR, seq BIGINT, t_ns BIGINT, tick BIGINT,
        first_t_ns BIGINT, first_tick BIGINT, state JSON, events BLOB)""",
    """CREATE TABLE _ingest (run_id VARCHAR, file VARCHAR, size BIGINT, mtime_ns BIGINT,
        schema_version VARCHAR, ingest_version VARCHAR, events BIGINT, last_tick BIGINT,
        truncated BOOLEAN, warnings JSON, snapshot_every BIGINT, tree JSON,
        ingest_seconds DOUBLE, snapshot_seconds DOUBLE)""",
)
#: The tables of design §5, the ones users write SQL against.
PUBLIC_TABLES = ("runs", "nodes", "transitions", "blackboard", "ticks", "mutations")
INTERNAL_TABLES = ("_mutations", "_answers", "_snapshots", "_ingest")


def first_row(con, query: str, params: dict | list | None = None) -> tuple | None:
    """The first row of ``query`` (None if it has none). The result is fetched to its
    end: DuckDB refuses new work on a connection with an unfinished result."""
    rows = (
        con.execute(query, params).fetchall()
        if params is not None
        else con.execute(query).fetchall()
    )
    return rows[0] if rows else None


def _identifier(name: str) -> str:
    """A quoted SQL identifier."""
    return '"' + name.replace('"', '""') + '"'


def create_schema(con: duckdb.DuckDBPyConnection) -> None:
    """Create the ``status`` type and every table in the connection's current catalog."""
    for statement in SCHEMA:
        con.execute(statement)


@dataclass
class IngestReport:
    """What one ingestion read and how long it took (seconds). ``events`` counts seqs
    (last seq + 1): the number of events of a gap-free run."""

    run_id: str
    file: str
    events: int
    transitions: int
    writes: int
    ticks: int
    mutations: int
    truncated: bool
    warnings: list[str]
    ingest_seconds: float
    snapshot_seconds: float
    snapshots: int
    snapshot_every: int

    @property
    def events_per_second(self) -> float:
        """Events loaded per second of table ingestion (snapshots excluded)."""
        return self.events / self.ingest_seconds if self.ingest_seconds else 0.0


# -- 1 and 2. walking the MCAP records, cutting the payloads ------------------------------------
_HEAD = struct.Struct("<BQ")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_CHUNK_HEAD = struct.Struct("<QQQI")
_MAGIC = b"\x89MCAP0\r\n"
_OP_FOOTER, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_METADATA = 0x02, 0x04, 0x05, 0x06, 0x0C
_MESSAGE_HEAD = 2 + 4 + 8 + 8  # channel id, sequence, log time, publish time

_EVENTS_HEAD = b'{"tick":'
_STATUS_KEY = b',"status":['
_WRITES_KEY = b'],"writes":['
_TICKS_HEAD = b'{"ticks":['
_TAIL = b"]}"
#: ``[`` (a row starts) becomes a newline; ``"`` and ``]`` are deleted:
#: ``[1,2,"IDLE","RUNNING"],`` → ``⏎1,2,IDLE,RUNNING,``
_ROWS_TO_CSV = bytes.maketrans(b"[", b"\n")
#: Bytes of rows gathered before they are handed to the loaders (while the walk goes on).
BATCH_BYTES = 48 << 20


@dataclass
class RowBatch:
    """Rows of consecutive messages, still bytes: status and tick rows as comma-joined
    row lists (``[…],[…],``), write rows as one row list per message."""

    status: bytearray = field(default_factory=bytearray)
    writes: list[bytes | memoryview] = field(default_factory=list)
    ticks: bytearray = field(default_factory=bytearray)

    def __bool__(self) -> bool:
        return bool(self.status or self.writes or self.ticks)


@dataclass
class _Collected:
    """What a walk found besides the bulk rows: metadata, tree, the rare messages, and
    the messages the fast path did not recognise."""

    metadata: dict[str, str] | None = None
    tree: dict | None = None
    mutations: list[dict] = field(default_factory=list)
    answers: list[dict] = field(default_factory=list)
    other_events: list[bytes] = field(default_factory=list)
    other_ticks: list[bytes] = field(default_factory=list)
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)


class _McapScan:
    """Walks the records of an MCAP file (steps 1 and 2 of the module docstring), handing
    each ``RowBatch`` of about ``BATCH_BYTES`` to ``on_batch`` as soon as it is full."""

    def __init__(self, path: str, on_batch: Callable[[RowBatch], None]) -> None:
        self.path = path
        self.out = _Collected()
        self.topics: dict[int, str] = {}
        self.events_channel: bytes | None = None
        self.batch = RowBatch()
        self.on_batch = on_batch

    def run(self) -> _Collected:
        """Walk the whole file; the last batch is handed over too."""
        file, size = open_mcap(self.path)
        with file:
            data = mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ)
            try:
                self._top_level(data, size)
            finally:
                data.close()
        if self.batch:
            self.on_batch(self.batch)
            self.batch = RowBatch()
        return self.out

    def _top_level(self, data: mmap.mmap, size: int) -> None:
        position = len(_MAGIC)
        while position + _HEAD.size <= size:
            opcode, length = _HEAD.unpack_from(data, position)
            body = position + _HEAD.size
            end = body + length
            if end > size:
                break
            if opcode == _OP_FOOTER:
                return
            try:
                self._top_record(opcode, data, body, end)
            except (ValueError, struct.error, RuntimeError) as error:
                self.out.truncated = True
                self.out.warnings.append(
                    f"{self.path}: damaged record, reading stopped there: "
                    f"{type(error).__name__}: {error}"
                )
                return
            if len(self.batch.status) + len(self.batch.ticks) >= BATCH_BYTES:
                self.on_batch(self.batch)
                self.batch = RowBatch()
            position = end
        self.out.truncated = True

    def _top_record(self, opcode: int, data: mmap.mmap, body: int, end: int) -> None:
        if opcode == _OP_CHUNK:
            self._records(self._decompress(data, body))
        elif opcode in (_OP_MESSAGE, _OP_CHANNEL):
            self._records(data[body - _HEAD.size : end])
        elif opcode == _OP_METADATA and self.out.metadata is None:
            self._metadata(data[body:end])

    @staticmethod
    def _decompress(data: mmap.mmap, body: int) -> bytes:
        _start, _end, size, _crc = _CHUNK_HEAD.unpack_from(data, body)
        position = body + _CHUNK_HEAD.size
        (name_length,) = _U32.unpack_from(data, position)
        compression = data[position + 4 : position + 4 + name_length]
        position += 4 + name_length
        (length,) = _U64.unpack_from(data, position)
        raw = data[position + 8 : position + 8 + length]
        if compression == b"zstd":
            return zstandard.ZstdDecompressor().decompress(raw, max_output_size=size)
        if compression == b"lz4":
            return lz4.frame.decompress(raw)
        if compression:
            raise ValueError(f"unknown chunk compression {compression.decode(errors='replace')}")
        return raw

    def _records(self, buffer: bytes) -> None:
        """The records of a chunk (or one top-level record). The events messages are cut
        here, inline: this loop runs once per message of the run."""
        head, events, view = _HEAD.unpack_from, self.events_channel, memoryview(buffer)
        status_rows, write_rows = self.batch.status, self.batch.writes
        find, starts, ends = buffer.find, buffer.startswith, buffer.endswith
        position, size = 0, len(buffer)
        while position < size:
            opcode, length = head(buffer, position)
            body = position + 9
            end = body + length
            if end > size:
                raise ValueError("a record overruns its chunk")
            position = end
            if opcode == _OP_MESSAGE and events is not None and starts(events, body):
                start = body + _MESSAGE_HEAD
                status = find(_STATUS_KEY, start + 8, start + 40) + 11
                writes = find(_WRITES_KEY, status, end) if status > 10 else -1
                if writes < 0 or not starts(_EVENTS_HEAD, start) or not ends(_TAIL, start, end):
                    self.out.other_events.append(buffer[start:end])
                    continue
                if writes > status:
                    status_rows += view[status:writes]
                    status_rows += b","
                if end - 2 > writes + 12:
                    write_rows.append(view[writes + 12 : end - 2])
            elif opcode == _OP_MESSAGE:
                self._message(buffer, body, end)
            elif opcode == _OP_CHANNEL:
                events = self._channel(buffer, body)

    def _channel(self, buffer: bytes, body: int) -> bytes | None:
        (channel,) = _U16.unpack_from(buffer, body)
        (length,) = _U32.unpack_from(buffer, body + 4)
        topic = buffer[body + 8 : body + 8 + length].decode()
        self.topics[channel] = topic
        if topic == fmt.EVENTS_TOPIC:
            self.events_channel = buffer[body : body + 2]
        return self.events_channel

    def _message(self, buffer: bytes, body: int, end: int) -> None:
        topic = self.topics.get(_U16.unpack_from(buffer, body)[0])
        payload = buffer[body + _MESSAGE_HEAD : end]
        out = self.out
        if topic == fmt.TICKS_TOPIC:
            if payload.startswith(_TICKS_HEAD) and payload.endswith(_TAIL):
                if len(payload) > len(_TICKS_HEAD) + 2:
                    self.batch.ticks += memoryview(payload)[len(_TICKS_HEAD) : -2]
                    self.batch.ticks += b","
            else:
                out.other_ticks.append(payload)
        elif topic == fmt.MUTATIONS_TOPIC:
            out.mutations.append(orjson.loads(payload))
        elif topic == fmt.ANSWERS_TOPIC:
            out.answers.append(orjson.loads(payload))
        elif topic == fmt.TREE_TOPIC and out.tree is None:
            out.tree = orjson.loads(payload)

    def _metadata(self, body: bytes) -> None:
        (name_length,) = _U32.unpack_from(body, 0)
        name = body[4 : 4 + name_length].decode()
        if name != fmt.METADATA_NAME:
            return
        position = 4 + name_length + 4
        record: dict[str, str] = {}
        while position < len(body):
            key, position = _string(body, position)
            value, position = _string(body, position)
            record[key] = value
        self.out.metadata = record


def _string(body: bytes, position: int) -> tuple[str, int]:
    (length,) = _U32.unpack_from(body, position)
    end = position + 4 + length
    return body[position + 4 : end].decode(), end


# -- 3. loading the rows ----------------------------------------------------------------------
class _Lane:
    """One worker thread with its own DuckDB cursor, running jobs in submission order."""

    def __init__(self, con: duckdb.DuckDBPyConnection, name: str) -> None:
        self.cursor = con.cursor()
        catalog, schema = first_row(con, "SELECT current_database(), current_schema()")
        self.cursor.execute(f"USE {_identifier(catalog)}.{_identifier(schema)}")
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"btlog-{name}")
        self.pending: deque[Future] = deque()
        self.closed = False

    def submit(self, job: Callable[..., None], *args: Any) -> None:
        """Queue ``job(cursor, *args)``, waiting while two are queued (bounds memory)."""
        while len(self.pending) >= 2:
            self.pending.popleft().result()
        self.pending.append(self.pool.submit(job, self.cursor, *args))

    def finish(self) -> None:
        """Wait for every queued job; re-raises a job's error."""
        while self.pending:
            self.pending.popleft().result()

    def close(self) -> None:
        """Cancel what has not started, wait for what has, release the cursor (once)."""
        for future in self.pending:
            future.cancel()
        self.pending.clear()
        self.pool.shutdown(wait=True)
        if not self.closed:
            self.closed = True
            self.cursor.close()


class _Loader:
    """Loads ``RowBatch``es into DuckDB while the walk goes on, in two lanes (status rows;
    write and tick rows), each in file order. DuckDB and Arrow release the GIL while they
    parse, so walking, parsing CSV and parsing JSON overlap."""

    def __init__(self, con: duckdb.DuckDBPyConnection, run_id: str, folder: Path) -> None:
        self.run_id = run_id
        self.folder = folder
        self.rows = _Lane(con, "rows")
        self.writes = _Lane(con, "writes")
        self.batches = 0

    def submit(self, batch: RowBatch) -> None:
        """Queue a batch's rows."""
        self.batches += 1
        run_id = self.run_id
        if batch.status:
            self.rows.submit(_load_csv_rows, run_id, "transitions", batch.status, _STATUS_CSV)
        if batch.writes:
            self.writes.submit(
                _load_write_rows, run_id, batch.writes, self.folder / f"writes-{self.batches}.jsonl"
            )
        if batch.ticks:
            self.writes.submit(_load_csv_rows, run_id, "ticks", batch.ticks, _TICKS_CSV)

    def finish(self) -> None:
        """Wait for every queued batch; re-raises a batch's error."""
        try:
            self.rows.finish()
            self.writes.finish()
        finally:
            self.close()

    def close(self) -> None:
        """Stop both lanes."""
        self.rows.close()
        self.writes.close()


_STATUS_TYPE = pa.dictionary(pa.int32(), pa.string())
#: (column names, Arrow types) of the CSV made from status rows and from tick rows; the
#: last, empty column comes from the comma after every row.
_STATUS_CSV = (
    ("seq", "t_ns", "tick", "uid", "prev_status", "status"),
    (pa.int64(), pa.int64(), pa.int64(), pa.int32(), _STATUS_TYPE, _STATUS_TYPE),
)
_TICKS_CSV = (
    ("tick", "start_ns", "end_ns", "root_status"),
    (pa.int64(), pa.int64(), pa.int64(), _STATUS_TYPE),
)


def _load_csv_rows(
    con,
    run_id: str,
    table: str,
    rows: bytearray,
    layout: tuple[tuple[str, ...], tuple[pa.DataType, ...]],
) -> None:
    """Rows ``[a,b,"X"],[c,d,"Y"],`` become the CSV lines ``a,b,X,`` (step 2), parsed
    by Arrow's multithreaded CSV reader and inserted; rows it refuses are decoded as JSON
    instead."""
    if not rows:
        return
    body = rows.translate(_ROWS_TO_CSV, b'"]')
    names, types = layout
    try:
        parsed = pa_csv.read_csv(
            pa.py_buffer(memoryview(body)[1:]),
            read_options=pa_csv.ReadOptions(column_names=[*names, "_"], block_size=8 << 20),
            parse_options=pa_csv.ParseOptions(quote_char=False, double_quote=False),
            convert_options=pa_csv.ConvertOptions(
                include_columns=list(names),
                column_types=dict(zip(names, types, strict=True)),
                strings_can_be_null=False,
            ),
        )
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        parsed = None
    del body
    canonical = None if parsed is None else _canonical_statuses(parsed)
    if canonical is None:
        _insert_rows(con, run_id, table, orjson.loads(b"[" + bytes(rows[:-1]) + b"]"))
        return
    _insert_arrow(con, table, run_id, canonical)


_STATUS_DICTIONARY = pa.array(STATUS_VALUES)


def _canonical_statuses(table: pa.Table) -> pa.Table | None:
    """``table`` with each status column re-encoded over the ENUM's own dictionary (so
    DuckDB takes the codes as they are); None if a column holds another name."""
    for position, column in enumerate(table.columns):
        if not pa.types.is_dictionary(column.type):
            continue
        chunks = []
        for chunk in column.chunks:
            codes = pa_compute.index_in(chunk.dictionary, value_set=_STATUS_DICTIONARY)
            if codes.null_count:
                return None
            indices = pa_compute.take(codes.cast(pa.int8()), chunk.indices)
            chunks.append(pa.DictionaryArray.from_arrays(indices, _STATUS_DICTIONARY))
        table = table.set_column(
            position,
            table.field(position).name,
            pa.chunked_array(chunks, pa.dictionary(pa.int8(), pa.string())),
        )
    return table


def _load_write_rows(con, run_id: str, lines: list[bytes | memoryview], path: Path) -> None:
    """Each message's write rows are one JSON line ``{"w":[[…],[…]]}``; DuckDB unnests."""
    if not lines:
        return
    longest = max(len(line) for line in lines) + 1024
    with open(path, "wb") as file:
        file.write(b'{"w":[' + b']}\n{"w":['.join(lines) + b"]}\n")
    try:
        con.execute(
            """INSERT INTO blackboard
            SELECT $run_id, r[1]::BIGINT, r[2]::BIGINT, r[3]::BIGINT, r[4] ->> '$',
                   r[5] ->> '$', coalesce(r[6], 'null'::JSON), r[7] ->> '$', r[8]::INTEGER
            FROM (SELECT unnest(w) AS r FROM read_json($path, format = 'newline_delimited',
                  columns = {'w': 'JSON[][]'}, maximum_object_size = $longest))""",
            {"run_id": run_id, "path": str(path), "longest": max(longest, 1 << 20)},
        )
    except duckdb.Error:
        _insert_write_rows(con, run_id, orjson.loads(b"[" + b",".join(lines) + b"]"))
    finally:
        path.unlink()


def _insert_status_rows(con, run_id: str, rows: list[list]) -> None:
    if not rows:
        return
    columns = list(zip(*rows, strict=True))
    table = pa.table(
        {
            "seq": pa.array(columns[0], pa.int64()),
            "t_ns": pa.array(columns[1], pa.int64()),
            "tick": pa.array(columns[2], pa.int64()),
            "uid": pa.array(columns[3], pa.int32()),
            "prev_status": pa.array(columns[4], pa.string()),
            "status": pa.array(columns[5], pa.string()),
        }
    )
    _insert_arrow(con, "transitions", run_id, table)


def _insert_write_rows(con, run_id: str, rows: list[list]) -> None:
    if not rows:
        return
    columns = list(zip(*rows, strict=True))
    values = [orjson.dumps(v).decode() for v in columns[5]]
    table = pa.table(
        {
            "seq": pa.array(columns[0], pa.int64()),
            "t_ns": pa.array(columns[1], pa.int64()),
            "tick": pa.array(columns[2], pa.int64()),
            "scope": pa.array(columns[3], pa.string()),
            "key": pa.array(columns[4], pa.string()),
            "value": pa.array(values, pa.string()),
            "type": pa.array(columns[6], pa.string()),
            "writer_uid": pa.array(columns[7], pa.int32()),
        }
    )
    _insert_arrow(con, "blackboard", run_id, table)


def _insert_tick_rows(con, run_id: str, rows: list[list]) -> None:
    if not rows:
        return
    columns = list(zip(*rows, strict=True))
    table = pa.table(
        {
            "tick": pa.array(columns[0], pa.int64()),
            "start_ns": pa.array(columns[1], pa.int64()),
            "end_ns": pa.array(columns[2], pa.int64()),
            "root_status": pa.array(columns[3], pa.string()),
        }
    )
    _insert_arrow(con, "ticks", run_id, table)


def _insert_rows(con, run_id: str, table: str, rows: list[list]) -> None:
    """Insert decoded JSON rows (the slow path) into ``table``."""
    inserts = {
        "transitions": _insert_status_rows,
        "blackboard": _insert_write_rows,
        "ticks": _insert_tick_rows,
    }
    inserts[table](con, run_id, rows)


def _insert_arrow(con, table_name: str, run_id: str, table: pa.Table) -> None:
    """Insert an Arrow table whose columns are the table's, without ``run_id``."""
    view = f"_arrow_{table_name}"
    con.register(view, table)
    try:
        names = ", ".join(table.column_names)
        con.execute(
            f"INSERT INTO {table_name} (run_id, {names}) SELECT $run_id, {names} FROM {view}",
            {"run_id": run_id},
        )
    finally:
        con.unregister(view)


def _load_other_messages(con, run_id: str, collected: _Collected, name: str) -> None:
    """The messages the fast path did not recognise, decoded one by one."""
    status: list[list] = []
    writes: list[list] = []
    try:
        for payload in collected.other_events:
            message = orjson.loads(payload)
            status.extend(message.get("status", ()))
            writes.extend(message.get("writes", ()))
        ticks = [
            row
            for payload in collected.other_ticks
            for row in orjson.loads(payload).get("ticks", ())
        ]
        _insert_status_rows(con, run_id, status)
        _insert_write_rows(con, run_id, writes)
        _insert_tick_rows(con, run_id, ticks)
    except (ValueError, TypeError, AttributeError, IndexError, duckdb.Error) as error:
        raise RecordingError(
            f"{name}: a message does not follow the btlog format: {type(error).__name__}: {error}"
        ) from None


# -- the small tables ---------------------------------------------------------------------
def short_run_id(metadata: dict[str, Any], path: str) -> str:
    """A short, stable id: the first 8 letters and digits of the metadata's run id (or of
    a hash of the file's path when the metadata has none)."""
    letters = "".join(c for c in str(metadata.get("run_id", "")).lower() if c.isalnum())
    if len(letters) >= 4 and letters.isascii():
        return letters[:8]
    import hashlib

    return hashlib.sha1(os.path.abspath(path).encode()).hexdigest()[:8]


def _node_rows(tree: dict, mutations: list[dict]) -> list[tuple]:
    """(uid, parent_uid, idx, depth, kind, type, name, path, ports, added_seq) per node:
    the recorded tree's, then each mutation's inserted nodes (as they were inserted)."""
    depth: dict[int, int] = {}
    rows = []
    batches = [(None, tree["nodes"])] + [(m["seq"], m["nodes"]) for m in mutations]
    for added_seq, records in batches:
        for record in records:
            parent = record.get("parent_uid")
            depth[record["uid"]] = 0 if parent is None else depth.get(parent, -1) + 1
            rows.append(
                (
                    record["uid"],
                    parent,
                    record.get("idx", 0),
                    depth[record["uid"]],
                    record["kind"],
                    record["type"],
                    record.get("name", ""),
                    record.get("path", ""),
                    orjson.dumps(record.get("ports", {})).decode(),
                    added_seq,
                )
            )
    return rows


def _insert_nodes(con, run_id: str, tree: dict, mutations: list[dict]) -> None:
    names = (
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
    )
    types = (
        pa.int32(),
        pa.int32(),
        pa.int32(),
        pa.int32(),
        pa.string(),
        pa.string(),
        pa.string(),
        pa.string(),
        pa.string(),
        pa.int64(),
    )
    rows = _node_rows(tree, mutations)
    columns = list(zip(*rows, strict=True)) if rows else [()] * len(names)
    table = pa.table({n: pa.array(c, t) for n, c, t in zip(names, columns, types, strict=True)})
    _insert_arrow(con, "nodes", run_id, table)


def _insert_mutations(con, run_id: str, mutations: list[dict]) -> None:
    for message in mutations:
        nodes = message.get("nodes") or [{}]
        con.execute(
            "INSERT INTO mutations VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            [
                run_id,
                message["seq"],
                message["t_ns"],
                message["op"],
                message["parent_uid"],
                message.get("after_uid"),
                message.get("inserted_root_uid", nodes[0].get("uid")),
                message.get("question", ""),
            ],
        )
        con.execute(
            "INSERT INTO _mutations VALUES ($1, $2, $3, $4, $5)",
            [
                run_id,
                message["seq"],
                message["t_ns"],
                message.get("tick", 0),
                orjson.dumps(message).decode(),
            ],
        )


def _insert_answers(con, run_id: str, answers: list[dict]) -> None:
    for message in answers:
        con.execute(
            "INSERT INTO _answers VALUES ($1, $2, $3, $4, $5, $6, $7)",
            [
                run_id,
                message.get("seq"),
                message.get("t_ns"),
                message.get("tick"),
                message.get("question"),
                message.get("intent"),
                message.get("answer"),
            ],
        )


@dataclass(frozen=True)
class Extent:
    """A run's extent as ingested: event count, last seq, times and ticks."""

    events: int
    last_seq: int | None
    last_t_ns: int
    last_tick: int
    duration_ns: int
    final_status: str | None


def _extent(con, run_id: str) -> Extent:
    events, last_seq, last_t, last_tick = first_row(
        con,
        """
        SELECT count(*), max(seq), max(t_ns), max(tick) FROM (
            SELECT seq, t_ns, tick FROM transitions WHERE run_id = $run_id
            UNION ALL SELECT seq, t_ns, tick FROM blackboard WHERE run_id = $run_id
            UNION ALL SELECT seq, t_ns, tick FROM _mutations WHERE run_id = $run_id)""",
        {"run_id": run_id},
    )
    tick_end, tick_max = first_row(
        con, "SELECT max(end_ns), max(tick) FROM ticks WHERE run_id = $run_id", {"run_id": run_id}
    )
    final = first_row(
        con,
        "SELECT root_status FROM ticks WHERE run_id = $run_id ORDER BY tick DESC LIMIT 1",
        {"run_id": run_id},
    )
    last_t = last_t or 0
    return Extent(
        events,
        last_seq,
        last_t,
        max(last_tick or 0, tick_max or 0),
        max(last_t, tick_end or 0),
        None if final is None else final[0],
    )


def _seq_space(extent: Extent) -> int:
    """The number of seqs of a run: last seq + 1 (the event count when gap-free)."""
    return 0 if extent.last_seq is None else extent.last_seq + 1


def _insert_run(con, run_id: str, path: str, tree: dict, metadata: dict, extent: Extent) -> None:
    started = metadata.get("started_at")
    try:
        started_at = datetime.fromisoformat(started) if started else None
    except (TypeError, ValueError):
        started_at = None
    if started_at is not None and started_at.tzinfo is not None:
        started_at = started_at.astimezone(UTC).replace(tzinfo=None)
    seed = str(metadata.get("seed", "")).strip()
    con.execute(
        "INSERT INTO runs VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)",
        [
            run_id,
            path,
            tree.get("tree_name", ""),
            started_at,
            extent.duration_ns,
            extent.final_status,
            metadata.get("domain") or None,
            int(seed) if seed.lstrip("-").isdigit() else None,
            orjson.dumps(metadata, default=repr).decode(),
        ],
    )


# -- snapshots: the fold, in blocks ------------------------------------------------------------
@dataclass
class EventBatch:
    """The events of a seq range: status changes as columns (codes for statuses), the
    blackboard writes and tree mutations as records (``others``, in seq order)."""

    seq: list[int]
    t_ns: list[int]
    tick: list[int]
    uid: list[int]
    prev: list[int]
    status: list[int]
    writes: list[BlackboardWrite]
    mutations: list[TreeMutation] = field(default_factory=list)

    def __post_init__(self) -> None:
        others = self.writes + self.mutations if self.mutations else self.writes
        self.others: list[BlackboardWrite | TreeMutation] = (
            sorted(others, key=_seq_of) if self.mutations else others
        )
        self._other_seqs = [e.seq for e in self.others]

    def fold(self, projection: StateProjection, lo: int, hi: int) -> None:
        """Apply this batch's events with ``lo <= seq < hi`` to ``projection``, in order:
        one pass over the status changes, the other events slotted in by seq."""
        seqs, other_seqs, others = self.seq, self._other_seqs, self.others
        i, end = bisect_left(seqs, lo), bisect_left(seqs, hi)
        k, last = bisect_left(other_seqs, lo), bisect_left(other_seqs, hi)
        on_status, codes = projection.on_status, _STATUS_BY_CODE
        pending = other_seqs[k] if k < last else hi
        for seq, t_ns, tick, uid, prev, status in zip(
            seqs[i:end],
            self.t_ns[i:end],
            self.tick[i:end],
            self.uid[i:end],
            self.prev[i:end],
            self.status[i:end],
            strict=True,
        ):
            while pending < seq:
                _apply_other(projection, others[k])
                k += 1
                pending = other_seqs[k] if k < last else hi
            on_status(seq, t_ns, tick, uid, codes[prev], codes[status])
        for event in others[k:last]:
            _apply_other(projection, event)

    def bound_at_most(self, attribute: str, limit: int) -> int | None:
        """One past the last seq of the batch whose ``t_ns`` (or ``tick``) is at most
        ``limit`` (None if no event of the batch is). Both never decrease along seq."""
        keys = self.t_ns if attribute == "t_ns" else self.tick
        index = bisect_right(keys, limit)
        last = self.seq[index - 1] if index else None
        for event in self.others:
            if getattr(event, attribute) <= limit and (last is None or event.seq > last):
                last = event.seq
        return None if last is None else last + 1

    def keys_of(self, seq: int) -> tuple[int, int] | None:
        """(t_ns, tick) of event ``seq`` if the batch holds it."""
        return self.first_keys(seq, seq + 1)

    def first_keys(self, lo: int, hi: int) -> tuple[int, int] | None:
        """(t_ns, tick) of the first event with ``lo <= seq < hi`` (None if there is none)."""
        found = None
        index = bisect_left(self.seq, lo)
        if index < len(self.seq) and self.seq[index] < hi:
            found = (self.seq[index], self.t_ns[index], self.tick[index])
        index = bisect_left(self._other_seqs, lo)
        if index < len(self._other_seqs) and self._other_seqs[index] < hi:
            event = self.others[index]
            if found is None or event.seq < found[0]:
                found = (event.seq, event.t_ns, event.tick)
        return None if found is None else found[1:]

    def block(self, lo: int, hi: int) -> bytes:
        """The status changes and writes with ``lo <= seq < hi``, compressed (mutations
        are kept apart, in ``_mutations``)."""
        i, j = bisect_left(self.seq, lo), bisect_left(self.seq, hi)
        write_seqs = [w.seq for w in self.writes] if self.mutations else self._other_seqs
        writes = [
            list(w) for w in self.writes[bisect_left(write_seqs, lo) : bisect_left(write_seqs, hi)]
        ]
        columns = [
            c[i:j] for c in (self.seq, self.t_ns, self.tick, self.uid, self.prev, self.status)
        ]
        data = orjson.dumps({"status": columns, "writes": writes}, default=repr)
        return zstandard.ZstdCompressor(level=1).compress(data)

    @classmethod
    def from_block(cls, data: bytes, mutations: list[TreeMutation]) -> EventBatch:
        """The batch of a ``block``, with the given mutations of its range."""
        message = orjson.loads(zstandard.ZstdDecompressor().decompress(data))
        writes = [BlackboardWrite(*row) for row in message["writes"]]
        return cls(*message["status"], writes, mutations)


def fetch_events(
    con, run_id: str, lo: int, hi: int, mutations: list[TreeMutation], prefix: str = ""
) -> EventBatch:
    """The events with ``lo <= seq < hi`` of a run, from the tables (``prefix``: the
    catalog, e.g. ``"run0."``)."""
    params = {"run_id": run_id, "lo": lo, "hi": hi}
    table = con.sql(
        f"""SELECT seq, t_ns, tick, uid, enum_code(prev_status),
            enum_code(status) FROM {prefix}transitions
        WHERE run_id = $run_id AND seq >= $lo AND seq < $hi ORDER BY seq""",
        params=params,
    ).to_arrow_table()
    columns = [column.to_pylist() for column in table.columns]
    rows = con.execute(
        f"""SELECT seq, t_ns, tick, scope, key, value, type, writer_uid
        FROM {prefix}blackboard WHERE run_id = $run_id AND seq >= $lo AND seq < $hi
        ORDER BY seq""",
        params,
    ).fetchall()
    loads = orjson.loads
    writes = [
        BlackboardWrite(
            seq, t, tick, scope, key, None if value is None else loads(value), kind, writer
        )
        for seq, t, tick, scope, key, value, kind, writer in rows
    ]
    return EventBatch(*columns, writes, [m for m in mutations if lo <= m.seq < hi])


def _seq_of(event: BlackboardWrite | TreeMutation) -> int:
    return event.seq


def _apply_other(projection: StateProjection, event: BlackboardWrite | TreeMutation) -> None:
    if type(event) is BlackboardWrite:
        projection.on_write(*event)
    else:
        projection.on_mutation(event)


def load_mutations(con, run_id: str, prefix: str = "") -> list[TreeMutation]:
    """Every mutation of a run, in seq order."""
    rows = con.execute(
        f"SELECT message FROM {prefix}_mutations WHERE run_id = $run_id ORDER BY seq",
        {"run_id": run_id},
    ).fetchall()
    return [fmt.decode_mutation(orjson.loads(message)) for (message,) in rows]


def build_snapshots(con, run_id: str, tree: Tree, events: int, every: int) -> int:
    """Fold the whole run once. Every ``every`` events (from seq 0) store a row in
    ``_snapshots``: the state *before* that event, and the block of the next ``every``
    events (so one row gives any state up to the next snapshot). Returns the row count."""
    mutations = load_mutations(con, run_id)
    projection = StateProjection(tree)
    batch_size = max(every, FOLD_BATCH // every * every)
    rows: list[tuple] = []
    for lo in range(0, events, batch_size):
        hi = min(lo + batch_size, events)
        batch = fetch_events(con, run_id, lo, hi, mutations)
        for start in range(lo, hi, every):
            stop = min(start + every, hi)
            rows.append(
                _snapshot_row(
                    projection.state, start, batch.first_keys(start, stop), batch.block(start, stop)
                )
            )
            batch.fold(projection, start, stop)
    if events % every == 0:
        rows.append(
            _snapshot_row(
                projection.state, events, None, EventBatch([], [], [], [], [], [], []).block(0, 0)
            )
        )
    _insert_snapshots(con, run_id, rows)
    return len(rows)


def _snapshot_row(state: State, seq: int, first: tuple[int, int] | None, block: bytes) -> tuple:
    first_t, first_tick = (None, None) if first is None else first
    return (
        seq,
        state.t_ns,
        state.tick,
        first_t,
        first_tick,
        orjson.dumps(state.to_json(), default=repr).decode(),
        block,
    )


def _insert_snapshots(con, run_id: str, rows: list[tuple]) -> None:
    names = ("seq", "t_ns", "tick", "first_t_ns", "first_tick", "state", "events")
    types = (pa.int64(), pa.int64(), pa.int64(), pa.int64(), pa.int64(), pa.string(), pa.binary())
    columns = list(zip(*rows, strict=True))
    table = pa.table({n: pa.array(c, t) for n, c, t in zip(names, columns, types, strict=True)})
    _insert_arrow(con, "_snapshots", run_id, table)


# -- one recording, end to end --------------------------------------------------------------
def ingest(
    con: duckdb.DuckDBPyConnection,
    path: str | os.PathLike,
    run_id: str | None = None,
    snapshot_every: int = DEFAULT_SNAPSHOT_EVERY,
    snapshots: bool = True,
) -> IngestReport:
    """Load the recording at ``path`` into ``con`` (whose tables ``create_schema`` made)
    as run ``run_id`` (default: ``short_run_id``): ``load_tables``, then
    ``add_snapshots`` unless ``snapshots`` is false (the tables alone serve SQL, not
    states).

    Raises ``RecordingError`` for a file that is not a readable recording; nothing of it
    is left in the tables then. A truncated file loads its readable prefix, with a
    warning in the report. The tables are filled by several statements (and worker
    threads), not one transaction: build a database, then publish it.
    """
    report = load_tables(con, path, run_id, snapshot_every)
    return add_snapshots(con, report) if snapshots else report


def load_tables(
    con: duckdb.DuckDBPyConnection,
    path: str | os.PathLike,
    run_id: str | None = None,
    snapshot_every: int = DEFAULT_SNAPSHOT_EVERY,
) -> IngestReport:
    """Every table of the run but ``_snapshots`` (see ``ingest``)."""
    if snapshot_every < 1:
        raise ValueError(f"snapshot_every must be at least 1, got {snapshot_every}")
    started = time.perf_counter()
    name = os.path.abspath(os.fspath(path))
    stat = os.stat(name)
    run_id = run_id or short_run_id(read_metadata(name), name)
    try:
        collected = _load_rows(con, run_id, name)
        metadata = decode_metadata(name, collected.metadata)
        _tree(name, collected.tree)
        _insert_small_tables(con, run_id, collected)
        extent = _extent(con, run_id)
        _insert_run(con, run_id, name, collected.tree, metadata, extent)
        report = IngestReport(
            run_id,
            name,
            _seq_space(extent),
            *_counts(con, run_id),
            len(collected.mutations),
            collected.truncated,
            _warnings(name, collected, extent),
            time.perf_counter() - started,
            0.0,
            0,
            snapshot_every,
        )
        _insert_ingest(con, report, stat, extent, collected.tree)
    except BaseException:
        discard_run(con, run_id)
        raise
    return report


def add_snapshots(con: duckdb.DuckDBPyConnection, report: IngestReport) -> IngestReport:
    """Fold the run loaded by ``load_tables`` and store its snapshots; the report with
    the snapshot figures."""
    started = time.perf_counter()
    (tree,) = first_row(
        con, "SELECT tree FROM _ingest WHERE run_id = $run_id", {"run_id": report.run_id}
    )
    try:
        stored = build_snapshots(
            con,
            report.run_id,
            Tree.from_description(orjson.loads(tree)),
            report.events,
            report.snapshot_every,
        )
        seconds = time.perf_counter() - started
        con.execute(
            "UPDATE _ingest SET snapshot_seconds = $seconds WHERE run_id = $run_id",
            {"seconds": seconds, "run_id": report.run_id},
        )
    except BaseException:
        con.execute("DELETE FROM _snapshots WHERE run_id = $run_id", {"run_id": report.run_id})
        raise
    return replace(report, snapshot_seconds=seconds, snapshots=stored)


def discard_run(con, run_id: str) -> None:
    """Delete every row of run ``run_id`` (a failed ingestion leaves nothing behind)."""
    for table in PUBLIC_TABLES + INTERNAL_TABLES:
        con.execute(f"DELETE FROM {table} WHERE run_id = $run_id", {"run_id": run_id})


def _tree(name: str, message: dict | None) -> Tree:
    if message is None:
        raise RecordingError(f"{name}: not a btlog recording: no {fmt.TREE_TOPIC} message")
    try:
        return Tree.from_description(message)
    except (KeyError, TypeError, StopIteration) as error:
        raise RecordingError(
            f"{name}: the {fmt.TREE_TOPIC} message is not a tree: {type(error).__name__}: {error}"
        ) from None


def _load_rows(con, run_id: str, name: str) -> _Collected:
    """Walk the file, loading its bulk rows as it goes; returns what else it found."""
    with tempfile.TemporaryDirectory(prefix="btlog-ingest-") as folder:
        loader = _Loader(con, run_id, Path(folder))
        try:
            collected = _McapScan(name, loader.submit).run()
            loader.finish()
        except (ValueError, TypeError, IndexError) as error:
            loader.close()
            if isinstance(error, RecordingError):
                raise
            raise RecordingError(
                f"{name}: rows that do not follow the btlog format: {type(error).__name__}: {error}"
            ) from None
        except BaseException:
            loader.close()
            raise
    if collected.metadata is None:
        raise RecordingError(f"{name}: not a btlog recording: no {fmt.METADATA_NAME} metadata")
    _load_other_messages(con, run_id, collected, name)
    return collected


def _insert_small_tables(con, run_id: str, collected: _Collected) -> None:
    _insert_nodes(con, run_id, collected.tree, collected.mutations)
    _insert_mutations(con, run_id, collected.mutations)
    _insert_answers(con, run_id, collected.answers)


def _counts(con, run_id: str) -> tuple[int, int, int]:
    return tuple(
        first_row(con, f"SELECT count(*) FROM {table} WHERE run_id = $run_id", {"run_id": run_id})[
            0
        ]
        for table in ("transitions", "blackboard", "ticks")
    )


def _warnings(name: str, collected: _Collected, extent: Extent) -> list[str]:
    warnings = list(collected.warnings)
    if extent.events and extent.last_seq != extent.events - 1:
        warnings.append(
            f"{name}: events are not gap-free: {extent.events} events up to seq {extent.last_seq}"
        )
    if collected.truncated:
        last = "(none)" if extent.last_seq is None else f"up to seq {extent.last_seq}"
        warnings.insert(0, f"{name}: truncated recording; read {extent.events} events {last}")
    return warnings


def _insert_ingest(
    con, report: IngestReport, stat: os.stat_result, extent: Extent, tree: dict
) -> None:
    con.execute(
        "INSERT INTO _ingest VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14)",
        [
            report.run_id,
            report.file,
            stat.st_size,
            stat.st_mtime_ns,
            btlog.SCHEMA_VERSION,
            INGEST_VERSION,
            _seq_space(extent),
            extent.last_tick,
            report.truncated,
            orjson.dumps(report.warnings).decode(),
            report.snapshot_every,
            orjson.dumps(tree).decode(),
            report.ingest_seconds,
            None,
        ],
    )

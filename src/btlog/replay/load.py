"""Bulk loading: row batches into the DuckDB tables, in worker threads.

``McapScan`` (``btlog.replay.scan``) hands over ``RowBatch``es while it walks the file;
``Loader`` loads each in one of two lanes (status rows; write and tick rows), in file
order. Binary columns (schema version 3, ``btlog.record.columns``) become Arrow arrays
over their bytes as they are, statuses checked and taken as the ENUM's codes: no row is
parsed. JSON status and tick rows (versions 1 and 2) become CSV with one
``bytes.translate`` (``[`` turned into a newline, ``"`` and ``]`` deleted:
``[1,2,"IDLE","RUNNING"],`` → ``⏎1,2,IDLE,RUNNING,``) and go through Arrow's
multithreaded CSV reader; the write rows of a batch's messages become one JSON array
that DuckDB's ``read_json`` reads a row at a time (a message of 200,000 writes of 1 KB
is never one 200 MB value to parse). Both parsers release the
GIL, so walking, parsing CSV and parsing JSON overlap. Rows these parsers refuse (an
unknown status, a row of another shape) are decoded with orjson and loaded through
Arrow instead: slower, never wrong.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import duckdb
import orjson
import pyarrow as pa
import pyarrow.compute as pa_compute
import pyarrow.csv as pa_csv

from btlog.record import format as fmt
from btlog.record.walk import MAGIC, RecordingError
from btlog.replay.scan import Collected, Columns, McapScan, RowBatch
from btlog.replay.tables import identifier, insert_arrow, one_row
from btlog.status import STATUS_NAMES

if TYPE_CHECKING:
    from btlog.replay.transitions_file import TransitionsFile

#: ``[`` (a row starts) becomes a newline; ``"`` and ``]`` are deleted.
_ROWS_TO_CSV = bytes.maketrans(b"[", b"\n")


class _Lane:
    """One worker thread with its own DuckDB cursor, running jobs in submission order."""

    def __init__(self, con: duckdb.DuckDBPyConnection, name: str) -> None:
        self.cursor = con.cursor()
        catalog, schema = one_row(con, "SELECT current_database(), current_schema()")
        self.cursor.execute(f"USE {identifier(catalog)}.{identifier(schema)}")
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


@dataclass
class Destination:
    """Where a run's rows go: its tables in DuckDB (the connection each load is given),
    but its status changes to ``transitions`` when that file is given (a cache's:
    ``btlog.replay.transitions_file``)."""

    run_id: str
    transitions: TransitionsFile | None = None

    def insert(self, con: duckdb.DuckDBPyConnection, table: str, rows: pa.Table) -> None:
        """Insert the Arrow table ``rows`` (the table's columns, without ``run_id``)."""
        if table == "transitions" and self.transitions is not None:
            self.transitions.write(rows)
        else:
            insert_arrow(con, table, self.run_id, rows)


class Loader:
    """Loads ``RowBatch``es into DuckDB while the walk goes on, in two lanes (status rows;
    write and tick rows), each in file order. DuckDB and Arrow release the GIL while they
    parse, so walking, parsing CSV and parsing JSON overlap."""

    def __init__(self, con: duckdb.DuckDBPyConnection, to: Destination, folder: Path) -> None:
        self.to = to
        self.folder = folder
        self.rows = _Lane(con, "rows")
        self.writes = _Lane(con, "writes")
        self.batches = 0

    def submit(self, batch: RowBatch) -> None:
        """Queue a batch's rows."""
        self.batches += 1
        to = self.to
        if batch.status_columns.count:
            self.rows.submit(_load_columns, to, "transitions", batch.status_columns)
        if batch.status:
            self.rows.submit(_load_csv_rows, to, "transitions", batch.status, _STATUS_CSV)
        if batch.writes:
            self.writes.submit(
                _load_write_rows, to, batch.writes, self.folder / f"writes-{self.batches}.jsonl"
            )
        if batch.tick_columns.count:
            self.writes.submit(_load_columns, to, "ticks", batch.tick_columns)
        if batch.ticks:
            self.writes.submit(_load_csv_rows, to, "ticks", batch.ticks, _TICKS_CSV)

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
    con: duckdb.DuckDBPyConnection,
    to: Destination,
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
        _insert_rows(con, to, table, orjson.loads(b"[" + bytes(rows[:-1]) + b"]"))
        return
    to.insert(con, table, canonical)


_STATUS_DICTIONARY = pa.array(STATUS_NAMES)
_ARROW_TYPES = {"q": pa.int64(), "i": pa.int32(), "b": pa.int8()}


def _load_columns(
    con: duckdb.DuckDBPyConnection, to: Destination, table: str, batch: Columns
) -> None:
    """Binary columns into ``table``: each an Arrow array over its bytes (no copy); a
    status column becomes the ENUM's codes once its values are checked."""
    arrays = {}
    for (name, code), data in zip(batch.layout, batch.data(), strict=True):
        array = pa.Array.from_buffers(_ARROW_TYPES[code], batch.count, [None, pa.py_buffer(data)])
        if name.endswith("status"):
            low, high = pa_compute.min_max(array).values()
            if low.as_py() < 0 or high.as_py() >= len(STATUS_NAMES):
                bad = low if low.as_py() < 0 else high
                raise ValueError(f"a {table} row has the status code {bad}, not a status")
            array = pa.DictionaryArray.from_arrays(array, _STATUS_DICTIONARY)
        arrays[name] = array
    to.insert(con, table, pa.table(arrays))


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


#: The longest write row DuckDB's JSON reader is first asked to take (it allocates about
#: twice this); a batch with a longer row is read again with its longest message's size.
WRITE_ROW_BYTES = 16 << 20


def _load_write_rows(
    con: duckdb.DuckDBPyConnection, to: Destination, lines: list[bytes | memoryview], path: Path
) -> None:
    """The write rows of each message (``[…],[…]``, without brackets) are written as
    one JSON array, which DuckDB reads an element at a time; rows it refuses are
    decoded with orjson, a message at a time."""
    if not lines:
        return
    with open(path, "wb") as file:
        file.write(b"[")
        for number, line in enumerate(lines):
            if number:
                file.write(b",")
            file.write(line)
        file.write(b"]")
    longest = max(len(line) for line in lines) + 1024  # no row is longer than its message
    try:
        for bound in sorted({min(WRITE_ROW_BYTES, longest), longest}):
            try:
                _read_write_rows(con, to.run_id, path, bound)
                return
            except duckdb.Error:
                if bound == longest:
                    raise
        return
    except duckdb.Error:
        for line in lines:
            _insert_write_rows(con, to, orjson.loads(b"[" + bytes(line) + b"]"))
    finally:
        path.unlink()


def _read_write_rows(con: duckdb.DuckDBPyConnection, run_id: str, path: Path, bound: int) -> None:
    """Insert the write rows of the JSON array in ``path``, none longer than ``bound``."""
    con.execute(
        """INSERT INTO blackboard
        SELECT $run_id, r[1]::BIGINT, r[2]::BIGINT, r[3]::BIGINT, r[4] ->> '$',
               r[5] ->> '$', coalesce(r[6], 'null'::JSON), r[7] ->> '$', r[8]::INTEGER
        FROM (SELECT json AS r FROM read_json($path, format = 'array', records = false,
              columns = {'json': 'JSON[]'}, maximum_object_size = $bound))""",
        {"run_id": run_id, "path": str(path), "bound": max(bound, 1 << 20)},
    )


def _insert_status_rows(con: duckdb.DuckDBPyConnection, to: Destination, rows: list[list]) -> None:
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
    to.insert(con, "transitions", table)


def _insert_write_rows(con: duckdb.DuckDBPyConnection, to: Destination, rows: list[list]) -> None:
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
    to.insert(con, "blackboard", table)


def _insert_tick_rows(
    con: duckdb.DuckDBPyConnection,
    to: Destination,
    rows: Sequence[Sequence],
    teardown: bool = False,
) -> None:
    if not rows:
        return
    columns = list(zip(*rows, strict=True))
    table = pa.table(
        {
            "tick": pa.array(columns[0], pa.int64()),
            "start_ns": pa.array(columns[1], pa.int64()),
            "end_ns": pa.array(columns[2], pa.int64()),
            "root_status": pa.array(columns[3], pa.string()),
            "teardown": pa.array([teardown] * len(rows), pa.bool_()),
        }
    )
    to.insert(con, "ticks", table)


def _insert_rows(
    con: duckdb.DuckDBPyConnection, to: Destination, table: str, rows: list[list]
) -> None:
    """Insert decoded JSON rows (the slow path) into ``table``."""
    inserts = {
        "transitions": _insert_status_rows,
        "blackboard": _insert_write_rows,
        "ticks": _insert_tick_rows,
    }
    inserts[table](con, to, rows)


def load_part(
    con: duckdb.DuckDBPyConnection,
    to: Destination,
    path: str,
    folder: Path,
    start: int = len(MAGIC),
    stop: int | None = None,
) -> Collected:
    """Scan the records of ``path`` from byte ``start`` to ``stop`` (the whole file by
    default; a part, ``btlog.replay.parts``), loading its bulk rows into ``to`` as the
    walk goes (``folder``: the loader's temporary files); what else the scan found. Rows
    that do not follow the format are a ``RecordingError`` naming the file."""
    loader = Loader(con, to, folder)
    try:
        collected = McapScan(path, loader.submit, start, stop).run()
        loader.finish()
    except (ValueError, TypeError, IndexError) as error:
        loader.close()
        if isinstance(error, RecordingError):
            raise
        raise RecordingError(
            f"{path}: rows that do not follow the btlog format: {type(error).__name__}: {error}"
        ) from None
    except BaseException:
        loader.close()
        raise
    return collected


def load_other_messages(
    con: duckdb.DuckDBPyConnection, to: Destination, collected: Collected, name: str
) -> None:
    """The messages the fast path did not recognise, decoded one by one."""
    status: list = []
    writes: list[list] = []
    try:
        for payload in collected.other_events:
            message = fmt.parse_events(payload)
            status.extend((*row[:4], row[4].name, row[5].name) for row in message.status)
            writes.extend(message.writes)
        _insert_status_rows(con, to, status)
        _insert_write_rows(con, to, writes)
        for payload in collected.other_ticks:  # the teardown's message is one of these
            ticks = fmt.decode_ticks(payload)
            _insert_tick_rows(
                con,
                to,
                [(t.tick, t.start_ns, t.end_ns, t.root_status.name) for t in ticks],
                any(t.teardown for t in ticks),
            )
    except (ValueError, TypeError, AttributeError, LookupError, duckdb.Error) as error:
        raise RecordingError(
            f"{name}: a message does not follow the btlog format: {type(error).__name__}: {error}"
        ) from None

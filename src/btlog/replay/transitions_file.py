"""A cached run's status changes as Parquet files, written at the speed of the scan.

The ``transitions`` table is nearly all of a long run's rows (99M of a 100M-event day).
Inserting them into DuckDB's own storage runs on one core and was what a first answer
waited for: 19 s of a 37.6 s first ``ask`` at 99M events. Written as Parquet instead, by
Arrow's C++ writer in the loader's worker thread (which releases the GIL, so it runs
beside the scan), they cost about 2.5 s of CPU beside it, and DuckDB reads the
files nearly as fast as its own tables: each row group's min and max of ``seq`` skip
the rest of the run for a moment's block, and a filter on a status code skips the row
groups without it. So a cache's ``transitions`` is a view over its files, one per part
of the recording read (``btlog.replay.tables.transitions_views``, ``btlog.replay.parts``);
the other tables stay DuckDB's.

Encodings: ``seq``, ``t_ns`` and ``tick`` as deltas (they grow by small steps), the
statuses as their codes (``btlog.status``), no dictionaries (a quarter less writing),
the pages LZ4-compressed: a 99M-event day of a 60-action tree takes 20 MB.
"""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pa_compute
import pyarrow.parquet as pq

from btlog.status import STATUS_NAMES

#: The file's columns: the table's, without ``run_id``, statuses as their codes.
SCHEMA = pa.schema(
    [
        ("seq", pa.int64()),
        ("t_ns", pa.int64()),
        ("tick", pa.int64()),
        ("uid", pa.int32()),
        ("prev_status", pa.int8()),
        ("status", pa.int8()),
    ]
)
#: Rows per row group: a moment's block reads one (DuckDB's own tables use 122,880).
ROW_GROUP_ROWS = 128 * 1024
_STATUS_NAMES = pa.array(STATUS_NAMES)


class TransitionsFile:
    """Writes Arrow tables of status changes (columns named as ``SCHEMA``'s, statuses
    as names, dictionary-encoded or not) to the Parquet file ``path``, in the order
    given; ``close`` completes the file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.rows = 0
        self._writer = pq.ParquetWriter(
            path,
            SCHEMA,
            compression="lz4",
            use_dictionary=False,
            column_encoding={
                "seq": "DELTA_BINARY_PACKED",
                "t_ns": "DELTA_BINARY_PACKED",
                "tick": "DELTA_BINARY_PACKED",
            },
            write_statistics=True,
        )

    def write(self, table: pa.Table) -> None:
        """Append ``table``'s rows."""
        if not table.num_rows:
            return
        arrays = [
            _status_codes(table.column(name)) if name.endswith("status") else table.column(name)
            for name in SCHEMA.names
        ]
        self._writer.write_table(
            pa.Table.from_arrays(arrays, schema=SCHEMA), row_group_size=ROW_GROUP_ROWS
        )
        self.rows += table.num_rows

    def close(self) -> None:
        """Write the file's footer (its row groups' statistics); the file is complete."""
        self._writer.close()


def _status_codes(column: pa.ChunkedArray) -> pa.ChunkedArray:
    """A status column as its codes (int8): a dictionary column over the status names
    (as the loaders make them) gives its indices; names are looked up."""
    chunks = []
    for chunk in column.chunks:
        if pa.types.is_dictionary(chunk.type):
            if not chunk.dictionary.equals(_STATUS_NAMES):
                chunk = chunk.dictionary_decode()
            else:
                chunks.append(chunk.indices.cast(pa.int8()))
                continue
        codes = pa_compute.index_in(chunk, value_set=_STATUS_NAMES)
        if codes.null_count:
            bad = chunk.filter(pa_compute.is_null(codes))[0].as_py()
            raise ValueError(f"a status change has the status {bad!r}, not a status")
        chunks.append(codes.cast(pa.int8()))
    return pa.chunked_array(chunks, pa.int8())

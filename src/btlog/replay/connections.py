"""DuckDB connections as btlog opens them: memory bounded by the process's limits, and
no temporary files where a user's SQL could read them.

DuckDB's defaults suit a server that owns its machine: a memory limit of 80 % of the
physical memory, whatever address-space limit (``ulimit -v``) the process runs under —
so under a 3 GB limit an allocation fails (or a thread cannot start) long before DuckDB
thinks of spilling — and a temporary folder ``.tmp`` in the current folder, which stays
readable to SQL once external access is turned off (DuckDB allows its temp folder).

``connect`` gives DuckDB a memory limit of ``MEMORY_LIMIT`` (1 GiB), or half of what the
address-space limit leaves when that is less, whatever the run's length (issue 27: the
default let one first answer on a 100M-event run take 9.8 GB), and either no temporary
folder at all (``sandbox``: the connection that runs users' SQL) or a private one in the
system's temporary folder, which DuckDB creates when it first spills and removes when
the connection closes.
"""

from __future__ import annotations

import functools
import os
import resource
import tempfile
import uuid

import duckdb

#: What DuckDB may use at most (its buffers: what it holds beyond that spills to the
#: temporary folder, or fails in a ``sandbox`` connection, which has none), so that a
#: command stays within about 2 GB of resident memory whatever the run's length.
MEMORY_LIMIT = 1 << 30
#: DuckDB is never given less than this, even when the address space is nearly used up.
MIN_MEMORY_LIMIT = 64 << 20
#: The share of the address space left free that DuckDB may use (the rest is for
#: Python, Arrow and DuckDB's own reservations: thread stacks, allocator arenas).
ADDRESS_SPACE_SHARE = 0.5


def memory_limit() -> int:
    """The bytes each DuckDB connection of this process may use: ``MEMORY_LIMIT``, or
    ``ADDRESS_SPACE_SHARE`` of what the address-space limit left when btlog first asked
    (before any connection reserved its share) when that is less."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return MEMORY_LIMIT
    share = int((soft - _first_address_space_used()) * ADDRESS_SPACE_SHARE)
    return min(MEMORY_LIMIT, max(MIN_MEMORY_LIMIT, share))


@functools.cache
def _first_address_space_used() -> int:
    """The address space this process held when btlog first opened a connection."""
    return _address_space_used()


def _address_space_used() -> int:
    """Bytes of address space this process holds now (``VmSize``; 0 if unknown)."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def connect(database: str = ":memory:", sandbox: bool = False) -> duckdb.DuckDBPyConnection:
    """A DuckDB connection with btlog's settings (see the module docstring): ``sandbox``
    for one that will run users' SQL (no temporary folder: nothing spills, nothing is
    readable)."""
    config: dict[str, str | bool | int | float | list[str]] = {
        "temp_directory": "" if sandbox else _private_temp_directory(),
        "memory_limit": f"{memory_limit() // (1 << 20)}MiB",
    }
    con = duckdb.connect(database, config=config)
    # A cache's transitions are Parquet files (``btlog.replay.transitions_file``): their
    # footers, read once, serve every later query (a story asks hundreds); a history's
    # "last such change" reads its row group once, not again for the row's other
    # columns (DuckDB's late materialization: 8 -> 4.8 ms a question, benchmarks/RESULTS.md).
    con.execute("SET parquet_metadata_cache = true")
    con.execute("SET late_materialization_max_rows = 0")
    return con


def _private_temp_directory() -> str:
    """A folder of this connection's own in the system's temporary folder (not created:
    DuckDB creates it on its first spill and removes it when the connection closes)."""
    name = f"btlog-duckdb-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    return os.path.join(tempfile.gettempdir(), name)

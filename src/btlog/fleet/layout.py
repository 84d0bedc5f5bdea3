"""The lake's layout on disk: its tables, partitions and files, and its one error.

``LAKE/{table}/domain={domain}/date={YYYY-MM-DD}/*.parquet``: exports (``btlog.fleet.lake``),
compactions (``btlog.fleet.compact``) and readers (the report, Spark) share these names.
"""

from __future__ import annotations

from btlog.replay.tables import PUBLIC_TABLES

#: The lake's tables: the read model's public ones, the failure causes and the
#: activations (``btlog.fleet.derived``). ``runs`` is written last.
LAKE_TABLES = (*PUBLIC_TABLES, "causes", "activations")
#: Partition keys (folder names), outermost first; ``run_id`` is a column.
PARTITIONS = ("domain", "date")
#: A table's files, relative to its folder.
FILES = "*/*/*.parquet"
#: The value used for a run without a domain or start date.
NONE = "none"


class LakeError(ValueError):
    """A lake that cannot be written or read (one line, naming the folder)."""

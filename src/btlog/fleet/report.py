"""The fleet report: what happened across many runs, as SQL that DuckDB and Spark share.

Three questions a developer asks of a fleet:

- **Outcomes**: how many runs ended in each final status.
- **Per node** (a node is its path, the same across runs of one tree): its activations (a
  start out of IDLE), how many completed and failed, the failure rate (failed /
  completed) and the duration of a completed activation (start to completion) at the
  50th, 90th and 99th percentiles, in seconds; read from the lake's ``activations``
  table (one row per activation, written at export: ``btlog.fleet.derived``).
- **Causes**: the most frequent failure causes: for a failed node, the execution node
  whose result caused it (the causal chain of ``btlog.explain.causes``, exported with
  every run as the ``causes`` table).

The queries are written once; ``dialect`` only names the exact percentile function
(DuckDB ``quantile_cont``, Spark ``percentile``: both interpolate linearly), so the two
engines give the same numbers on the same lake.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: How many causes the report lists.
TOP_CAUSES = 10

_PERCENTILE = {"duckdb": "quantile_cont", "spark": "percentile"}

OUTCOMES = """
SELECT coalesce(final_status, 'UNKNOWN') AS final_status, count(*) AS runs
FROM runs {where}
GROUP BY coalesce(final_status, 'UNKNOWN')
ORDER BY runs DESC, final_status
"""

NODES = """
SELECT n.path, n.uid, n.name, n.type, n.kind,
       count(*) AS activations,
       sum(a.completed) AS completed,
       sum(a.failed) AS failed,
       CASE WHEN sum(a.completed) = 0 THEN NULL
            ELSE sum(a.failed) / sum(a.completed) END AS failure_rate,
       {pct}(CASE WHEN a.completed = 1 THEN (a.end_ns - a.start_ns) / 1e9 END, 0.5) AS p50_s,
       {pct}(CASE WHEN a.completed = 1 THEN (a.end_ns - a.start_ns) / 1e9 END, 0.9) AS p90_s,
       {pct}(CASE WHEN a.completed = 1 THEN (a.end_ns - a.start_ns) / 1e9 END, 0.99) AS p99_s
FROM (SELECT * FROM activations {where}) a
JOIN (SELECT * FROM nodes {where}) n ON n.run_id = a.run_id AND n.uid = a.uid
GROUP BY n.path, n.uid, n.name, n.type, n.kind
ORDER BY failed DESC, activations DESC, n.path, n.uid
"""

CAUSES = """
SELECT name AS failed_node, cause_name AS cause, verb, count(*) AS times,
       count(DISTINCT run_id) AS runs
FROM causes {where}
GROUP BY name, cause_name, verb
ORDER BY times DESC, failed_node, cause
LIMIT {top}
"""


def queries(dialect: str, where: str = "") -> dict[str, str]:
    """The report's three queries for ``dialect`` ("duckdb" or "spark"); ``where`` is a
    filter on the partition columns (``WHERE domain = 'taxi'``), built by the caller
    from validated values only."""
    return {
        "outcomes": OUTCOMES.format(where=where),
        "nodes": NODES.format(where=where, pct=_PERCENTILE[dialect]),
        "causes": CAUSES.format(where=where, top=TOP_CAUSES),
    }


@dataclass
class FleetReport:
    """The report's rows, each a dict of column → value, in the queries' order."""

    outcomes: list[dict[str, Any]] = field(default_factory=list)
    nodes: list[dict[str, Any]] = field(default_factory=list)
    causes: list[dict[str, Any]] = field(default_factory=list)

    @property
    def runs(self) -> int:
        """How many runs the report covers."""
        return sum(int(row["runs"]) for row in self.outcomes)

    def to_json(self) -> dict[str, Any]:
        """The report as JSON-ready data."""
        return {
            "runs": self.runs,
            "outcomes": self.outcomes,
            "nodes": self.nodes,
            "causes": self.causes,
        }


def normalised(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows with engine-specific number types made plain (ints as int, decimals and
    floats as float), so reports from two engines compare equal."""
    plain = []
    for row in rows:
        out: dict[str, Any] = {}
        for key, value in row.items():
            if value is None or isinstance(value, str | bool):
                out[key] = value
            elif isinstance(value, int):
                out[key] = int(value)
            else:
                out[key] = round(float(value), 6)
        plain.append(out)
    return plain


def duckdb_report(lake: str, domain: str | None = None, date: str | None = None) -> FleetReport:
    """The fleet report over ``lake`` computed by DuckDB (optionally one domain/date:
    only those partitions are read)."""
    from btlog.fleet.lake import reading_lake

    with reading_lake(lake) as con:
        where, params = partition_filter(domain, date, placeholder="$")
        report = FleetReport()
        for name, query in queries("duckdb", where).items():
            cursor = con.execute(query, params)
            columns = [d[0] for d in cursor.description or ()]
            setattr(
                report,
                name,
                normalised([dict(zip(columns, r, strict=True)) for r in cursor.fetchall()]),
            )
        return report


def partition_filter(
    domain: str | None, date: str | None, placeholder: str
) -> tuple[str, dict[str, str]]:
    """A WHERE clause on the partition columns with named parameters (``$domain`` for
    DuckDB, ``:domain`` for Spark), and the parameters."""
    terms, params = [], {}
    for key, value in (("domain", domain), ("date", date)):
        if value is not None:
            terms.append(f"{key} = {placeholder}{key}")
            params[key] = value
    return ("WHERE " + " AND ".join(terms) if terms else ""), params

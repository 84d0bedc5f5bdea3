"""A fleet of runs: many recordings as one Parquet *lake*, and the reports across them.

A robot records a run per mission, CI a run per re-run: thousands of recordings. The lake
holds each run's read-model tables (the same columns as ``btlog sql``'s tables) as Parquet
under a Hive-partitioned layout, ``LAKE/{table}/domain=…/date=…/*.parquet`` (``run_id`` a
column), so any engine reads it and a query about one domain or one day opens only those
folders. Beside the six tables, ``causes`` (every failure of a control node, decorator or
subtree with its causal leaf, failures by design left out) and ``activations`` (one row
per activation of a node) are computed once at export.

- ``btlog.fleet.lake``: export runs into a lake; open a lake in DuckDB (read-only).
- ``btlog.fleet.derived``: the ``causes`` and ``activations`` of one run.
- ``btlog.fleet.compact``: a partition's per-run files merged into one file per table.
- ``btlog.fleet.report``: the fleet report (outcomes, per-node activations, failure rate,
  duration percentiles, most frequent failure causes) as SQL that DuckDB and Spark share.
- ``btlog.fleet.spark``: the same report as a PySpark job, for lakes beyond one machine.
"""

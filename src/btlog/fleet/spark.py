"""The fleet report as a PySpark job: the same queries as ``btlog fleet``, on Spark.

A lake is plain Parquet, so a fleet too large for one machine is read by a cluster. This
job registers each lake table as a view (partition columns read as strings, as DuckDB
reads them) and runs the queries of ``btlog.fleet.report`` with Spark's exact percentile,
so on the same lake it prints the same numbers as ``btlog fleet``::

    python -m btlog.fleet.spark LAKE [--domain D] [--date YYYY-MM-DD] [--json]

``pyspark`` (the ``spark`` extra) and a Java runtime are needed; ``--master`` picks the
cluster (default ``local[*]``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from btlog.fleet.layout import FILES, LAKE_TABLES
from btlog.fleet.report import FleetReport, normalised, partition_filter, queries


def spark_report(
    lake: str,
    domain: str | None = None,
    date: str | None = None,
    master: str = "local[*]",
) -> FleetReport:
    """The fleet report over ``lake`` computed by Spark (a local session by default)."""
    from pyspark.sql import SparkSession

    os.environ.setdefault("SPARK_LOCAL_IP", "127.0.0.1")  # loopback only, never a LAN address

    spark = (
        SparkSession.builder.master(master)
        .appName("btlog-fleet")
        .config("spark.sql.sources.partitionColumnTypeInference.enabled", "false")
        .config("spark.ui.enabled", "false")
        .config("spark.ui.showConsoleProgress", "false")
        .config("spark.driver.host", "127.0.0.1")
        .config("spark.driver.bindAddress", "127.0.0.1")
        .config("spark.sql.shuffle.partitions", "4")
        .getOrCreate()
    )
    try:
        spark.sparkContext.setLogLevel("ERROR")
        root = Path(lake).resolve()
        for table in LAKE_TABLES:
            folder = root / table
            if any(folder.glob(FILES)):
                frame = spark.read.option("basePath", str(folder)).parquet(str(folder))
                frame.createOrReplaceTempView(table)
        where, params = partition_filter(domain, date, placeholder=":")
        report = FleetReport()
        for name, query in queries("spark", where).items():
            rows = [row.asDict() for row in spark.sql(query, args=params).collect()]
            setattr(report, name, normalised(rows))
        return report
    finally:
        spark.stop()


def main(argv: list[str] | None = None) -> int:
    """Run the job from the command line; prints the report as JSON."""
    parser = argparse.ArgumentParser(prog="python -m btlog.fleet.spark", description=__doc__)
    parser.add_argument("lake", metavar="LAKE")
    parser.add_argument("--domain")
    parser.add_argument("--date")
    parser.add_argument("--master", default="local[*]")
    args = parser.parse_args(argv)
    report: Any = spark_report(args.lake, args.domain, args.date, args.master)
    json.dump(report.to_json(), sys.stdout, indent=2)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``btlog cache`` (list or clear the read model's caches) and the ``--cache-dir`` option
of every command that reads recordings through the read model (``btlog.replay.cache``)."""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path

from btlog.render.escape import safe

#: Commands that open recordings through the read model (and so take ``--cache-dir``).
READING_COMMANDS = ("ask", "explain", "show", "timeline", "replay", "sql", "check")


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Add ``cache`` to the command line, and ``--cache-dir`` to the reading commands."""
    parser = commands.add_parser(
        "cache",
        help="list or clear the read model's caches",
        description="List the read model's cache files (size, last use) or remove them. "
        "Caches live in $BTLOG_CACHE_DIR, else $XDG_CACHE_HOME/btlog, else ~/.cache/btlog; "
        "they are keyed by the recording's content and capped at $BTLOG_CACHE_MAX_MB "
        "(default 2048), least recently used evicted first.",
    )
    parser.add_argument("--clear", action="store_true", help="remove every cache file")
    parser.add_argument("--json", action="store_true", help="JSON output")
    add_cache_dir(parser)
    for name in READING_COMMANDS:
        if name in commands.choices:
            add_cache_dir(commands.choices[name])


def add_cache_dir(parser: argparse.ArgumentParser) -> None:
    """The ``--cache-dir`` option."""
    parser.add_argument(
        "--cache-dir",
        metavar="DIR",
        help="cache folder (default: $BTLOG_CACHE_DIR, $XDG_CACHE_HOME/btlog or ~/.cache/btlog)",
    )


@contextmanager
def cache_dir_of(args: argparse.Namespace) -> Iterator[None]:
    """While a command runs, its ``--cache-dir`` (if given) is the cache folder."""
    chosen = getattr(args, "cache_dir", None)
    if chosen is None:
        yield
        return
    before = os.environ.get("BTLOG_CACHE_DIR")
    os.environ["BTLOG_CACHE_DIR"] = os.path.abspath(chosen)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("BTLOG_CACHE_DIR", None)
        else:
            os.environ["BTLOG_CACHE_DIR"] = before


def cache_command(args: argparse.Namespace) -> int:
    """``btlog cache``: list the cache files and their total, or remove them."""
    from btlog.replay import cache  # DuckDB is imported only by commands that use it

    root = cache.cache_root()
    if args.clear:
        removed, freed = cache.clear(root)
        print(f"{root}: removed {removed} files, {freed / 1e6:.1f} MB")
        return 0
    found = cache.entries(root)
    total = sum(entry.size for entry in found)
    names = {entry.path: recording_of(entry.path) for entry in found}
    if args.json:
        print(
            json.dumps(
                {
                    "folder": str(root),
                    "bytes": total,
                    "max_bytes": cache.max_bytes(),
                    "files": [
                        {
                            "name": e.path.name,
                            "recording": names[e.path],
                            "bytes": e.size,
                            "last_used_ns": e.last_used_ns,
                        }
                        for e in found
                    ],
                },
                indent=2,
            )
        )
        return 0
    for entry in reversed(found):
        used = datetime.fromtimestamp(entry.last_used_ns / 1e9).isoformat(timespec="seconds")
        recording = safe(names[entry.path] or "(unreadable)")
        print(f"{entry.size / 1e6:10.1f} MB  {used}  {recording}  {entry.path.name}")
    print(
        f"{root}: {len(found)} caches, {total / 1e6:.1f} MB (cap {cache.max_bytes() / 1e6:.0f} MB)"
    )
    return 0


def recording_of(path: Path) -> str | None:
    """The recording a cache file was built from (``runs.file`` in the cache; for a
    snapshots file, its cache's), or None when the file cannot be read now (a build in
    progress holds its lock)."""
    import duckdb

    from btlog.replay import cache

    if path.name.endswith(cache.SNAPSHOTS_SUFFIX):
        path = cache.tables_path(path)
        found = recording_of(path) if path.exists() else None
        return None if found is None else f"{found} (snapshots)"
    try:
        with duckdb.connect(str(path), read_only=True) as con:
            row = con.execute("SELECT file FROM runs LIMIT 1").fetchone()
    except duckdb.Error:
        return None
    return None if row is None else str(row[0])

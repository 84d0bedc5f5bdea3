"""BehaviorTree.CPP v4 ``SqliteLogger`` files (``.db3``/``.btdb``), one run per session.

The tables (``src/loggers/bt_sqlite_logger.cpp``):

- ``Definitions(session_id, date, xml_tree)``: one row per logger created (``append``
  keeps earlier sessions), the tree as ``WriteTreeToXML`` writes it;
- ``Nodes(session_id, fullpath, node_uid)``: every node's path;
- ``Transitions(timestamp, session_id, node_uid, duration, state, extra_data)``: the
  timestamp is µs since the Unix epoch, made strictly increasing by the logger; ``state``
  is the new status; ``extra_data`` is whatever the user's callback returned.

Each session becomes one recording; its time 0 is its first transition. Non-empty
``extra_data`` is kept as a write of key ``extra_data`` in the scope ``btcpp.extra_data``
by the node of the transition, right after it.
"""

from __future__ import annotations

import os
import sqlite3
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from btlog.sources.btcpp_records import status_of
from btlog.sources.btcpp_tree import tree_from_file, tree_from_log_xml
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    RecordingBuilder,
    Source,
    SourceError,
)
from btlog.tree.model import Tree
from btlog.tree.registry import Registry

FORMAT = "btcpp-sqlite"
TABLES = ("Definitions", "Nodes", "Transitions")
EXTRA_SCOPE = "btcpp.extra_data"


@dataclass(frozen=True)
class Session:
    """One session of a SQLite log: its id, date (as BT.CPP wrote it) and tree XML."""

    session_id: int
    date: str
    xml: str


def open_log(path: str | os.PathLike) -> sqlite3.Connection:
    """Open the file read-only and check it has BT.CPP's tables."""
    file = os.fspath(path)
    if not Path(path).is_file():
        raise SourceError(f"{file}: no such file")
    try:
        con = sqlite3.connect(Path(path).resolve().as_uri() + "?mode=ro", uri=True)
        names = {row[0] for row in con.execute("SELECT name FROM sqlite_master")}
    except sqlite3.Error as error:
        raise SourceError(f"{file}: not a readable SQLite file ({error})") from None
    missing = [t for t in TABLES if t not in names]
    if missing:
        con.close()
        raise SourceError(f"{file}: no table {', '.join(missing)}: not a BT.CPP SqliteLogger file")
    return con


def sessions(con: sqlite3.Connection) -> list[Session]:
    """The sessions of an open log, in order."""
    rows = con.execute(
        "SELECT session_id, date, xml_tree FROM Definitions ORDER BY session_id"
    ).fetchall()
    return [Session(int(s), str(d), str(x)) for s, d, x in rows]


def import_sqlite(
    path: str | os.PathLike,
    outputs: dict[int, Path],
    tree_file: str | os.PathLike | None = None,
    registry: Registry | None = None,
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS,
) -> list[BuildResult]:
    """Import the sessions in ``outputs`` (session id → recording file)."""
    file = os.fspath(path)
    con = open_log(path)
    try:
        known = {s.session_id: s for s in sessions(con)}
        unknown = sorted(set(outputs) - set(known))
        if unknown:
            have = ", ".join(map(str, known)) or "none"
            raise SourceError(f"{file}: no session {unknown[0]} (sessions: {have})")
        return [
            _import_session(con, file, known[sid], out, tree_file, registry, tick_gap_ns)
            for sid, out in outputs.items()
        ]
    finally:
        con.close()


def _import_session(
    con: sqlite3.Connection,
    file: str,
    session: Session,
    output: Path,
    tree_file: str | os.PathLike | None,
    registry: Registry | None,
    tick_gap_ns: int,
) -> BuildResult:
    where = f"{file} session {session.session_id}"
    tree = tree_from_log_xml(session.xml.encode(), where, registry)
    if tree_file is not None:
        tree = tree_from_file(tree_file, tree, registry)
    warnings = _check_paths(con, session.session_id, tree, where)
    rows = con.execute(
        "SELECT timestamp, node_uid, state, extra_data FROM Transitions "
        "WHERE session_id = ? ORDER BY timestamp",
        (session.session_id,),
    )
    first = con.execute(
        "SELECT min(timestamp), count(*) FROM Transitions WHERE session_id = ?",
        (session.session_id,),
    ).fetchone()
    start_us = int(first[0]) if first[0] is not None else 0
    started = datetime.fromtimestamp(start_us / 1e6, UTC) if first[0] is not None else None
    source = Source.of_file(
        FORMAT, file, session=session.session_id, date=session.date, records=int(first[1])
    )
    builder = RecordingBuilder(
        output,
        tree,
        source,
        started_at=started,
        attachments=[("btcpp-tree.xml", session.xml.encode())],
        tick_gap_ns=tick_gap_ns,
    )
    builder.warnings.extend(warnings)
    try:
        for timestamp, uid, state, extra in rows:
            status = status_of(state, f"{where}: transition at {timestamp}")
            t_ns = (int(timestamp) - start_us) * 1000
            builder.transition(t_ns, int(uid), status)
            if extra:
                builder.write(t_ns, EXTRA_SCOPE, "extra_data", str(extra), int(uid))
    except BaseException:
        builder.close()
        output.unlink(missing_ok=True)
        raise
    return builder.close()


def _check_paths(con: sqlite3.Connection, session_id: int, tree: Tree, where: str) -> list[str]:
    """Warnings for ``Nodes`` rows whose path differs from the tree's."""
    rows = con.execute(
        "SELECT node_uid, fullpath FROM Nodes WHERE session_id = ?", (session_id,)
    ).fetchall()
    differ = [
        (uid, path) for uid, path in rows if uid not in tree.nodes or tree.nodes[uid].path != path
    ]
    if not differ:
        return []
    uid, path = differ[0]
    return [f"{where}: {len(differ)} node paths differ from the tree's, e.g. uid {uid} {path!r}"]

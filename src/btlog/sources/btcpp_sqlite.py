"""BehaviorTree.CPP v4 ``SqliteLogger`` files (``.db3``/``.btdb``), one run per session.

The tables (``src/loggers/bt_sqlite_logger.cpp``):

- ``Definitions(session_id, date, xml_tree)``: one row per logger created (``append``
  keeps earlier sessions), the tree as ``WriteTreeToXML`` writes it;
- ``Nodes(session_id, fullpath, node_uid)``: every node's path (since BT.CPP 4.6);
- ``Transitions(timestamp, session_id, node_uid, duration, state, extra_data)``: the
  timestamp is µs since the Unix epoch, made strictly increasing by the logger; ``state``
  is the new status; ``extra_data`` is whatever the user's callback returned. BT.CPP 4.1
  to 4.5 name the uid column ``uid`` and have no ``extra_data`` (nor ``Nodes``): such
  files import too.

Each session becomes one recording; its time 0 is its first transition. Non-empty
``extra_data`` is kept as a write of key ``extra_data`` in the scope ``btcpp.extra_data``
by the node of the transition, right after it.

A file is untrusted: every value is checked (a timestamp or uid that is no integer, a
status out of range, a tree that is not UTF-8 are refused naming the session and the
timestamp); a database damaged part-way through a session's transitions keeps those
read before the damage, with a warning; SQLite's own errors name the file.
"""

from __future__ import annotations

import os
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from btlog.sources.btcpp_records import status_of
from btlog.sources.btcpp_tree import tree_from_file, tree_from_log_xml
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    RecordingBuilder,
    Source,
    SourceError,
    wall_start,
)
from btlog.tree.model import Tree
from btlog.tree.registry import Registry

FORMAT = "btcpp-sqlite"
TABLES = ("Definitions", "Transitions")
EXTRA_SCOPE = "btcpp.extra_data"
#: The uid column of Transitions: BT.CPP 4.6 and later, then 4.1 to 4.5.
UID_COLUMNS = ("node_uid", "uid")


@dataclass(frozen=True)
class Session:
    """One session of a SQLite log: its id, date (as BT.CPP wrote it) and tree XML."""

    session_id: int
    date: str
    xml: bytes


@dataclass(frozen=True)
class Layout:
    """What this file's BT.CPP version wrote: the uid column of Transitions, whether it
    has ``extra_data`` and the ``Nodes`` table."""

    uid: str
    extra: bool
    nodes: bool


class SqliteLog:
    """An open SqliteLogger file (read-only), its layout checked; use it in ``with``."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.file = os.fspath(path)
        if not Path(path).is_file():
            raise SourceError(f"{self.file}: no such file")
        with self.reading():
            self.con = sqlite3.connect(Path(path).resolve().as_uri() + "?mode=ro", uri=True)
            self.con.text_factory = bytes  # text is decoded and checked here
            try:
                self.layout = self._layout()
            except BaseException:
                self.con.close()
                raise

    @contextmanager
    def reading(self, where: str = "") -> Iterator[None]:
        """SQLite's errors as ``SourceError`` naming the file (and ``where``)."""
        try:
            yield
        except sqlite3.Error as error:
            at = f" {where}" if where else ""
            raise SourceError(f"{self.file}{at}: not a readable SQLite log ({error})") from None

    def _layout(self) -> Layout:
        names = {_text(row[0]) for row in self.con.execute("SELECT name FROM sqlite_master")}
        missing = [t for t in TABLES if t not in names]
        if missing:
            raise SourceError(
                f"{self.file}: no table {', '.join(missing)}: not a BT.CPP SqliteLogger file"
            )
        columns = {_text(row[1]) for row in self.con.execute("PRAGMA table_info(Transitions)")}
        uid = next((c for c in UID_COLUMNS if c in columns), None)
        needed = [c for c in ("timestamp", "session_id", "state") if c not in columns]
        if uid is None or needed:
            lacking = ", ".join([*needed, *([] if uid else ["node_uid"])])
            raise SourceError(
                f"{self.file}: table Transitions has no column {lacking}: "
                "not a BT.CPP SqliteLogger file"
            )
        return Layout(uid, "extra_data" in columns, "Nodes" in names)

    def sessions(self) -> list[Session]:
        """The sessions, in order."""
        with self.reading("(table Definitions)"):
            rows = self.con.execute(
                "SELECT session_id, date, xml_tree FROM Definitions ORDER BY session_id"
            ).fetchall()
        found = []
        for session_id, date, xml in rows:
            if not isinstance(session_id, int):
                raise SourceError(f"{self.file}: session id {session_id!r} is not an integer")
            if not isinstance(xml, bytes):
                raise SourceError(f"{self.file} session {session_id}: xml_tree is {xml!r}")
            found.append(Session(session_id, _text(date), xml))
        return found

    def close(self) -> None:
        """Close the file."""
        self.con.close()

    def __enter__(self) -> SqliteLog:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _text(value: Any) -> str:
    """A text value read as bytes, decoded leniently (names, dates, extra data)."""
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    return "" if value is None else str(value)


def session_ids(path: str | os.PathLike) -> list[int]:
    """The ids of the sessions in the file, in order."""
    with SqliteLog(path) as log:
        return [s.session_id for s in log.sessions()]


def import_sqlite(
    path: str | os.PathLike,
    outputs: dict[int, Path],
    tree_file: str | os.PathLike | None = None,
    registry: Registry | None = None,
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS,
) -> list[BuildResult]:
    """Import the sessions in ``outputs`` (session id → recording file)."""
    with SqliteLog(path) as log:
        known = {s.session_id: s for s in log.sessions()}
        unknown = sorted(set(outputs) - set(known))
        if unknown:
            have = ", ".join(map(str, known)) or "none"
            raise SourceError(f"{log.file}: no session {unknown[0]} (sessions: {have})")
        return [
            _import_session(log, known[sid], out, tree_file, registry, tick_gap_ns)
            for sid, out in outputs.items()
        ]


def _session_tree(
    session: Session, where: str, tree_file: str | os.PathLike | None, registry: Registry | None
) -> Tree:
    try:
        session.xml.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SourceError(
            f"{where}: xml_tree is not UTF-8 text (byte {error.start} of {len(session.xml)})"
        ) from None
    tree = tree_from_log_xml(session.xml, where, registry)
    if tree_file is not None:
        tree = tree_from_file(tree_file, tree, registry)
    return tree


def _import_session(
    log: SqliteLog,
    session: Session,
    output: Path,
    tree_file: str | os.PathLike | None,
    registry: Registry | None,
    tick_gap_ns: int,
) -> BuildResult:
    where = f"{log.file} session {session.session_id}"
    tree = _session_tree(session, where, tree_file, registry)
    warnings = _check_paths(log, session.session_id, tree, where)
    extra = "extra_data" if log.layout.extra else "NULL"
    with log.reading(f"session {session.session_id}"):
        rows = log.con.execute(
            f"SELECT timestamp, {log.layout.uid}, state, {extra} FROM Transitions "
            "WHERE session_id = ? ORDER BY timestamp",
            (session.session_id,),
        )  # the column names are BT.CPP's, chosen from UID_COLUMNS, never the file's text
        first = rows.fetchone()
    start_us = _integer(first[0], "timestamp", where) if first is not None else 0
    started = wall_start(start_us, where, warnings) if first is not None else None
    source = Source.of_file(FORMAT, log.file, session=session.session_id, date=session.date)
    builder = RecordingBuilder(
        output,
        tree,
        source,
        started_at=started,
        attachments=[("btcpp-tree.xml", session.xml)],
        tick_gap_ns=tick_gap_ns,
    )
    builder.warnings.extend(warnings)
    try:
        if first is not None:
            _add_rows(builder, first, rows, start_us, where)
    except BaseException:
        builder.close()
        output.unlink(missing_ok=True)
        raise
    return builder.close()


def _add_rows(
    builder: RecordingBuilder, first: tuple, rows: sqlite3.Cursor, start_us: int, where: str
) -> None:
    """Each row as a transition (and its extra data as a write), in timestamp order; a
    database damaged part-way keeps the rows read before, with a warning."""
    row: tuple | None = first
    count, timestamp = 0, None
    while row is not None:
        timestamp = _integer(row[0], "timestamp", where)
        at = f"{where}: transition at timestamp {timestamp}"
        status = status_of(row[2], at)
        uid = _integer(row[1], "node uid", at)
        t_ns = (timestamp - start_us) * 1000
        try:
            builder.transition(t_ns, uid, status)
        except SourceError as error:  # the builder names the file; say the session too
            what = str(error).removeprefix(f"{builder.source.file}: ")
            raise SourceError(f"{where}: {what} (transition at timestamp {timestamp})") from None
        if row[3]:
            builder.write(t_ns, EXTRA_SCOPE, "extra_data", _text(row[3]), uid)
        count += 1
        try:
            row = rows.fetchone()
        except sqlite3.DatabaseError as error:
            builder.warnings.append(
                f"{where}: the database is damaged after the transition at timestamp "
                f"{timestamp} ({error}); imported the {count} transitions before it"
            )
            return


def _integer(value: Any, what: str, where: str) -> int:
    if isinstance(value, int):
        return value
    raise SourceError(f"{where}: {what} {_text(value)[:40]!r} is not an integer")


def _check_paths(log: SqliteLog, session_id: int, tree: Tree, where: str) -> list[str]:
    """Warnings for ``Nodes`` rows whose path differs from the tree's."""
    if not log.layout.nodes:
        return []
    with log.reading("(table Nodes)"):
        rows = log.con.execute(
            "SELECT node_uid, fullpath FROM Nodes WHERE session_id = ?", (session_id,)
        ).fetchall()
    differ = [
        (uid, _text(path))
        for uid, path in rows
        if uid not in tree.nodes or tree.nodes[uid].path != _text(path)
    ]
    if not differ:
        return []
    uid, path = differ[0]
    return [f"{where}: {len(differ)} node paths differ from the tree's, e.g. uid {uid} {path!r}"]

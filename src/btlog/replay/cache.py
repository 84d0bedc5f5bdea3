"""The read model's cache: one DuckDB file per recording *content*, in the user's cache folder.

Ingesting a long run costs seconds, so each recording's read model is kept as a DuckDB
file in the cache folder (never beside the recording): ``--cache-dir``/``cache_dir``, else
``$BTLOG_CACHE_DIR``, else ``$XDG_CACHE_HOME/btlog``, else ``~/.cache/btlog``. A cache is
named by the SHA-256 of the recording's bytes, the cache format (the read model's layout
version and btlog's version) and the snapshot interval, so:

- a recording replaced by another — even of the same size and mtime — never meets the
  old cache, and a moved or copied recording reuses its cache;
- two btlog versions never share a file.

Hashing reads the whole file (~0.9 GB/s here; see ``benchmarks/``), so the digest is
remembered in the cache folder (``digests/``, one line per recording file) with what
identifies the file as it is now: its size, mtime and ctime (which no tool sets back: a
file rewritten in place, even with its mtime restored, gets a new ctime) and a hash of
its first and last 64 KiB. A warm open of a recording of any size stats and reads
128 KiB of it; any change of those hashes the whole file again. A cache
is built under a temporary name holding the builder's pid and moved into place when
complete; the leftovers of a killed build (its pid gone) are removed on the next open.
Using a cache touches its mtime, and after a build the least recently used caches are
evicted until the folder is under its size cap (``$BTLOG_CACHE_MAX_MB``, default 2048).
A cache holds the tables, its status changes in Parquet files beside it
(``NAME.transitions.N.parquet``, one per part of the recording read: ``build``), counted,
evicted and cleared with it; the snapshots, which only states need, are built a segment at
a time (``btlog.replay.snapshots.SEGMENT_BLOCKS`` snapshots) on the first state asked for
in the segment's range, each into a file beside it (``NAME.N.snapshots.duckdb``): a
first answer about one moment of a long run does not wait for the whole run's.
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import os
import re
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

import btlog
from btlog.replay.connections import connect
from btlog.replay.tables import INGEST_VERSION, create_schema, transitions_views

if TYPE_CHECKING:  # ingestion (and pyarrow) is imported to build a cache, not to use one
    from btlog.replay import ingest as ingestion

SUFFIX = ".duckdb"
#: The status changes of a cache ``NAME.duckdb`` are in ``NAME.transitions.N.parquet``,
#: one file per part of the recording read (``btlog.replay.parts``), which its
#: ``transitions`` view reads (``btlog.replay.transitions_file``).
TRANSITIONS_SUFFIX = ".parquet"
#: The snapshots of segment N of a cache ``NAME.duckdb`` are in ``NAME.N.snapshots.duckdb``.
SNAPSHOTS_SUFFIX = ".snapshots" + SUFFIX
_SEGMENT = re.compile(r"\.\d+$")
#: The default size cap of the cache folder, in MB (``$BTLOG_CACHE_MAX_MB`` overrides).
DEFAULT_MAX_MB = 2048
#: Recordings smaller than this get a cache of 16 KiB blocks instead of DuckDB's 256 KiB:
#: ~0.2 MB instead of ~2.5 MB for a 30 KB recording (big caches compress better in big
#: blocks: 31 MB instead of 9.7 MB at 1M events).
SMALL_RECORDING = 512 * 1024
#: The folder (in the cache folder) remembering each recording file's digest.
DIGESTS = "digests"
#: Bytes hashed at each end of a recording to tell whether a remembered digest is its.
FINGERPRINT_BYTES = 64 * 1024
#: A temporary cache of a build in progress: ``.<name>.<pid>-<hex>.duckdb`` (+ ``.wal``).
_TEMPORARY = re.compile(r"^\..+\.(\d+)-[0-9a-f]{8}\.duckdb(\.wal)?$")


def cache_root(cache_dir: str | os.PathLike | None = None) -> Path:
    """The cache folder: ``cache_dir``, else ``$BTLOG_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/btlog``, else ``~/.cache/btlog``."""
    if cache_dir is not None:
        return Path(cache_dir)
    if os.environ.get("BTLOG_CACHE_DIR"):
        return Path(os.environ["BTLOG_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "btlog"


def content_hash(path: str | os.PathLike) -> str:
    """The SHA-256 of the file's bytes (hex)."""
    with open(path, "rb") as file:
        return hashlib.file_digest(file, "sha256").hexdigest()


def recording_digest(path: str | os.PathLike, root: Path) -> str:
    """``content_hash(path)``, remembered in ``root/digests`` for the file as it is now
    (``_identity``): hashed again only when the file changed (or was never hashed)."""
    with open(path, "rb") as file:
        status = os.fstat(file.fileno())
        identity = _identity(file, status)
        memo = root / DIGESTS / f"{status.st_dev}-{status.st_ino}"
        try:
            remembered = memo.read_text(encoding="ascii").split()
        except (OSError, UnicodeDecodeError):
            remembered = []
        if len(remembered) == 2 and remembered[0] == identity:
            return remembered[1]
        file.seek(0)
        digest = hashlib.file_digest(file, "sha256").hexdigest()
    with contextlib.suppress(OSError):  # a folder that cannot be written: hash each time
        memo.parent.mkdir(parents=True, exist_ok=True)
        temporary = memo.with_name(f".{memo.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}")
        temporary.write_text(f"{identity} {digest}\n", encoding="ascii")
        os.replace(temporary, memo)
    return digest


def _identity(file: BinaryIO, status: os.stat_result) -> str:
    """What identifies an open file's content without reading it all: size, mtime and
    ctime (ns), and a BLAKE2b of its first and last ``FINGERPRINT_BYTES``."""
    fingerprint = hashlib.blake2b(file.read(FINGERPRINT_BYTES), digest_size=16)
    if status.st_size > FINGERPRINT_BYTES:
        file.seek(max(status.st_size - FINGERPRINT_BYTES, FINGERPRINT_BYTES))
        fingerprint.update(file.read(FINGERPRINT_BYTES))
    return f"{status.st_size}:{status.st_mtime_ns}:{status.st_ctime_ns}:{fingerprint.hexdigest()}"


def cache_format() -> str:
    """What a cache's layout depends on besides the recording: layout and btlog versions."""
    return f"f{INGEST_VERSION}-v{btlog.__version__}"


def cache_path(
    recording: str | os.PathLike, snapshot_every: int, cache_dir: str | os.PathLike | None = None
) -> Path:
    """Where the cache of ``recording`` (as it is now) lives."""
    root = cache_root(cache_dir)
    digest = recording_digest(recording, root)[:32]
    return root / f"{digest}-{cache_format()}-k{snapshot_every}{SUFFIX}"


@dataclass(frozen=True)
class CacheEntry:
    """One cache file: its path, size in bytes and last use (mtime, ns)."""

    path: Path
    size: int
    last_used_ns: int


def entries(root: Path) -> list[CacheEntry]:
    """The cache files of ``root``, least recently used first (temporaries excluded);
    a cache's size includes its transitions file."""
    found = []
    if root.is_dir():
        for path in root.glob(f"*{SUFFIX}"):
            try:
                stat = path.stat()
            except OSError:
                continue
            size = stat.st_size
            for part in transitions_paths(path):
                with contextlib.suppress(OSError):
                    size += part.stat().st_size
            found.append(CacheEntry(path, size, stat.st_mtime_ns))
    return sorted(found, key=lambda entry: entry.last_used_ns)


def clear(root: Path) -> tuple[int, int]:
    """Remove every cache file (and leftover) of ``root`` and the remembered digests;
    (cache files removed, bytes freed)."""
    removed = freed = 0
    if not root.is_dir():
        return 0, 0
    for path in root.iterdir():
        if path.name.endswith((SUFFIX, f"{SUFFIX}.wal", TRANSITIONS_SUFFIX)) and path.is_file():
            size = path.stat().st_size
            path.unlink(missing_ok=True)  # a cache's transitions file is counted with it
            removed += path.name.endswith(SUFFIX)
            freed += size
    if (root / DIGESTS).is_dir():  # the remembered digests (bytes each) go too, uncounted
        for path in (root / DIGESTS).iterdir():
            path.unlink(missing_ok=True)
    return removed, freed


def touch(cache: Path) -> None:
    """Mark ``cache`` as just used (its mtime orders the eviction)."""
    with contextlib.suppress(OSError):
        os.utime(cache)


def max_bytes() -> int:
    """The size cap of the cache folder (``$BTLOG_CACHE_MAX_MB``, default 2048 MB)."""
    text = os.environ.get("BTLOG_CACHE_MAX_MB", "")
    try:
        megabytes = float(text) if text else DEFAULT_MAX_MB
    except ValueError:
        megabytes = DEFAULT_MAX_MB
    return int(max(megabytes, 0) * (1 << 20))


def evict(root: Path, limit: int, keep: set[Path]) -> list[Path]:
    """Remove the least recently used caches until ``root`` holds at most ``limit``
    bytes; caches in ``keep`` (attached now) stay. Returns the removed files."""
    found = entries(root)
    total = sum(entry.size for entry in found)
    removed = []
    for entry in found:
        if total <= limit:
            break
        if entry.path in keep:
            continue
        entry.path.unlink(missing_ok=True)
        Path(f"{entry.path}.wal").unlink(missing_ok=True)
        for part in transitions_paths(entry.path):
            part.unlink(missing_ok=True)
        total -= entry.size
        removed.append(entry.path)
    return removed


def remove_leftovers(folder: Path) -> list[Path]:
    """Remove the temporary files of cache builds whose process is gone (killed)."""
    removed: list[Path] = []
    if not folder.is_dir():
        return removed
    for path in folder.iterdir():
        match = _TEMPORARY.match(path.name)
        if match and not _alive(int(match.group(1))):
            with contextlib.suppress(OSError):
                path.unlink(missing_ok=True)
                removed.append(path)
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, owned by someone else
    return True


def build(path: str, cache: Path, snapshot_every: int) -> ingestion.IngestReport:
    """Ingest ``path``'s tables into a new cache file, moved into place when complete.

    The status changes go to Parquet files beside it, one per part of the recording read
    (``transitions_path``), which the cache's ``transitions`` view reads: written beside
    the scan, they cost a first answer about a 100M-event run 4 s instead of DuckDB's
    19 s insert. The other tables are loaded straight into the file. The snapshots are
    not built here: a first question in SQL needs only the tables; the first state asked
    for builds them (``build_snapshots``). The transitions files are moved into place
    first, so a cache in place always has its files.
    """
    from btlog.replay import ingest as ingestion

    cache.parent.mkdir(parents=True, exist_ok=True)
    temporary = _temporary(cache)
    parts: dict[int, Path] = {}

    def part_file(number: int) -> Path:
        if number not in parts:  # (the same file when a read in parts is read again)
            parts[number] = _temporary(transitions_path(cache, number))
        return parts[number]

    con = connect()
    try:
        small = os.path.getsize(path) < SMALL_RECORDING
        con.execute(f"ATTACH $path AS cache_file{_blocks(small)}", {"path": str(temporary)})
        con.execute("USE cache_file")
        create_schema(con)
        report = ingestion.load_tables(
            con, path, snapshot_every=snapshot_every, transitions_files=part_file
        )
        # the parts read (a read in parts read again in one part removed the others' files)
        numbers = [number for number in sorted(parts) if parts[number].exists()]
        files = [transitions_path(cache, number) for number in numbers]
        for stale in set(transitions_paths(cache)) - set(files):  # a build in more parts
            stale.unlink(missing_ok=True)
        for number, file in zip(numbers, files, strict=True):
            os.replace(parts[number], file)
        for statement in transitions_views(report.run_id, [str(file) for file in files]):
            con.execute(statement)
        con.execute("USE memory")
        con.execute("DETACH cache_file")
        os.replace(temporary, cache)
    finally:
        con.close()
        _remove_temporary(temporary)
        for part in parts.values():
            part.unlink(missing_ok=True)
    return report


def transitions_path(cache: Path, part: int) -> Path:
    """The Parquet file of the status changes of part ``part`` of the recording cached
    in ``cache`` (``btlog.replay.transitions_file``)."""
    return cache.with_name(
        f"{cache.name.removesuffix(SUFFIX)}.transitions.{part}{TRANSITIONS_SUFFIX}"
    )


def transitions_paths(cache: Path) -> list[Path]:
    """The transitions files of the cache ``cache`` that exist (none for a snapshots
    file)."""
    if cache.name.endswith(SNAPSHOTS_SUFFIX):
        return []
    stem = glob.escape(cache.name.removesuffix(SUFFIX))
    return sorted(cache.parent.glob(f"{stem}.transitions.*{TRANSITIONS_SUFFIX}"))


def snapshots_path(cache: Path, segment: int) -> Path:
    """Where the snapshots of segment ``segment`` of the cache ``cache`` live: a file
    beside it, built on the first state asked for in its range (``build_snapshots``)."""
    return cache.with_name(f"{cache.name.removesuffix(SUFFIX)}.{segment}{SNAPSHOTS_SUFFIX}")


def tables_path(snapshots: Path) -> Path:
    """The cache whose snapshots file is ``snapshots`` (``snapshots_path``'s inverse)."""
    stem = _SEGMENT.sub("", snapshots.name.removesuffix(SNAPSHOTS_SUFFIX))
    return snapshots.with_name(stem + SUFFIX)


def build_snapshots(cache: Path, target: Path, segment: int) -> float:
    """Build the snapshots of segment ``segment`` of the run cached in ``cache`` into a
    new file ``target`` (moved into place when complete); returns the seconds taken. The
    cache itself is only read (other processes may have it open)."""
    from btlog.replay import ingest as ingestion

    temporary = _temporary(target)
    con = connect()
    try:
        small = cache.stat().st_size < SMALL_RECORDING * 4
        con.execute("ATTACH $path AS cached (READ_ONLY)", {"path": str(cache)})
        con.execute(f"ATTACH $path AS snapshot_file{_blocks(small)}", {"path": str(temporary)})
        con.execute("CREATE TABLE snapshot_file._snapshots AS FROM cached._snapshots LIMIT 0")
        _rows, seconds = ingestion.snapshots_into(
            con, "snapshot_file._snapshots", "cached", segment=segment
        )
        con.execute("DETACH snapshot_file")
        os.replace(temporary, target)
    finally:
        con.close()
        _remove_temporary(temporary)
    return seconds


def _temporary(path: Path) -> Path:
    """The name a file is built under (``_TEMPORARY``) before it is moved to ``path``."""
    return path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}{SUFFIX}")


def _remove_temporary(temporary: Path) -> None:
    for leftover in (temporary, Path(f"{temporary}.wal")):
        leftover.unlink(missing_ok=True)


def _blocks(small: bool) -> str:
    """The ATTACH option of a cache file: 16 KiB blocks for a small recording."""
    return " (BLOCK_SIZE 16384)" if small else ""

"""The read model's cache: in the cache folder, keyed by content, capped, cleaned, optional.

Recordings are real runs; the hostile cases (a replaced recording with the same size and
mtime, leftovers of killed builds, an unwritable cache folder) are made here.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import orjson
import pytest
from mcap.writer import CompressionType

from btlog.record import format as fmt
from btlog.record import iter_messages
from btlog.replay import cache
from btlog.replay.database import cache_location, open_runs
from btlog.status import Status
from tests.cli_support import btlog
from tests.mcap_support import record_loop, stored_metadata, write_messages

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def caches(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "caches"
    monkeypatch.setenv("BTLOG_CACHE_DIR", str(folder))
    return folder


def test_caches_live_in_the_cache_folder_never_beside_the_recording(tmp_path, caches):
    folder = tmp_path / "recordings"
    folder.mkdir()
    path = record_loop(folder / "run.mcap")
    with open_runs(path) as database:
        assert len(database.ingested) == 1
    assert sorted(p.name for p in folder.iterdir()) == ["run.mcap"]
    [built] = cache.entries(caches)
    assert built.path == cache_location(path)
    assert built.path.name.startswith(cache.content_hash(path)[:32])
    assert cache.cache_format() in built.path.name
    os.utime(built.path, ns=(0, 0))
    with open_runs(path) as database:
        assert database.ingested == []
    assert built.path.stat().st_mtime_ns > 0, "a used cache is marked as recently used"


def test_xdg_cache_home_is_the_default(tmp_path, monkeypatch):
    monkeypatch.delenv("BTLOG_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_root() == tmp_path / "xdg" / "btlog"
    assert cache.cache_root(tmp_path / "mine") == tmp_path / "mine"


def equal_sized_variant(source: Path, target: Path, status: str) -> Path:
    """``source`` re-written uncompressed with the last transition's status replaced by
    ``status`` (a name of the same length): same size, other content."""
    messages = list(iter_messages(source))
    last = max(i for i, (topic, _t, _d) in enumerate(messages) if topic == fmt.EVENTS_TOPIC)
    topic, log_time, data = messages[last]
    events = fmt.parse_events(data)
    *rows, row = events.status
    rows.append((*row[:5], Status[status]))
    messages[last] = (topic, log_time, fmt.encode_events(replace(events, status=rows)))
    return write_messages(
        target, stored_metadata(source), messages, compression=CompressionType.NONE
    )


def test_a_replaced_recording_with_the_same_size_and_mtime_is_not_answered_stale(tmp_path, caches):
    source = record_loop(tmp_path / "source.mcap")
    first = equal_sized_variant(source, tmp_path / "first.mcap", "SUCCESS")
    second = equal_sized_variant(source, tmp_path / "second.mcap", "FAILURE")
    assert first.stat().st_size == second.stat().st_size
    path = tmp_path / "run.mcap"
    shutil.copyfile(first, path)
    query = "SELECT status FROM transitions ORDER BY seq DESC LIMIT 1"
    with open_runs(path) as database:
        assert database.sql(query)[1] == [("SUCCESS",)]
    stat = path.stat()
    shutil.copyfile(second, path)
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))  # touch -r
    assert path.stat().st_size == stat.st_size
    with open_runs(path) as database:
        assert database.sql(query)[1] == [("FAILURE",)]


def test_a_moved_recording_reuses_its_cache_and_is_named_where_it_is(tmp_path, caches):
    path = record_loop(tmp_path / "run.mcap")
    with open_runs(path) as database:
        assert len(database.ingested) == 1
    moved = tmp_path / "elsewhere" / "moved.mcap"
    moved.parent.mkdir()
    path.rename(moved)
    with open_runs(moved) as database:
        assert database.ingested == []
        assert database.run().info.file == str(moved)
        assert database.sql("SELECT file FROM runs")[1] == [(str(moved),)]


def test_least_recently_used_caches_are_evicted_beyond_the_cap(tmp_path, caches, monkeypatch):
    old = record_loop(tmp_path / "old.mcap", ticks=30)
    new = record_loop(tmp_path / "new.mcap", ticks=31)
    with open_runs(old):
        pass
    [first] = cache.entries(caches)
    monkeypatch.setenv("BTLOG_CACHE_MAX_MB", str(first.size * 1.5 / (1 << 20)))
    with open_runs(new):
        pass
    assert [entry.path for entry in cache.entries(caches)] == [cache_location(new)]


def test_leftovers_of_killed_builds_are_removed_on_the_next_open(tmp_path, caches):
    path = record_loop(tmp_path / "run.mcap")
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        check=True,
        capture_output=True,
        text=True,
    )
    pid = int(dead.stdout)
    caches.mkdir()
    killed = [
        caches / f".abc-f2-k512.duckdb.{pid}-0123abcd.duckdb",
        caches / f".abc-f2-k512.duckdb.{pid}-0123abcd.duckdb.wal",
        tmp_path / f".run.mcap.duckdb.{pid}-89abcdef.duckdb",  # beside, by older versions
    ]
    running = caches / f".abc-f2-k512.duckdb.{os.getpid()}-0123abcd.duckdb"
    for leftover in [*killed, running]:
        leftover.write_bytes(b"x" * 100)
    with open_runs(path):
        pass
    assert not any(leftover.exists() for leftover in killed)
    assert running.exists(), "a build in progress is left alone"


def test_an_unwritable_cache_folder_falls_back_to_memory_with_a_notice(tmp_path, monkeypatch):
    path = record_loop(tmp_path / "run.mcap")
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    monkeypatch.setenv("BTLOG_CACHE_DIR", str(blocker / "btlog"))
    with open_runs(path) as database:
        assert database.run().info.events > 0
        [notice] = database.notices
        assert "read into memory" in notice and str(blocker) in notice
    result = btlog(
        "sql", str(path), "SELECT count(*) AS n FROM ticks WHERE NOT teardown", "--format", "csv"
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["n", "40"]
    [line] = result.stderr.strip().splitlines()
    assert line.startswith("btlog: notice: cannot write the cache folder")


def test_cache_command_lists_and_clears(tmp_path):
    folder = tmp_path / "c"
    path = record_loop(tmp_path / "run.mcap")
    assert btlog("sql", str(path), "SELECT 1", "--cache-dir", str(folder)).returncode == 0
    [built] = cache.entries(folder)
    listing = btlog("cache", "--cache-dir", str(folder), "--json")
    assert listing.returncode == 0, listing.stderr
    shown = orjson.loads(listing.stdout)
    assert shown["bytes"] == built.size and [f["name"] for f in shown["files"]] == [built.path.name]
    cleared = btlog("cache", "--clear", "--cache-dir", str(folder))
    assert cleared.returncode == 0 and "removed 1 files" in cleared.stdout
    assert cache.entries(folder) == []


def test_a_recordings_digest_is_remembered_for_the_file_as_it_is(tmp_path, caches):
    """A warm open does not read the whole recording again: its digest is remembered in
    the cache folder with the file's size, times and a hash of its two ends."""
    path = tmp_path / "big.bin"
    path.write_bytes(os.urandom(3 * cache.FINGERPRINT_BYTES))
    assert cache_location(path).name.startswith(cache.content_hash(path)[:32])
    [memo] = (caches / cache.DIGESTS).iterdir()
    assert memo.read_text(encoding="ascii").split()[1] == cache.content_hash(path)
    identity = memo.read_text(encoding="ascii").split()[0]
    memo.write_text(f"{identity} {'0' * 64}\n", encoding="ascii")
    assert cache_location(path).name.startswith("0" * 32), "the remembered digest is used"


def test_a_change_between_the_fingerprinted_ends_is_seen(tmp_path, caches):
    """A byte changed in the middle of a recording (outside the hashed ends), its size and
    mtime kept: the ctime tells, and the whole file is hashed again."""
    path = tmp_path / "big.bin"
    data = bytearray(os.urandom(3 * cache.FINGERPRINT_BYTES))
    path.write_bytes(data)
    before = cache_location(path)
    status = path.stat()
    data[len(data) // 2] ^= 0xFF
    with open(path, "r+b") as file:  # in place: same inode
        file.write(data)
    os.utime(path, ns=(status.st_atime_ns, status.st_mtime_ns))
    assert (path.stat().st_ino, path.stat().st_size) == (status.st_ino, status.st_size)
    after = cache_location(path)
    assert after != before
    assert after.name.startswith(cache.content_hash(path)[:32])


def test_clear_removes_the_remembered_digests(tmp_path, caches):
    path = record_loop(tmp_path / "run.mcap")
    with open_runs(path):
        pass
    assert list((caches / cache.DIGESTS).iterdir())
    cache.clear(caches)
    assert list((caches / cache.DIGESTS).iterdir()) == []
    assert cache.entries(caches) == []

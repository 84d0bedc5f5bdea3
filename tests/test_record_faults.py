"""Damaged records that no chunk CRC guards, and a full disk: every one ends in exit 0
with the data, or in exit 2 with one line naming the file and the byte offset; never in
exit 3 ("a bug in btlog")."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from btlog.errors import EXIT_BAD_INPUT, EXIT_OK
from btlog.record import open_recording
from btlog.record.reader import iter_messages
from tests.cli_support import btlog
from tests.mcap_support import record_loop, stored_metadata, write_blackboard_dump, write_messages


def top_level(data: bytes) -> list[tuple[int, int, int]]:
    """``(offset, opcode, length)`` of the file's top-level records, the footer last."""
    found, position = [], 8
    while position + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, position)
        found.append((position, opcode, length))
        if opcode == 0x02:
            break
        position += 9 + length
    return found


def flipped(source: Path, target: Path, offset: int, xor: int = 0x40) -> Path:
    data = bytearray(source.read_bytes())
    data[offset] ^= xor
    target.write_bytes(bytes(data))
    return target


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    return record_loop(tmp_path_factory.mktemp("faults") / "run.mcap", ticks=60)


@pytest.fixture(scope="module")
def unchunked(recording, tmp_path_factory) -> Path:
    """The recording rewritten with every record at the top level (channels included)."""
    target = tmp_path_factory.mktemp("faults") / "unchunked.mcap"
    return write_messages(
        target, stored_metadata(recording), list(iter_messages(recording)), chunked=False
    )


def refused(path: Path, *words: str) -> str:
    for command in (["explain"], ["sql", "SELECT count(*) FROM transitions"]):
        done = btlog(command[0], path, *command[1:], "--cache-dir", path.parent / "cache")
        assert done.returncode == EXIT_BAD_INPUT, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1, done.stderr
        for word in (str(path), *words):
            assert word in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("field", [9, 22, 28], ids=["name-length", "map-length", "key-length"])
def test_a_damaged_metadata_record_names_file_and_offset(recording, tmp_path, field):
    (offset, _opcode, _length) = next(r for r in top_level(recording.read_bytes()) if r[1] == 0x0C)
    damaged = flipped(recording, tmp_path / "metadata.mcap", offset + field, 0x7F)
    line = refused(damaged, f"metadata record at byte {offset}")
    assert "EndOfFile" not in line


def test_a_damaged_channel_record_names_file_and_offset(unchunked, tmp_path):
    records = top_level(unchunked.read_bytes())
    assert not any(opcode == 0x06 for _o, opcode, _l in records)  # no chunk: no CRC
    (offset, _opcode, _length) = next(r for r in records if r[1] == 0x04)
    damaged = flipped(unchunked, tmp_path / "channel.mcap", offset + 9 + 4, 0x7F)  # topic length
    refused(damaged, f"channel record at byte {offset}")


def test_a_damaged_summary_is_read_around(recording, tmp_path):
    """The summary repeats the data section's schemas and channels: damage there (its
    CRC fails) loses nothing."""
    data = recording.read_bytes()
    records = top_level(data)
    end = next(o for o, opcode, _l in records if opcode == 0x0F)  # data end
    channel = next(o for o, opcode, _l in records if opcode == 0x04 and o > end)
    damaged = flipped(recording, tmp_path / "summary.mcap", channel + 9 + 4, 0x7F)
    read, original = open_recording(damaged), open_recording(recording)
    assert read.events == original.events and read.ticks == original.ticks
    assert any("summary" in warning and "CRC" in warning for warning in read.warnings)
    done = btlog("explain", damaged, "--cache-dir", tmp_path / "cache")
    assert done.returncode == EXIT_OK, done.stderr


def test_a_damaged_tree_chunk_names_its_offset(recording, tmp_path):
    first_chunk = next(o for o, opcode, _l in top_level(recording.read_bytes()) if opcode == 0x06)
    damaged = flipped(recording, tmp_path / "tree.mcap", first_chunk + 200)
    line = refused(damaged, f"damaged data at byte {first_chunk}", "btlog recover")
    assert "no /btlog/tree message" in line


def test_a_full_disk_names_the_file(tmp_path):
    full = tmp_path / "run.mcap"
    full.symlink_to("/dev/full")
    tree = Path(__file__).resolve().parent.parent / "trees" / "kitting.xml"
    done = btlog("run", tree, "-o", full, "--max-ticks", "200")
    assert done.returncode == EXIT_BAD_INPUT, done.stderr
    assert done.stderr.count("\n") == 1
    assert "No space left on device" in done.stderr and str(full) in done.stderr


def test_a_200k_key_blackboard_dump_is_read_in_bounded_memory(tmp_path):
    """One message of 200,000 writes of 1 KB (under 1 MB on disk, 200 MB of values):
    ``sql`` reads it under a 1 GiB address-space limit; ``explain``, whose story needs
    more, ends in exit 0 or in exit 2 naming the limit, never in exit 3."""
    dump = write_blackboard_dump(tmp_path / "dump.mcap", 200_000, 1000)
    assert dump.stat().st_size < 1 << 20
    query = "SELECT count(*), max(strlen(value::VARCHAR)) FROM blackboard"
    done = btlog("sql", dump, query, "--format", "csv", address_space=1 << 30)
    assert done.returncode == EXIT_OK, done.stderr
    assert "200000,1008" in done.stdout
    told = btlog("explain", dump, "--cache-dir", tmp_path / "cache", address_space=1 << 30)
    assert told.returncode in (EXIT_OK, EXIT_BAD_INPUT), told.stderr
    assert "internal error" not in told.stderr and told.stderr.count("\n") <= 1

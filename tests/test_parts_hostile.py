"""Reading a recording in parts is safe on hostile input: lying summaries, dying parts.

A finished recording is cut into parts where its summary's chunk indexes say chunks start
(``btlog.replay.parts``). A summary's CRC tells it was written whole, not that it tells
the truth: here a real recording's chunk indexes are rewritten to lie (an offset into a
chunk at a byte that happens to be a chunk opcode, past the end, into the summary,
listed twice, a wrong chunk length) and the footer's summary CRC is computed again, so
the lie is trusted as far as a CRC goes. Such a file must be read in one part, with the
rows and warnings of the true file. So must a summary that leaves out (or renames) a
channel the chunks define: a part knows the summary's channels only, so the file is read
again in one part. A part's process that is killed or fails is one line naming the file
(exit 2), leaving nothing behind in the cache folder; a damaged chunk in a later part,
and messages of channels the file never defines, are told as reading in one part tells
them.
"""

from __future__ import annotations

import os
import signal
import struct
import time
import zlib
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from btlog.record import iter_messages
from btlog.record.walk import RecordingError, chunk_starts, mapped, sound_summary
from btlog.replay import cache, parts
from tests.cli_support import assert_bad_input, btlog, btlog_command, btlog_environment
from tests.mcap_support import stored_metadata, write_messages
from tests.test_damage import chunks
from tests.test_parts import record

PART_BYTES = {"BTLOG_PART_BYTES": "4096"}
FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary start, offsets start, CRC
MAGIC_BYTES = 8
CHANNEL_OPCODE, CHUNK_OPCODE, CHUNK_INDEX_OPCODE = 0x04, 0x06, 0x08
QUERY = "SELECT status, count(*), sum(seq), max(seq) FROM transitions GROUP BY ALL ORDER BY ALL"
Index = tuple[int, int]  # a chunk index's chunk start and chunk length


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = record(tmp_path_factory.mktemp("hostile") / "loop.mcap", ticks=1500)
    assert len(chunks(path.read_bytes())) >= 20
    return path


def index_fields(data: bytes) -> list[int]:
    """The byte offset of each chunk index's chunk start field (its length follows)."""
    footer = len(data) - MAGIC_BYTES - FOOTER.size
    _opcode, _length, position, _offsets, _crc = FOOTER.unpack_from(data, footer)
    fields = []
    while position < footer:
        opcode, length = struct.unpack_from("<BQ", data, position)
        if opcode == CHUNK_INDEX_OPCODE:
            fields.append(position + 9 + 16)
        position += 9 + length
    return fields


def lying_copy(source: Path, target: Path, lie: Callable[[bytes, list[Index]], list[Index]]):
    """``source`` with its chunk indexes' (start, length) replaced by ``lie``'s, and the
    footer's summary CRC computed again over the lying summary."""
    data = bytearray(source.read_bytes())
    fields = index_fields(bytes(data))
    told = lie(bytes(data), [struct.unpack_from("<QQ", data, field) for field in fields])
    for field, (start, length) in zip(fields, told, strict=True):
        struct.pack_into("<QQ", data, field, start, length)
    footer = len(data) - MAGIC_BYTES - FOOTER.size
    opcode, length, summary, offsets, _crc = FOOTER.unpack_from(data, footer)
    crc = zlib.crc32(data[summary : footer + FOOTER.size - 4])
    FOOTER.pack_into(data, footer, opcode, length, summary, offsets, crc)
    target.write_bytes(bytes(data))
    with mapped(target) as (mapped_data, size):
        assert sound_summary(mapped_data, size) is not None  # the CRC trusts the lie
    return target


def _told(number: int, start: int | None = None, length: int | None = None):
    """A lie: chunk index ``number`` (of the middle ones) tells ``start``/``length``."""

    def lie(data: bytes, indexes: list[Index]) -> list[Index]:
        told = list(indexes)
        old_start, old_length = told[number]
        told[number] = (
            old_start if start is None else start,
            old_length if length is None else length,
        )
        return told

    return lie


def _first_cut(data: bytes, indexes: list[Index]) -> int:
    """The index of the chunk ``parts.plan`` cuts the file at first (the first at or after
    its first target): a lie from there on is one a plan would use."""
    target = len(data) // min(parts._cores(), parts.MAX_PARTS)
    return min(n for n, (start, _length) in enumerate(indexes) if start >= target)


def _into_a_chunk(data: bytes, indexes: list[Index]) -> list[Index]:
    """The first cut moved into a chunk: the first byte from the plan's first target on
    inside a chunk that is a chunk opcode (the chunks from the target up to the one after
    it said to start there)."""
    target = len(data) // min(parts._cores(), parts.MAX_PARTS)
    inside = next(
        byte
        for start, length in indexes
        for byte in range(max(start + 1, target), start + length)
        if data[byte] == CHUNK_OPCODE
    )
    after = min(start for start, _length in indexes if start > inside)
    return [(inside if target <= start <= after else start, n) for start, n in indexes]


def _into_the_summary(data: bytes, indexes: list[Index]) -> list[Index]:
    """Every chunk from the first cut on said to start at a byte of the summary that is a
    chunk opcode."""
    footer = len(data) - MAGIC_BYTES - FOOTER.size
    summary = FOOTER.unpack_from(data, footer)[2]
    inside = data.index(bytes([CHUNK_OPCODE]), summary, footer)
    cut = _first_cut(data, indexes)
    return [*indexes[:cut], *[(inside, length) for _start, length in indexes[cut:]]]


LIES: dict[str, Callable[[bytes, list[Index]], list[Index]]] = {
    "into a chunk": _into_a_chunk,
    "past the end": lambda data, indexes: _told(-1, len(data) + 4096)(data, indexes),
    "at the last byte": lambda data, indexes: _told(-1, len(data) - 1)(data, indexes),
    "into the summary": _into_the_summary,
    "at the magic": lambda data, indexes: _told(0, 0)(data, indexes),
    "listed twice": lambda data, indexes: [*indexes[:3], indexes[2], *indexes[4:]],
    "a wrong length": lambda data, indexes: _told(3, length=indexes[3][1] + 1)(data, indexes),
    "a length of zero": lambda data, indexes: _told(3, length=0)(data, indexes),
    "one left out": lambda data, indexes: [*indexes[:-1], indexes[0]],
}


def answer(path: Path, cache_dir: Path, env: dict[str, str] | None = None):
    """``btlog sql`` of the status changes (counts and seq sums: a record read twice or
    skipped shows) of ``path``."""
    return btlog("sql", path, QUERY, "--cache-dir", cache_dir, env=env)


@pytest.fixture(scope="module")
def truth(recording, tmp_path_factory):
    """The answer about the true recording, read in one part."""
    result = answer(recording, tmp_path_factory.mktemp("truth"))
    assert result.returncode == 0 and "FAILURE" in result.stdout, result.stderr
    return result


@pytest.mark.parametrize("lie", list(LIES))
def test_a_summary_whose_chunk_indexes_lie_is_read_in_one_part(
    recording, truth, tmp_path, monkeypatch, lie
):
    hostile = lying_copy(recording, tmp_path / "lying.mcap", LIES[lie])
    with mapped(hostile) as (data, size):
        assert chunk_starts(data, size) == []
    monkeypatch.setenv("BTLOG_PART_BYTES", PART_BYTES["BTLOG_PART_BYTES"])
    assert parts.plan(str(hostile)) == [parts.Part(MAGIC_BYTES, None)]
    result = answer(hostile, tmp_path / "cache", env=PART_BYTES)
    assert result.returncode == 0, result.stderr
    assert result.stdout == truth.stdout
    assert result.stderr == truth.stderr == ""


def test_chunk_indexes_listed_out_of_order_still_cut_at_chunks(recording, truth, tmp_path):
    hostile = lying_copy(recording, tmp_path / "shuffled.mcap", lambda data, xs: xs[::-1])
    with mapped(hostile) as (data, size):
        starts = chunk_starts(data, size)
    assert starts == [offset for offset, _length in chunks(recording.read_bytes())]
    result = answer(hostile, tmp_path / "cache", env=PART_BYTES)
    assert result.returncode == 0 and result.stdout == truth.stdout, result.stderr


@settings(
    max_examples=300,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    lies=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 2), st.integers()), max_size=4)
)
def test_any_lie_about_chunk_starts_gives_the_true_starts_or_none(recording, lies):
    data = bytearray(recording.read_bytes())
    true_starts = [offset for offset, _length in chunks(bytes(data))]
    fields = index_fields(bytes(data))
    special = [0, 1, len(data) - 1, len(data), len(data) + 9, 2**64 - 1]
    for index, kind, value in lies:
        field = fields[index % len(fields)] + (8 if kind == 2 else 0)
        (old,) = struct.unpack_from("<Q", data, field)
        new = [value % len(data), old + value % 17 - 8, special[value % len(special)]][kind]
        struct.pack_into("<Q", data, field, new % 2**64)
    footer = len(data) - MAGIC_BYTES - FOOTER.size
    opcode, length, summary, offsets, _crc = FOOTER.unpack_from(data, footer)
    crc = zlib.crc32(data[summary : footer + FOOTER.size - 4])
    FOOTER.pack_into(data, footer, opcode, length, summary, offsets, crc)
    starts = chunk_starts(bytes(data), len(data))
    assert starts in ([], true_starts)


@pytest.mark.parametrize(
    "command", [("sql", QUERY), ("ask", "--at", "end", "What are you doing?")], ids=["sql", "ask"]
)
def test_a_killed_part_is_one_line_and_leaves_nothing_behind(recording, tmp_path, command):
    import subprocess

    for attempt in range(5):
        root = tmp_path / f"cache-{attempt}"
        process = subprocess.Popen(
            btlog_command(command[0], recording, *command[1:], "--cache-dir", root),
            env=btlog_environment(PART_BYTES),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        killed = _kill_part(process.pid)
        stdout, stderr = process.communicate(timeout=120)
        if killed:
            break
    else:
        pytest.skip("the part's process ended before it could be killed (5 times)")
    result = subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)
    assert_bad_input(result, str(recording), "exit code -9")
    left = [path.name for path in root.iterdir() if path.name != "digests"]
    assert left == [], left
    again = answer(recording, root, env=PART_BYTES)
    assert again.returncode == 0 and "FAILURE" in again.stdout, again.stderr


def _kill_part(parent: int, seconds: float = 30) -> bool:
    """Kill the first part's process ``parent`` starts (True), or False if none ran."""
    deadline = time.monotonic() + seconds
    children = Path(f"/proc/{parent}/task/{parent}/children")
    while time.monotonic() < deadline:
        try:
            pids = children.read_text().split()
        except OSError:  # the parent has ended
            return False
        for pid in pids:
            try:
                command = Path(f"/proc/{pid}/cmdline").read_bytes()
            except OSError:
                continue
            if b"btlog.replay.parts" in command:
                os.kill(int(pid), signal.SIGKILL)
                return True
        time.sleep(0.001)
    return False


class _Refused:
    """A request a part's process cannot read: unpickling it fails there (a traceback
    of the process's own, before it can answer)."""

    def __reduce__(self):
        return (int, ("not a number",))


def test_a_part_failing_before_it_answers_is_one_line_naming_the_file(recording, tmp_path):
    scan = parts.PartScan(str(recording), parts.Part(MAGIC_BYTES, None), _Refused())
    try:
        with pytest.raises(RecordingError) as raised:
            scan.rows()
    finally:
        scan.stop()
    message = str(raised.value)
    assert message.startswith(f"{recording}: the process reading bytes 8 to the end")
    assert "exit code 1" in message and "invalid literal for int()" in message
    assert "\n" not in message and "Traceback" not in message


def damaged_copy(source: Path, target: Path, chunk: int, where: Callable[[int, int], int]):
    """``source`` with one byte of its chunk at byte ``chunk`` flipped: at
    ``where(start, length)`` of the chunk."""
    data = bytearray(source.read_bytes())
    start, length = next((s, n) for s, n in chunks(bytes(data)) if s == chunk)
    data[where(start, length)] ^= 0x5A
    target.write_bytes(bytes(data))
    return target


def _planned(path: Path, monkeypatch) -> list[parts.Part]:
    """The parts ``path`` is read in with ``PART_BYTES``."""
    with monkeypatch.context() as patched:
        patched.setenv("BTLOG_PART_BYTES", PART_BYTES["BTLOG_PART_BYTES"])
        return parts.plan(str(path))


@pytest.mark.parametrize(
    "where, in_parts",
    [
        (lambda start, length: start + length - 20, True),  # compressed records: CRC fails
        (lambda start, length: start + 3, False),  # the chunk's length: framing damaged
    ],
    ids=["records", "length"],
)
@pytest.mark.parametrize("which", ["last but one", "first of the last part"])
def test_a_damaged_chunk_in_a_later_part_is_told_as_in_one_part(
    recording, tmp_path, monkeypatch, where, in_parts, which
):
    last_part = _planned(recording, monkeypatch)[-1].start
    offsets = [start for start, _length in chunks(recording.read_bytes())]
    chunk = last_part if which != "last but one" and last_part in offsets else offsets[-2]
    damaged = damaged_copy(recording, tmp_path / "damaged.mcap", chunk, where)
    planned = _planned(damaged, monkeypatch)
    if in_parts and len(os.sched_getaffinity(0)) >= 2:
        assert len(planned) >= 2 and planned[-1].start == last_part <= chunk
    elif not in_parts:
        assert planned == [parts.Part(MAGIC_BYTES, None)]
    whole = answer(damaged, tmp_path / "whole")
    split = answer(damaged, tmp_path / "parts", env=PART_BYTES)
    assert whole.returncode == 0 and "damaged data at byte" in whole.stderr, whole.stderr
    assert str(damaged) in whole.stderr
    assert split.returncode == whole.returncode
    assert split.stdout == whole.stdout and split.stderr == whole.stderr


def channel_lie(
    source: Path, target: Path, topic: bytes, change: Callable[[bytearray, int], None]
) -> Path:
    """``source`` whose summary's channel of ``topic`` is changed in place by ``change``
    (of the file's bytes and the channel record's body offset), its summary CRC computed
    again: the
    chunks' own channel records then tell what the summary does not."""
    data = bytearray(source.read_bytes())
    footer = len(data) - MAGIC_BYTES - FOOTER.size
    opcode, length, position, offsets, _crc = FOOTER.unpack_from(data, footer)
    summary = position
    while position < footer:
        record, size = struct.unpack_from("<BQ", data, position)
        if record == CHANNEL_OPCODE and topic in data[position + 9 : position + 9 + size]:
            change(data, position + 9)
        position += 9 + size
    crc = zlib.crc32(data[summary : footer + FOOTER.size - 4])
    FOOTER.pack_into(data, footer, opcode, length, summary, offsets, crc)
    target.write_bytes(bytes(data))
    return target


@pytest.mark.parametrize("lie", ["another id", "another topic"])
def test_a_summary_without_a_channel_the_chunks_define_is_read_again_in_one_part(
    recording, truth, tmp_path, monkeypatch, lie
):
    def change(data: bytearray, body: int) -> None:
        if lie == "another id":
            struct.pack_into("<H", data, body, 0x7777)
        else:  # the topic's last letter: the chunks' channel record gives the true one
            topic_end = body + 4 + 4 + len(b"/btlog/events")
            data[topic_end - 1] ^= 0x20

    hostile = channel_lie(recording, tmp_path / "channels.mcap", b"/btlog/events", change)
    monkeypatch.setenv("BTLOG_PART_BYTES", PART_BYTES["BTLOG_PART_BYTES"])
    if len(os.sched_getaffinity(0)) >= 2:
        assert len(parts.plan(str(hostile))) >= 2  # tried in parts
    result = answer(hostile, tmp_path / "cache", env=PART_BYTES)
    assert result.returncode == 0, result.stderr
    assert result.stdout == truth.stdout and result.stderr == ""
    (entry,) = [e for e in cache.entries(tmp_path / "cache") if "snapshots" not in e.path.name]
    assert len(cache.transitions_paths(entry.path)) == 1  # read again, in one part
    assert [p.name for p in (tmp_path / "cache").iterdir() if p.name.startswith(".")] == []


def test_messages_of_undefined_channels_in_every_part_are_told_once(
    recording, tmp_path, monkeypatch
):
    def with_strays():
        for number, (topic, log_time, data) in enumerate(iter_messages(recording)):
            yield topic, log_time, data
            if number % 20 == 0:
                yield 999, log_time, b"stray"

    strays = write_messages(
        tmp_path / "strays.mcap", stored_metadata(recording), with_strays(), chunk_size=2048
    )
    monkeypatch.setenv("BTLOG_PART_BYTES", PART_BYTES["BTLOG_PART_BYTES"])
    if len(os.sched_getaffinity(0)) >= 2:
        assert len(parts.plan(str(strays))) >= 2
    split = answer(strays, tmp_path / "parts", env=PART_BYTES)
    monkeypatch.delenv("BTLOG_PART_BYTES")
    whole = answer(strays, tmp_path / "whole")
    assert whole.returncode == 0 and whole.stdout == split.stdout, whole.stderr
    (told,) = whole.stderr.splitlines()
    assert "messages of channels the file never defines skipped" in told
    assert split.stderr == whole.stderr

"""Fuzzed btlog recordings (``tests/fuzz_support.py``): a real recording in many small
chunks, damaged byte by byte, read by ``open_recording`` and by the real command line
(``sql``, ``explain``), ends in exit 0 or in exit 2 with one line naming the file; never
in exit 3 or a traceback. On success nothing intact is lost: every event of a chunk that
ends before the first damaged byte is read, and a flipped byte inside one chunk loses
that chunk's events only."""

from __future__ import annotations

import struct
import tempfile
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st
from mcap.opcode import Opcode

from btlog.record import RecordingError, open_recording
from btlog.record import format as fmt
from btlog.record.walk import HEAD, MESSAGE_HEAD, chunk_records, inner_records
from tests.fuzz_support import Damage, assert_contract, damaged, fuzz, run_cli, scratch_folder
from tests.test_damage import chunks, record

_FOLDER = scratch_folder("btlog-fuzz-recordings-")
_SOURCE = _FOLDER / "run.mcap"
record(_SOURCE, ticks=120)
ORIGINAL = _SOURCE.read_bytes()
CHUNKS = chunks(ORIGINAL)
#: where the damage may start: after the magic and the header record (the metadata,
#: the chunks, the summary and the footer may all be damaged)
AFTER_HEADER = 8 + HEAD.size + int.from_bytes(ORIGINAL[9:17], "little")


def _event_seqs(offset: int, length: int) -> set[int]:
    """The seqs of the events in the chunk at ``offset`` (of the original file)."""
    seqs: set[int] = set()
    buffer = chunk_records(ORIGINAL, offset + HEAD.size, offset + length)
    for opcode, data, body, end in inner_records(buffer):
        if opcode != Opcode.MESSAGE:
            continue
        (channel,) = struct.unpack_from("<H", data, body)
        payload = bytes(data[body + MESSAGE_HEAD : end])
        if channel == EVENTS_CHANNEL:
            events = fmt.parse_events(payload)
            seqs.update(row[0] for rows in (events.status, events.writes) for row in rows)
    return seqs


def _events_channel() -> int:
    """The id of the events channel, from its record in the chunks."""
    for offset, length in CHUNKS:
        buffer = chunk_records(ORIGINAL, offset + HEAD.size, offset + length)
        for opcode, data, body, _end in inner_records(buffer):
            if opcode == Opcode.CHANNEL:
                (channel,) = struct.unpack_from("<H", data, body)
                (topic_length,) = struct.unpack_from("<I", data, body + 4)
                topic = bytes(data[body + 8 : body + 8 + topic_length]).decode()
                if topic == fmt.EVENTS_TOPIC:
                    return channel
    raise AssertionError("no events channel")


EVENTS_CHANNEL = _events_channel()
SEQS = [_event_seqs(offset, length) for offset, length in CHUNKS]
assert sum(len(s) for s in SEQS) == len(open_recording(_SOURCE).events)


def _write(damage: Damage) -> Path:
    folder = Path(tempfile.mkdtemp(dir=_FOLDER))
    path = folder / "damaged.mcap"
    path.write_bytes(damage.data)
    return path


def _read(path: Path) -> set[int] | None:
    """The seqs ``open_recording`` reads (None: refused, in one line naming the file)."""
    try:
        recording = open_recording(path)
    except RecordingError as error:
        assert str(path) in str(error) and "\n" not in str(error), str(error)
        return None
    return {event.seq for event in recording.events}


@given(damage=damaged(ORIGINAL, start=AFTER_HEADER))
@fuzz(examples=60, seconds=15)
def test_a_damaged_recording_is_read_with_its_intact_chunks_or_refused(damage: Damage) -> None:
    path = _write(damage)
    read = _read(path)
    if read is not None:
        intact = set().union(
            *(s for (o, n), s in zip(CHUNKS, SEQS, strict=True) if o + n <= damage.intact)
        )
        assert intact <= read, f"{len(intact - read)} intact events lost"
    cache = path.parent / "cache"
    outcome = run_cli("sql", path, "SELECT count(*) FROM transitions", "--cache-dir", cache)
    assert_contract(outcome, str(path))
    assert_contract(run_cli("explain", path, "--cache-dir", cache), str(path))


@given(
    chunk=st.integers(0, len(CHUNKS) - 1),
    where=st.floats(0.0, 0.999),
    mask=st.integers(1, 255),
)
@fuzz(examples=40, seconds=12)
def test_a_flipped_byte_in_a_chunk_loses_that_chunk_only(chunk: int, where: float, mask: int):
    offset, length = CHUNKS[chunk]
    at = offset + HEAD.size + int(where * (length - HEAD.size))
    data = bytearray(ORIGINAL)
    data[at] ^= mask
    path = _write(Damage(bytes(data), at, f"byte {at} ^= {mask:#04x}"))
    read = _read(path)
    others = set().union(*(s for i, s in enumerate(SEQS) if i != chunk))
    if read is None:  # only the chunk holding the tree (and the channels) may be vital
        assert chunk == 0
        return
    assert others <= read, f"{len(others - read)} events of other chunks lost"
    outcome = run_cli("explain", path, "--cache-dir", path.parent / "cache")
    assert_contract(outcome, str(path))

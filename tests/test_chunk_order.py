"""Reading a recording does not depend on the order of its chunks in the file: chunks
moved around (every CRC valid) read as the original does, with or without the summary
that names the channels first, and no event before the ``/btlog/tree`` chunk is lost."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from btlog.record import open_recording
from tests.cli_support import btlog
from tests.test_damage import chunks, record


@pytest.fixture(scope="module")
def original(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("order") / "run.mcap"
    record(path)
    assert len(chunks(path.read_bytes())) >= 30
    return path


#: The data end record (opcode 0x0F, length 4, a zero CRC) that follows the last chunk.
DATA_END = bytes([0x0F, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])


def reordered(source: Path, target: Path, order: list[int], keep_summary: bool = True) -> Path:
    """``source`` with its chunks (each with its message indexes) rewritten in ``order``
    (bytes unchanged, so every CRC holds, the summary's included); without
    ``keep_summary`` the file ends after its last chunk (a cut file)."""
    data = source.read_bytes()
    starts = [offset for offset, _length in chunks(data)]
    last = data.index(DATA_END, starts[-1])
    parts = [data[a:b] for a, b in zip(starts, [*starts[1:], last], strict=True)]
    tail = data[last:] if keep_summary else b""
    target.write_bytes(data[: starts[0]] + b"".join(parts[i] for i in order) + tail)
    return target


def shuffled_order(count: int, seed: int = 7) -> list[int]:
    order = list(range(count))
    random.Random(seed).shuffle(order)
    assert order != sorted(order)
    return order


def rows(path: Path) -> str:
    """Every row of the read model's tables, as ``btlog sql`` prints them (CSV)."""
    query = (
        "SELECT 't', seq, tick, uid::VARCHAR, prev_status::VARCHAR, status::VARCHAR "
        "FROM transitions UNION ALL "
        "SELECT 'b', seq, tick, key, value::VARCHAR, type FROM blackboard UNION ALL "
        "SELECT 'k', tick, start_ns, end_ns::VARCHAR, root_status::VARCHAR, "
        "teardown::VARCHAR FROM ticks ORDER BY 1, 2, 3"
    )
    done = btlog("sql", path, query, "--format", "csv", "--cache-dir", path.parent / "cache")
    assert done.returncode == 0, done.stderr
    assert "gap-free" not in done.stderr, done.stderr
    return done.stdout


def test_two_chunks_swapped_read_the_same_transitions(original, tmp_path):
    count = len(chunks(original.read_bytes()))
    swapped = reordered(original, tmp_path / "swapped.mcap", [1, 0, *range(2, count)])
    before, after = open_recording(original), open_recording(swapped)
    assert len(before.transitions) > 1000
    assert after.transitions == before.transitions
    assert after.events == before.events
    assert after.ticks == before.ticks
    assert after.warnings == []


@pytest.mark.parametrize("keep_summary", [True, False], ids=["summary", "no-summary"])
def test_thirty_chunks_shuffled_keep_every_row(original, tmp_path, keep_summary):
    count = len(chunks(original.read_bytes()))
    order = shuffled_order(count)
    moved = reordered(original, tmp_path / "shuffled.mcap", order, keep_summary)
    assert order.index(0) > 0  # the /btlog/tree chunk (the first written) is not first
    before, after = open_recording(original), open_recording(moved)
    assert after.events == before.events
    assert after.ticks == before.ticks
    assert after.truncated is not keep_summary
    assert rows(original).count("\n") > 1500
    assert rows(moved) == rows(original)


def test_explain_of_shuffled_chunks_is_the_original_story(original, tmp_path):
    count = len(chunks(original.read_bytes()))
    moved = reordered(original, tmp_path / "shuffled.mcap", shuffled_order(count, seed=3))
    told = [btlog("explain", path, "--cache-dir", tmp_path / "cache") for path in (original, moved)]
    assert [t.returncode for t in told] == [0, 0], told[1].stderr
    assert told[1].stdout == told[0].stdout
    assert "0 events" not in told[1].stdout

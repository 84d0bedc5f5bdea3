"""``export --to btlog`` streamed (bounded memory) writes the same bytes as the export of
the whole recording read into memory: on a recording of many chunks with blackboard
writes, on a file cut short, and (by falling back) on chunks out of seq order."""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.record import open_recording
from btlog.sinks.btcpp_filelog import export_filelog
from btlog.sinks.filelog_stream import stream_filelog
from tests.cli_support import btlog
from tests.test_chunk_order import reordered
from tests.test_damage import chunks, record


@pytest.fixture(scope="module")
def original(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("stream") / "run.mcap"
    record(path)
    assert len(chunks(path.read_bytes())) >= 30
    return path


def old_export(recording: Path, out: Path) -> bytes:
    """The bytes of the export of the whole recording read into memory."""
    export_filelog(open_recording(recording), out)
    return out.read_bytes()


def test_streamed_export_of_many_chunks_is_the_old_export(original, tmp_path):
    streamed = stream_filelog(original, tmp_path / "streamed.btlog")
    assert streamed is not None  # in seq order: streamed, not the fallback
    assert streamed.warnings == []
    old = old_export(original, tmp_path / "old.btlog")
    assert (tmp_path / "streamed.btlog").read_bytes() == old
    recording = open_recording(original)
    assert streamed.result.transitions == len(recording.transitions) > 1000
    assert streamed.result.writes_left_out == len(recording.events) - len(recording.transitions)
    assert streamed.result.writes_left_out > 0
    done = btlog("export", original, "--to", "btlog", tmp_path / "cli.btlog")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "cli.btlog").read_bytes() == old
    assert f"{streamed.result.writes_left_out} blackboard writes left out" in done.stderr


def test_a_cut_file_streams_its_prefix_with_the_readers_warning(original, tmp_path):
    data = original.read_bytes()
    starts = [offset for offset, _length in chunks(data)]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: starts[len(starts) // 2] + 40])  # inside a chunk
    streamed = stream_filelog(cut, tmp_path / "streamed.btlog")
    assert streamed is not None
    recording = open_recording(cut)
    assert recording.truncated
    assert streamed.warnings == recording.warnings
    assert "truncated recording" in streamed.warnings[0]
    assert (tmp_path / "streamed.btlog").read_bytes() == old_export(cut, tmp_path / "old.btlog")


@pytest.mark.parametrize("keep_summary", [True, False], ids=["summary", "no-summary"])
def test_chunks_out_of_seq_order_fall_back_to_the_same_bytes(original, tmp_path, keep_summary):
    count = len(chunks(original.read_bytes()))
    order = [0, 2, 1, *range(3, count)]
    swapped = reordered(original, tmp_path / "swapped.mcap", order, keep_summary)
    out = tmp_path / "streamed.btlog"
    assert stream_filelog(swapped, out) is None
    assert not out.exists()  # the partial file is removed
    done = btlog("export", swapped, "--to", "btlog", tmp_path / "cli.btlog")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "cli.btlog").read_bytes() == old_export(original, tmp_path / "old.btlog")

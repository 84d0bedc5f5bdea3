"""``btlog export --to nav2`` streams a recording in order (bounded memory): the bag holds
the messages the whole-recording export writes; a file whose chunks were moved is
exported whole instead, to the same messages."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from btlog.record.reader import open_recording
from btlog.sinks.nav2_rosbag import export_nav2
from btlog.sinks.nav2_stream import stream_nav2
from tests.cli_support import btlog
from tests.test_chunk_order import reordered, shuffled_order
from tests.test_damage import chunks
from tests.test_damage import record as record_loop
from tests.test_nav2_rosbag import record


def decoded(bag: Path) -> list[tuple]:
    with open(bag, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [
            (channel.topic, message.log_time, repr(ros))
            for _schema, channel, message, ros in reader.iter_decoded_messages()
        ]


def test_the_streamed_bag_is_the_whole_recordings_bag(tmp_path: Path) -> None:
    record_loop(tmp_path / "loop.mcap")
    for run in (record(tmp_path, "nav2"), open_recording(tmp_path / "loop.mcap")):
        whole, streamed = tmp_path / f"{run.path.stem}-whole.mcap", tmp_path / "streamed.mcap"
        expected = export_nav2(run, whole)
        done = stream_nav2(run.path, streamed)
        assert done is not None
        result, warnings = done
        assert (result.messages, result.transitions, result.writes_left_out) == (
            expected.messages,
            expected.transitions,
            expected.writes_left_out,
        )
        assert warnings == run.warnings
        assert decoded(streamed) == decoded(whole) and result.messages > 3
        streamed.unlink()


def test_moved_chunks_are_exported_whole_to_the_same_messages(tmp_path: Path) -> None:
    path = tmp_path / "loop.mcap"
    record_loop(path)
    count = len(chunks(path.read_bytes()))
    moved = reordered(path, tmp_path / "moved.mcap", shuffled_order(count))
    assert stream_nav2(moved, tmp_path / "streamed.mcap") is None
    assert not (tmp_path / "streamed.mcap").exists()
    for source, bag in ((path, "a.mcap"), (moved, "b.mcap")):
        done = btlog("export", source, "--to", "nav2", tmp_path / bag)
        assert done.returncode == 0, done.stderr
    assert decoded(tmp_path / "a.mcap") == decoded(tmp_path / "b.mcap")

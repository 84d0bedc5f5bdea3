"""MCAP log_time is the run's clock: start + t_ns, so players show a run at its own pace.

A simulated kitting run is recorded for real and its messages are read back with the
official MCAP reader; the committed recordings (schema version 1) still read.
"""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import pytest
from mcap.reader import make_reader

import btlog
from btlog.record import format as fmt
from btlog.record import open_recording, read_metadata
from btlog.record.recorder import GROUP_NS
from btlog.runner import RunConfig, execute

ROOT = Path(__file__).resolve().parents[1]
OLD_RECORDING = ROOT / "tests" / "data" / "v1-kitting-ok.mcap"  # schema version 1


@pytest.fixture(scope="module")
def kitting(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A kitting run in which look at chuck fails once (simulated clock)."""
    path = tmp_path_factory.mktemp("log-time") / "kitting.mcap"
    config = RunConfig(tree=str(ROOT / "trees" / "kitting.xml"), domain="kitting")
    config.fail = ["look at chuck"]
    execute(config, path)
    return path


def test_log_time_is_start_plus_the_events_time(kitting: Path) -> None:
    metadata = read_metadata(kitting)
    assert metadata["schema_version"] == btlog.SCHEMA_VERSION == "3"
    start = datetime.fromisoformat(metadata["started_at"])
    start_ns = int(start.timestamp() * 1_000_000) * 1000
    spans = []
    with kitting.open("rb") as file:
        for _schema, channel, message in make_reader(file).iter_messages(log_time_order=False):
            if channel.topic == fmt.EVENTS_TOPIC:
                events = fmt.parse_events(message.data)
                last = max([*events.status, *events.writes], key=lambda row: row[0])
                assert message.log_time == start_ns + last[1]
                spans.append(message.log_time)
            elif channel.topic == fmt.TREE_TOPIC:
                assert message.log_time == start_ns
    duration = open_recording(kitting).ticks[-1].end_ns
    assert duration > 10**10  # a run of tens of simulated seconds…
    assert spans == sorted(spans)
    assert max(spans) - start_ns > duration * 0.9  # …spans as much log time


def test_events_are_cut_by_the_runs_clock_so_a_player_plays_them_in_time(kitting: Path) -> None:
    """A message spans at most ``GROUP_NS`` (100 ms) of run time, so each event is shown
    within 100 ms of its time: the 72 s run is many messages, not one at its end."""
    spans = []
    with kitting.open("rb") as file:
        for _schema, _channel, message in make_reader(file).iter_messages(
            topics=[fmt.EVENTS_TOPIC]
        ):
            events = fmt.parse_events(message.data)
            times = [row[1] for row in [*events.status, *events.writes]]
            spans.append((min(times), max(times)))
    assert all(last - first <= GROUP_NS for first, last in spans)
    assert len(spans) >= 40
    assert spans[0][1] < 1e9 and spans[-1][0] > 70e9  # the first second and the last


def test_a_schema_version_1_recording_still_reads() -> None:
    assert read_metadata(OLD_RECORDING)["schema_version"] == "1"
    recording = open_recording(OLD_RECORDING)
    assert len(recording.events) > 100

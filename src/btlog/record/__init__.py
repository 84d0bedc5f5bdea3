"""Recording: a run's events in one MCAP file, written as they happen and read back.

- ``Recorder`` (a ``Subscriber``) writes the file while the executor runs; it flushes by
  wall time, so a killed run loses at most the last ``flush_interval`` seconds;
- ``open_recording`` reads a file back as a ``Recording`` (tree, events in seq order,
  ticks, answers, metadata, attachments), a truncated file included, with a warning;
  ``iter_messages`` streams raw messages for bulk consumers and ``read_metadata`` reads
  only the run's metadata;
- ``recover`` rewrites a truncated file into a valid, indexed one;
- ``RecordingError`` is what bad input raises, one line naming file and problem.

The wire format (topics, message layouts, metadata keys) is ``btlog.record.format``; its
JSON Schemas are served by ``btlog.schema.schema_text``.
"""

from btlog.record.reader import (
    MessageStream,
    Recording,
    RecordingError,
    iter_messages,
    open_recording,
    read_metadata,
)
from btlog.record.recorder import Recorder
from btlog.record.recover import RecoveryReport, recover
from btlog.schema import schema_text

__all__ = [
    "MessageStream",
    "Recorder",
    "Recording",
    "RecordingError",
    "RecoveryReport",
    "iter_messages",
    "open_recording",
    "read_metadata",
    "recover",
    "schema_text",
]

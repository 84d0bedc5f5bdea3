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

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from btlog.record.reader import (
        MessageStream,
        Recording,
        RecordingError,
        iter_messages,
        open_recording,
        read_metadata,
    )
    from btlog.record.recorder import Recorder
    from btlog.record.recovery import RecoveryReport, recover
    from btlog.schema import schema_text

#: Where each public name lives: imported on first use, so reading a cache (which needs
#: only ``btlog.record.format``) does not import the MCAP writer and the recovery.
_HOMES = {
    "MessageStream": "btlog.record.reader",
    "Recording": "btlog.record.reader",
    "RecordingError": "btlog.record.reader",
    "iter_messages": "btlog.record.reader",
    "open_recording": "btlog.record.reader",
    "read_metadata": "btlog.record.reader",
    "Recorder": "btlog.record.recorder",
    "RecoveryReport": "btlog.record.recovery",
    "recover": "btlog.record.recovery",
    "schema_text": "btlog.schema",
}


def __getattr__(name: str) -> Any:
    """The public names, imported from their modules on first use (PEP 562)."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'btlog.record' has no attribute {name!r}")
    return getattr(importlib.import_module(home), name)


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

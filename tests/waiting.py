"""Waiting on a running recorder by what it has written, never by a guessed sleep."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest

from btlog.record.reader import RecordingError, open_recording


def wait_for_events(
    path: Path, process: subprocess.Popen, at_least: int = 1, timeout: float = 30.0
) -> int:
    """Wait until the readable prefix of the recording at ``path`` holds ``at_least``
    events while ``process`` still runs, and return how many it holds. Fails the test
    when the process ends first or the events do not come within ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            pytest.fail(f"the recorder ended (exit {process.returncode}) before {path} grew")
        try:
            count = len(open_recording(path).events) if path.exists() else 0
        except RecordingError:
            count = 0  # not even the header yet
        if count >= at_least:
            return count
        time.sleep(0.02)
    pytest.fail(f"{path} did not reach {at_least} events in {timeout} s")

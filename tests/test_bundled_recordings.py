"""The bundled recordings are what today's code records (``recordings/regenerate.py
--check``), the check sees a stale one, and so does ``btlog check --rerun``."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from tests.cli_support import ROOT, btlog, btlog_environment

SCRIPT = ROOT / "recordings" / "regenerate.py"


def test_regenerating_the_bundled_recordings_changes_nothing() -> None:
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--check"], cwd=ROOT, env=btlog_environment(),
        capture_output=True, text=True, check=False, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_check_names_a_stale_recording(tmp_path: Path) -> None:
    """A copy of the project whose kitting-ok.mcap is an older recording (schema
    version 1, two ticks longer): the check fails and says what differs."""
    copy = tmp_path / "project"
    (copy / "recordings").mkdir(parents=True)
    shutil.copytree(ROOT / "trees", copy / "trees")
    shutil.copy(SCRIPT, copy / "recordings" / SCRIPT.name)
    shutil.copy(
        ROOT / "tests" / "data" / "v1-kitting-ok.mcap", copy / "recordings" / "kitting-ok.mcap"
    )
    done = subprocess.run(
        [sys.executable, str(copy / "recordings" / SCRIPT.name), "--check", "kitting-ok.mcap"],
        cwd=copy, env=btlog_environment(), capture_output=True, text=True, check=False,
        timeout=600,
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    assert "recordings/kitting-ok.mcap is stale" in done.stdout
    assert "ticks: 640 recorded" in done.stdout


def test_check_rerun_fails_on_a_stale_recording() -> None:
    """The schema-version-1 kitting-ok (older code: two ticks and an event more) re-runs
    to the same actions but not the same run: its duration, ticks and events differ."""
    stale = ROOT / "tests" / "data" / "v1-kitting-ok.mcap"
    done = btlog("check", str(stale), "--rerun")
    assert done.returncode == 1, done.stdout + done.stderr
    assert "FAIL  duration, ticks and events" in done.stdout
    assert "expected: 63.900 s, 640 ticks, 216 events" in done.stdout
    fresh = btlog("check", str(ROOT / "recordings" / "kitting-ok.mcap"), "--rerun")
    assert fresh.returncode == 0, fresh.stdout
    assert "ok    duration, ticks and events" in fresh.stdout

"""The bundled recordings are what today's code records (``recordings/regenerate.py
--check``), and the check sees a stale one."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from tests.cli_support import ROOT, btlog_environment

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

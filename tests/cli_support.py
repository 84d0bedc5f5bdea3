"""The real ``btlog`` command line in a subprocess, for the tests that run it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def btlog_environment(env: dict[str, str] | None = None) -> dict[str, str]:
    """The environment ``btlog`` runs in: this checkout's source first on the path, colour
    off and ``BTLOG_DEBUG`` unset unless ``env`` (added) sets it."""
    paths = [str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]
    environment = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(p for p in paths if p),
        "NO_COLOR": "1",
    }
    environment.pop("BTLOG_DEBUG", None)
    environment.update(env or {})
    return environment


def btlog_command(*args: str | os.PathLike) -> list[str]:
    """The command line of ``btlog ARGS``, for tests that start it themselves."""
    return [sys.executable, "-m", "btlog.cli.main", *map(str, args)]


def btlog(
    *args: str | os.PathLike,
    cwd: str | os.PathLike | None = ROOT,
    env: dict[str, str] | None = None,
    timeout: float = 120,
) -> subprocess.CompletedProcess:
    """Run ``btlog ARGS`` (this checkout's source) and capture its output as text (see
    ``btlog_environment``)."""
    return subprocess.run(
        btlog_command(*args),
        cwd=cwd,
        env=btlog_environment(env),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def assert_bad_input(result: subprocess.CompletedProcess, *words: str) -> None:
    """Exit 2, one line on stderr mentioning ``words``, no traceback."""
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0]

"""The real ``btlog`` command line in a subprocess, for the tests that run it."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
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
    input: str | None = None,
    address_space: int | None = None,
) -> subprocess.CompletedProcess:
    """Run ``btlog ARGS`` (this checkout's source) and capture its output as text (see
    ``btlog_environment``); ``input`` is its standard input; ``address_space``, bytes,
    limits the process's address space as ``ulimit -v`` does."""
    return subprocess.run(
        btlog_command(*args),
        cwd=cwd,
        input=input,
        env=btlog_environment(env),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        preexec_fn=None if address_space is None else _address_space_limit(address_space),
    )


def _address_space_limit(size: int) -> Callable[[], None]:
    """A ``preexec_fn`` limiting the child's address space to ``size`` bytes."""

    def limit() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (size, size))

    return limit


def assert_bad_input(result: subprocess.CompletedProcess, *words: str) -> None:
    """Exit 2, one line on stderr mentioning ``words``, no traceback."""
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0]


class Terminal:
    """``btlog ARGS`` on a real terminal (a pty: stdin, stdout and stderr), for what only
    a terminal shows: keystrokes, progress bars. ``send`` types, ``expect`` reads until a
    text appears (or the process ends: then ``expect`` fails naming what it saw)."""

    def __init__(self, *args: str | os.PathLike, cwd: str | os.PathLike, columns: int = 120):
        import pty
        import struct
        import termios
        from fcntl import ioctl

        self.leader, follower = pty.openpty()
        ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 50, columns, 0, 0))
        env = btlog_environment({"COLUMNS": str(columns), "TERM": "xterm"})
        env.pop("NO_COLOR", None)
        env["PROMPT_TOOLKIT_NO_CPR"] = "1"  # no cursor-position queries to answer
        self.process = subprocess.Popen(
            btlog_command(*args), cwd=cwd, env=env, stdin=follower, stdout=follower,
            stderr=follower, close_fds=True, start_new_session=True,
        )  # fmt: skip
        os.close(follower)
        self.output = ""
        self._read_to = 0

    def send(self, keys: str) -> None:
        """Type ``keys`` (escape sequences for arrow keys: ``\\x1b[C`` is →)."""
        os.write(self.leader, keys.encode())

    def _read(self, timeout: float) -> bool:
        import select

        ready, _, _ = select.select([self.leader], [], [], timeout)
        if not ready:
            return False
        try:
            data = os.read(self.leader, 65536)
        except OSError:  # the terminal closed: the process has ended
            return False
        self.output += data.decode(errors="replace")
        return bool(data)

    def expect(self, text: str, timeout: float = 60) -> str:
        """The output from the last ``expect`` up to and including ``text``."""
        import time

        deadline = time.monotonic() + timeout
        while text not in self.output[self._read_to :]:
            left = deadline - time.monotonic()
            if left <= 0 or not self._read(left):
                raise AssertionError(f"{text!r} never appeared; the terminal shows:\n"
                                     f"{self.output[self._read_to:][-3000:]}")  # fmt: skip
        end = self.output.index(text, self._read_to) + len(text)
        seen, self._read_to = self.output[self._read_to : end], end
        return seen

    def finish(self, timeout: float = 60) -> str:
        """Read until the process ends; its whole output."""
        while self._read(timeout):
            pass
        self.process.wait(timeout=timeout)
        os.close(self.leader)
        return self.output

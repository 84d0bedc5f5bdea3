"""Fuzzing btlog's readers: damaged copies of valid inputs, and the contract they keep.

One harness for every reader (btlog's recordings, ``.btlog``, SqliteLogger, rosbag2,
``.fbl``, Groot2 replies). A fuzz test takes a valid input made by the test, damages it
with ``damaged`` (hypothesis over bytes: flips, truncations, boundary integers, spans
deleted, duplicated or inserted), feeds it to the real command line in-process
(``run_cli``: ``btlog.cli.main.main``, the same exit-code contract as the installed
command, without a subprocess's start-up) or to a reader directly, and checks:

- ``assert_contract``: exit 0 or 2, never 3 ("a bug in btlog") nor a traceback; exit 2
  is one line on stderr naming what it must name (the file, an offset or a key);
- ``assert_prefix_kept``: on success, what lay wholly before the first damaged byte is
  kept, in order (``Damage.intact`` is that byte).

``fuzz`` bounds a test: seeded (``derandomize``, no example database, so every run tries
the same inputs), at most ``examples`` inputs and about ``seconds`` of wall time (inputs
past the allowance pass without running, unless an input already failed, so shrinking
still works). Use it under ``@given``::

    @given(damage=damaged(ORIGINAL, start=HEADER))
    @fuzz(examples=60, seconds=10)
    def test_damaged_logs(damage: Damage) -> None:
        ...
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import io
import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st

from btlog.errors import EXIT_BAD_INPUT, EXIT_OK

#: Integers that readers get wrong most often, written little-endian at a chosen width.
BOUNDARY_VALUES = (0, 1, -1, 2, 8, 9, 255, 1 << 15, 1 << 16, 1 << 31, 1 << 32, 1 << 48, 1 << 62)


@dataclass(frozen=True)
class Damage:
    """A damaged copy of an input: its bytes, how many leading bytes are the original's
    (``intact``), and what was done, for the failure message."""

    data: bytes
    intact: int
    how: str

    def __repr__(self) -> str:
        return f"Damage({self.how}; {len(self.data)} bytes, intact up to {self.intact})"


def _at(original: bytes, start: int, end: int | None) -> st.SearchStrategy[int]:
    stop = len(original) if end is None else min(end, len(original))
    return st.integers(min_value=min(start, max(stop - 1, 0)), max_value=max(stop - 1, 0))


def _boundary(width: int) -> st.SearchStrategy[bytes]:
    bits = 8 * width
    values = st.sampled_from(BOUNDARY_VALUES) | st.integers(-(1 << (bits - 1)), (1 << bits) - 1)
    return values.map(lambda v: (v % (1 << bits)).to_bytes(width, "little"))


@st.composite
def _one_damage(draw: Any, data: bytes, start: int, end: int | None) -> tuple[bytes, int, str]:
    offset = draw(_at(data, start, end))
    kind = draw(st.sampled_from(("flip", "truncate", "integer", "delete", "repeat", "insert")))
    if kind == "flip":
        mask = draw(st.integers(1, 255))
        changed = bytearray(data)
        if offset < len(changed):
            changed[offset] ^= mask
        return bytes(changed), offset, f"byte {offset} ^= {mask:#04x}"
    if kind == "truncate":
        return data[:offset], offset, f"cut at byte {offset}"
    if kind == "integer":
        width = draw(st.sampled_from((1, 2, 4, 6, 8)))
        value = draw(_boundary(width))
        changed = data[:offset] + value + data[offset + width :]
        return changed, offset, f"bytes {offset}..{offset + width} = {value.hex()}"
    length = draw(st.integers(1, 64))
    if kind == "delete":
        return data[:offset] + data[offset + length :], offset, f"{length} bytes at {offset} cut"
    if kind == "repeat":
        span = data[offset : offset + length]
        return data[:offset] + span + data[offset:], offset, f"{length} bytes at {offset} twice"
    noise = draw(st.binary(min_size=1, max_size=length))
    return data[:offset] + noise + data[offset:], offset, f"{len(noise)} bytes put at {offset}"


@st.composite
def damaged(
    draw: Any, original: bytes, start: int = 0, end: int | None = None, most: int = 3
) -> Damage:
    """A copy of ``original`` with 1 to ``most`` damages at offsets in ``[start, end)``
    (the whole input by default: give ``start`` to keep a header intact)."""
    data, intact, done = original, len(original), []
    for _ in range(draw(st.integers(1, most))):
        data, offset, how = draw(_one_damage(data, start, end))
        intact, done = min(intact, offset), [*done, how]
    return Damage(data, intact, "; ".join(done))


@dataclass(frozen=True)
class Outcome:
    """What one command printed and returned."""

    code: int
    stdout: str
    stderr: str


def run_cli(*args: object) -> Outcome:
    """``btlog ARGS`` in this process (the real ``main``: parsing, dispatch, exit codes),
    with its standard output and error captured."""
    from btlog.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return Outcome(code, out.getvalue(), err.getvalue())


def assert_contract(
    outcome: Outcome, *words: str, codes: Sequence[int] = (EXIT_OK, EXIT_BAD_INPUT)
) -> None:
    """Exit in ``codes`` (0 or 2), no traceback nor internal error; a refusal (exit 2) is
    one line on stderr holding each of ``words``."""
    stderr = outcome.stderr
    assert outcome.code in codes, f"exit {outcome.code}: {stderr[-2000:]}"
    assert "Traceback" not in stderr and "internal error" not in stderr, stderr[-2000:]
    if outcome.code == EXIT_BAD_INPUT:
        lines = stderr.strip().splitlines()
        assert len(lines) == 1, f"a refusal in {len(lines)} lines: {stderr[-2000:]}"
        for word in words:
            assert word in lines[0], f"{word!r} not in {lines[0]!r}"


def assert_prefix_kept(intact: Sequence[Any], kept: Sequence[Any]) -> None:
    """Every item of ``intact`` (what the undamaged part of the input holds) is in
    ``kept``, first and in order."""
    assert list(kept[: len(intact)]) == list(intact), (
        f"{len(intact)} intact items, the reader kept {len(kept)}; first difference at "
        f"{next((i for i, (a, b) in enumerate(zip(intact, kept, strict=False)) if a != b), '?')}"
    )


class _Allowance:
    """Wall time for one test, counted from its first input; off once an input failed."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.began: float | None = None
        self.failed = False

    def spent(self) -> bool:
        if self.began is None:
            self.began = time.monotonic()
        return not self.failed and time.monotonic() - self.began > self.seconds


def fuzz(examples: int = 50, seconds: float = 10.0) -> Callable[[Callable], Callable]:
    """Hypothesis settings of a fuzz test (seeded, ``examples`` inputs at most) and a wall
    time allowance of about ``seconds``; apply it under ``@given``."""

    def bounded(test: Callable) -> Callable:
        allowance = _Allowance(seconds)

        @functools.wraps(test)
        def run(*args: Any, **kwargs: Any) -> Any:
            if allowance.spent():
                return None
            try:
                return test(*args, **kwargs)
            except BaseException:
                allowance.failed = True
                raise

        return settings(
            max_examples=examples,
            derandomize=True,
            database=None,
            deadline=None,
            phases=(Phase.explicit, Phase.generate, Phase.shrink),  # no slow "explain"
            suppress_health_check=[
                HealthCheck.too_slow,
                HealthCheck.data_too_large,
                HealthCheck.function_scoped_fixture,
            ],
        )(run)

    return bounded


def scratch_folder(prefix: str) -> Path:
    """A new temporary folder for a fuzz module's inputs and outputs, removed when the
    process ends (a module's inputs are made at import, before any fixture exists)."""
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return folder

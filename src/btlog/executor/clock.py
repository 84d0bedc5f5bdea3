"""Time sources: a simulated clock for reproducible runs and the wall clock.

Times are integer nanoseconds since the run started. The executor calls ``start_tick(k)``
before tick ``k`` (from 1). The simulated clock then jumps to ``(k-1)`` tick periods, so a
simulated run's events and times are the same every time and it runs as fast as the
machine allows. The wall clock reads real time and, when paced, sleeps until the tick is due.
"""

from __future__ import annotations

import time


class SimClock:
    """Simulated time: tick ``k`` happens at ``(k-1) * tick_period`` seconds."""

    simulated = True

    def __init__(self, tick_period: float = 0.1) -> None:
        self.period_ns = round(tick_period * 1e9)
        #: the current simulated time in ns since start (what ``now_ns`` returns)
        self.t_ns = 0

    def now_ns(self) -> int:
        """The current simulated time in ns since start."""
        return self.t_ns

    def start_tick(self, tick: int) -> None:
        """Jump to the time of tick ``tick``."""
        self.t_ns = (tick - 1) * self.period_ns


class WallClock:
    """Monotonic wall time since construction; ``paced`` ticks wait for their due time."""

    simulated = False

    def __init__(self, tick_period: float = 0.1, paced: bool = True) -> None:
        self.period_ns = round(tick_period * 1e9)
        self.paced = paced
        self._start = time.monotonic_ns()

    def now_ns(self) -> int:
        """Nanoseconds since the clock was created."""
        return time.monotonic_ns() - self._start

    @property
    def t_ns(self) -> int:
        """``now_ns()``, read as ``SimClock.t_ns`` is (the executor's hot path does)."""
        return time.monotonic_ns() - self._start

    def start_tick(self, tick: int) -> None:
        """Sleep until tick ``tick`` is due (when paced)."""
        if self.paced:
            delay = (tick - 1) * self.period_ns - self.now_ns()
            if delay > 0:
                time.sleep(delay / 1e9)

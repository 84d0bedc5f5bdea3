"""A time limit on one DuckDB statement: a timer thread interrupts the connection when
the limit passes (DuckDB checks for the interrupt between its vectors, so the statement
ends within milliseconds, and nothing polls meanwhile)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

import duckdb


class QueryTimeout(ValueError):
    """A statement interrupted at its time limit; ``str()`` is one line."""


@contextmanager
def time_limit(con: duckdb.DuckDBPyConnection, seconds: float | None) -> Iterator[None]:
    """Run the block's statements on ``con`` with a limit of ``seconds`` (None or 0: no
    limit); ``QueryTimeout`` when the limit interrupted them. The timer is cancelled
    when the block ends, and an interrupt never reaches a later statement."""
    if not seconds:
        yield
        return
    lock = threading.Lock()
    state = {"running": True, "fired": False}

    def interrupt() -> None:
        with lock:
            if state["running"]:
                state["fired"] = True
                con.interrupt()

    timer = threading.Timer(seconds, interrupt)
    timer.daemon = True
    timer.start()
    try:
        yield
    except duckdb.InterruptException:
        if state["fired"]:
            raise QueryTimeout(
                f"the query was stopped at its time limit of {seconds:g} s (--timeout)"
            ) from None
        raise
    finally:
        with lock:
            state["running"] = False
        timer.cancel()

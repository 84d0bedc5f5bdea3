"""The recorder's writer thread: MCAP messages added, chunks compressed and written to the
file while the run goes on.

Compressing a chunk (zstd) and writing it are most of what recording costs beyond
buffering the rows, and both release the GIL: done on a thread of their own they overlap
the next ticks, as BehaviorTree.CPP's FileLogger2 writes from a thread of its own. The
run's thread only encodes each message and queues it; the thread applies the calls to the
mcap ``Writer`` in the order they were queued, so the file is the same as if they had
been made at once. The queue is bounded: a run that produces faster than the disk takes
waits for it instead of growing without end.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from mcap.writer import Writer

#: Calls queued at most (a message is about a thousand events): beyond, the run waits.
QUEUE_CALLS = 64
#: What ``wait()`` queues: done even after an error.
_DONE = threading.Event.set


def name_file(error: BaseException, name: str | None) -> BaseException:
    """``error``, naming the file ``name`` if it is an OSError that names none (a full
    disk met while writing an open file names no file)."""
    if isinstance(error, OSError) and error.filename is None and name is not None:
        error.filename = name
    return error


class BackgroundWriter:
    """Applies ``add_message``, ``flush`` and ``finish`` of ``writer`` on a thread of its
    own, in order. ``wait()`` returns once everything queued so far is done; an error
    of the writer (a full disk) is raised by the next ``wait()`` or ``stop()``, and the
    calls after it are dropped. An OSError of a file that it does not name is given
    ``name``, the file being written."""

    def __init__(self, writer: Writer, name: str | None = None) -> None:
        self._writer = writer
        self._name = name
        self._calls: queue.Queue[tuple[Callable[..., Any], tuple] | None] = queue.Queue(QUEUE_CALLS)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="btlog-recorder", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        calls, failed = self._calls, False
        while True:
            call = calls.get()
            if call is None:
                return
            function, args = call
            if failed and function is not _DONE:
                continue
            try:
                function(*args)
            except BaseException as error:  # handed to the run's thread by wait()
                self._error, failed = name_file(error, self._name), True

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int) -> None:
        """Queue ``Writer.add_message``."""
        self._calls.put((self._writer.add_message, (channel_id, log_time, data, publish_time)))

    def add_encoded(
        self,
        channel_id: int,
        log_time: int,
        encode: Callable[..., bytes],
        args: tuple,
        publish_time: int,
    ) -> None:
        """Queue ``Writer.add_message`` of the message ``encode(*args)``, encoded on the
        writer's thread (``args`` must not change afterwards: pass copies)."""
        self._calls.put((self._add_encoded, ((channel_id, log_time, encode, args, publish_time),)))

    def _add_encoded(self, call: tuple[int, int, Callable[..., bytes], tuple, int]) -> None:
        channel_id, log_time, encode, args, publish_time = call
        self._writer.add_message(channel_id, log_time, encode(*args), publish_time)

    def flush(self) -> None:
        """Queue ``Writer.flush`` (the chunk in progress is compressed and written)."""
        self._calls.put((self._writer.flush, ()))

    def wait(self) -> None:
        """Return once every call queued so far is done; raise the writer's error if any."""
        if self._thread.is_alive():
            done = threading.Event()
            self._calls.put((_DONE, (done,)))
            while not done.wait(0.1):
                if not self._thread.is_alive():
                    break
        self._raise()

    def stop(self) -> None:
        """Queue ``Writer.finish``, wait for it and end the thread."""
        if self._thread.is_alive():
            self._calls.put((self._writer.finish, ()))
            self._calls.put(None)
            self._thread.join()
        self._raise()

    @property
    def cpu_seconds(self) -> float | None:
        """The CPU time the writer's thread has used so far (None where the platform
        cannot tell, or once the thread has ended): what recording costs beyond the
        run's own thread."""
        ident = self._thread.ident
        if ident is None or not self._thread.is_alive():
            return None
        try:
            return time.clock_gettime(time.pthread_getcpuclockid(ident))
        except (AttributeError, OSError):  # no per-thread CPU clocks here
            return None

    @property
    def running(self) -> bool:
        """True until ``stop()`` has ended the thread."""
        return self._thread.is_alive()

    def _raise(self) -> None:
        error, self._error = self._error, None
        if error is not None:
            raise error

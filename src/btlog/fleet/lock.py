"""The lake's lock: many exporters and readers at once, or one compaction.

Exporting runs only adds files under names of their own (``run-{run_id}.parquet``,
written under a hidden temporary name first), so exports into one lake may run side by
side, on one machine or from CI jobs sharing a folder. A compaction is different: it
removes the files it merged and any temporary file it finds, which would break an
export writing one or a query reading one. So exports and readers hold the lake's lock
**shared**, and a compaction holds it **exclusively**: it waits for them, and they wait
for it. The lock is ``flock`` on ``LAKE/.btlog-lake.lock``; it is released when its
holder ends, however it ends. A lake folder the user may not write to is read without
the lock (nobody compacts it through btlog).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: no locking (documented in the README)
    fcntl = None  # type: ignore[assignment]

#: The lock file, at the lake's top (the lake's readers look only into table folders).
LOCK_NAME = ".btlog-lake.lock"


@contextmanager
def lake_lock(lake: str | os.PathLike, exclusive: bool) -> Iterator[None]:
    """Hold ``lake``'s lock, exclusively (compaction) or shared (export, reading), until
    the block ends; waits for it as long as it takes. The lock file is made only in a
    lake (a folder with ``runs/``, which an export makes first): reading a folder that
    is not a lake leaves nothing behind."""
    root = Path(lake)
    flags = os.O_RDWR | (os.O_CREAT if (root / "runs").is_dir() else 0)
    try:
        descriptor = os.open(root / LOCK_NAME, flags, 0o644)
    except OSError:  # no lake here, or one we may only read
        yield
        return
    try:
        if fcntl is not None:
            fcntl.flock(descriptor, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        yield
    finally:
        os.close(descriptor)  # releases the lock

"""The bounds btlog puts on untrusted input, and the one bounded file read.

Trees, outcomes and expectations files come from users and may be hostile: a file may be
``/dev/zero``, a few KB of XML may expand (SubTree calling SubTree) to billions of nodes,
a script may double a string forty times. Every such input is refused with one line
naming the file as soon as a bound is crossed, before the memory or time is spent.

The defaults are documented in the README's security notes; the commands that load trees
take ``--max-nodes`` and ``--max-file-size`` to raise (or lower) the first two.
"""

from __future__ import annotations

import math
import os
import resource
import stat
from dataclasses import dataclass, replace

#: Bytes of one tree, outcomes or expectations file (includes are counted one by one).
MAX_FILE_BYTES = 8 * 1024 * 1024
#: Nodes of a tree once every SubTree is expanded.
MAX_NODES = 200_000
#: Depth of a tree once every SubTree is expanded (the root has depth 0).
MAX_DEPTH = 200
#: Attributes on one XML element, and nesting of XML elements.
MAX_ATTRIBUTES = 1_000
MAX_XML_NESTING = 256
#: Characters of one string built by a script (``..``), and of one script's code.
MAX_SCRIPT_STRING = 16 * 1024 * 1024
MAX_SCRIPT_CODE = 64 * 1024
#: Nesting of parentheses and unary operators in one script.
MAX_SCRIPT_NESTING = 64
#: Values of one outcomes or expectations file once its YAML aliases are expanded.
MAX_DOCUMENT_VALUES = 1_000_000
#: Seconds a ``btlog sql`` query may run unless ``--timeout`` says otherwise.
DEFAULT_QUERY_TIMEOUT = 60.0
#: Any count, tick or seq given by a user, and any duration in ns: a signed 64-bit integer.
MAX_INT64 = 2**63 - 1


class LimitError(ValueError):
    """An input that crosses one of the bounds; ``str()`` is one line."""


@dataclass(frozen=True)
class Limits:
    """The bounds that commands may override with flags."""

    max_file_bytes: int = MAX_FILE_BYTES
    max_nodes: int = MAX_NODES


_current = Limits()


def current() -> Limits:
    """The limits in force (the defaults unless a command overrode them)."""
    return _current


def override(max_file_bytes: int | None = None, max_nodes: int | None = None) -> Limits:
    """Set the limits for this process (the CLI's ``--max-file-size``/``--max-nodes``);
    ``None`` keeps a limit as it is. Returns the limits now in force."""
    global _current
    for flag, value in (("--max-file-size", max_file_bytes), ("--max-nodes", max_nodes)):
        if value is not None and value < 1:
            raise LimitError(f"{flag} {value}: must be at least 1")
    changes = {"max_file_bytes": max_file_bytes, "max_nodes": max_nodes}
    _current = replace(_current, **{k: v for k, v in changes.items() if v is not None})
    return _current


def read_bounded(path: str | os.PathLike, limit: int | None = None) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (default: the current
    ``max_file_bytes``). The size is checked with ``stat`` before reading and the read
    itself stops one byte past the limit, so ``/dev/zero``, a FIFO or a file growing
    while it is read is refused at once. Raises ``LimitError`` or ``OSError``."""
    limit = current().max_file_bytes if limit is None else limit
    # O_NONBLOCK: opening a FIFO must not wait for a writer; fstat then refuses it.
    descriptor = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with open(descriptor, "rb") as file:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            raise LimitError("not a regular file")
        if info.st_size > limit:
            raise LimitError(f"file is larger than {limit} bytes (--max-file-size)")
        data = file.read(limit + 1)
    if len(data) > limit:
        raise LimitError(f"file is larger than {limit} bytes (--max-file-size)")
    return data


def seconds(value: object, what: str, positive: bool = False) -> float:
    """``value`` if it is a finite number of seconds, >= 0 (> 0 when ``positive``),
    whose nanoseconds fit in 64 bits; else ``LimitError`` naming ``what`` and the value
    (NaN and infinities never reach an integer conversion)."""
    number = value if isinstance(value, int | float) and not isinstance(value, bool) else None
    bound = "> 0" if positive else ">= 0"
    if (
        number is None
        or not math.isfinite(number)
        or number < 0
        or (positive and number == 0)
        or number * 1e9 > MAX_INT64
    ):
        raise LimitError(f"{what}: expected a finite number of seconds {bound}, got {value!r}")
    return float(number)


#: glibc's ``mallopt`` parameter for the number of malloc arenas.
_M_ARENA_MAX = -8


def fit_address_space() -> None:
    """Under an address-space limit (``ulimit -v``), make the allocators reserve little
    more than they use; call it before Arrow first allocates. Arrow then uses the
    system allocator (mimalloc reserves 1 GiB of address space at its first
    allocation) and glibc at most 2 malloc arenas (each thread DuckDB or a loader starts
    would reserve 64 MiB). Without such a limit nothing changes."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return
    import ctypes.util  # only under a limit: finding libc costs milliseconds

    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    name = ctypes.util.find_library("c")
    mallopt = getattr(ctypes.CDLL(name), "mallopt", None) if name else None
    if mallopt is not None:
        mallopt(_M_ARENA_MAX, 2)


def out_of_memory() -> str:
    """What to say when an input needs more memory than the process may use: the
    address-space limit (``ulimit -v``) when there is one."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return "out of memory: the input needs more memory than this machine gives"
    return (
        f"out of memory under the address-space limit of {soft >> 20} MiB (ulimit -v); "
        "raise it to read this input"
    )

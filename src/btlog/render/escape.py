"""The one escaping function for everything btlog prints to a terminal.

Names, values, file names and messages come from trees, recordings and command lines
that may be hostile: a newline in a node's name would print a line of its own
(``n&#10;FAKE: OK``), an escape sequence would recolour, retitle or clear the terminal,
a bidi override (U+202E) would reverse what follows. ``safe`` makes every character that
is not printable visible as its Python escape (``\\n``, ``\\x1b``, ``\\u202e``): control
characters (C0, DEL, C1), format characters (bidi marks, overrides and isolates,
zero-width characters), line and paragraph separators, unassigned, private-use and
surrogate code points, and spaces other than the ASCII space. Plain text is returned
unchanged, and ``safe(safe(x)) == safe(x)``.
"""

from __future__ import annotations

from typing import Any


def safe(text: Any) -> str:
    """``text`` (any object, as ``str()``) on one line with nothing a terminal would
    act on: each non-printable character replaced by its visible escape."""
    string = str(text)
    if string.isprintable():  # the common case, at C speed
        return string
    return "".join(
        char if char.isprintable() else char.encode("unicode_escape").decode("ascii")
        for char in string
    )

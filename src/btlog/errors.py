"""Errors shown to users: every message is one line (see docs/design.md, "Bad input")."""

from __future__ import annotations

#: The command line's exit codes: 0 ok, 1 a check failed, 2 bad input, 3 a bug in btlog.
EXIT_OK, EXIT_CHECK_FAILED, EXIT_BAD_INPUT, EXIT_BUG = 0, 1, 2, 3


def one_line(error: BaseException) -> str:
    """The error's message on one line (its type's name when the message is empty)."""
    text = str(error).strip() or type(error).__name__
    return " ".join(text.split())

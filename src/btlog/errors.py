"""Errors shown to users: every message is one line (see docs/design.md, "Bad input")."""

from __future__ import annotations


def one_line(error: BaseException) -> str:
    """The error's message on one line (its type's name when the message is empty)."""
    text = str(error).strip() or type(error).__name__
    return " ".join(text.split())

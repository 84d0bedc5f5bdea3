"""An output file never overwrites an input: ``-o`` naming the tree, an included tree,
the outcomes file or the recording being read is refused before anything is written."""

from __future__ import annotations

import os
from collections.abc import Iterable


def refuse_overwrite(
    output: str | os.PathLike, inputs: Iterable[str | os.PathLike | None], flag: str = "-o"
) -> None:
    """Raise ``ValueError`` (one line naming the flag and the file) when ``output`` is one
    of ``inputs``: the same path once resolved, or the same file under another name."""
    for given in inputs:
        if given is None:
            continue
        same = os.path.realpath(output) == os.path.realpath(given)
        if not same and os.path.exists(output) and os.path.exists(given):
            same = os.path.samefile(output, given)
        if same:
            raise ValueError(f"{flag} {os.fspath(output)}: that is an input ({os.fspath(given)})")

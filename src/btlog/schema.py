"""The JSON Schemas of the recording's messages, as bytes for the MCAP schema records.

The schemas are files, not code: ``schemas/*.schema.json`` at the top of the repository,
shipped inside the wheel as ``btlog/schemas`` (pyproject's ``force-include``). Installed,
they are package resources; run from a checkout (editable install or ``PYTHONPATH=src``)
the package folder has no ``schemas`` beside it, so the repository's folder is used.
"""

from __future__ import annotations

from functools import cache
from importlib.resources import files
from pathlib import Path

#: The repository's ``schemas/`` folder, beside ``src/``.
_REPOSITORY_SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"


@cache
def schema_text(name: str) -> bytes:
    """The bytes of schema file ``name`` (e.g. ``"events.schema.json"``).

    Raises FileNotFoundError naming both places looked in when it is in neither.
    """
    packaged = files("btlog") / "schemas" / name
    if packaged.is_file():
        return packaged.read_bytes()
    fallback = _REPOSITORY_SCHEMAS / name
    if fallback.is_file():
        return fallback.read_bytes()
    raise FileNotFoundError(
        f"schema {name!r} is neither in the btlog package nor in {_REPOSITORY_SCHEMAS}"
    )

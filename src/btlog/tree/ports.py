"""Typed port values: converting the strings of XML (and of the blackboard) to values.

BT.CPP converts a port's string to the port's declared type when the port is read. btlog
does the same for the types users declare: ``int``, ``float``, ``bool``, ``str``, ``json``
(a JSON document, with or without BT.CPP's ``json:`` prefix), ``status`` and ``any``
(kept as the XML string, as BT.CPP keeps an untyped literal). ``int`` is C++'s 32-bit
``int`` and ``unsigned`` its 32-bit ``unsigned int`` (the milliseconds of Delay, Timeout
and Sleep): a value out of range is refused as BT.CPP refuses it (``delay_msec="-1"``, a
26-digit ``num_cycles``).
"""

from __future__ import annotations

import json
from typing import Any

from btlog.status import Status

TRUE_WORDS = {"true", "True", "TRUE", "1"}
FALSE_WORDS = {"false", "False", "FALSE", "0"}
#: The integer port types and their ranges (C++'s ``int`` and ``unsigned int``).
INTEGER_RANGES = {"int": (-(2**31), 2**31 - 1), "unsigned": (0, 2**32 - 1)}


class PortValueError(ValueError):
    """A value that cannot be converted to the port's type."""


def convert(value: Any, type_name: str) -> Any:
    """Convert ``value`` (usually a string) to ``type_name``; raise PortValueError if bad."""
    if type_name in ("str", "any", "", None):
        return value
    if not isinstance(value, str):
        return _convert_value(value, type_name)
    text = value.strip()
    try:
        if type_name in INTEGER_RANGES:
            number = int(text, 0) if text.lower().startswith(("0x", "-0x")) else int(text)
            return _in_range(number, type_name)
        if type_name in ("float", "double"):
            return float(text)
        if type_name == "bool":
            if text in TRUE_WORDS:
                return True
            if text in FALSE_WORDS:
                return False
            raise ValueError
        if type_name == "json":
            return json.loads(text[5:] if text.startswith("json:") else text)
        if type_name == "status":
            return Status[text.upper()]
    except PortValueError:
        raise
    except (ValueError, KeyError):
        raise PortValueError(f"{value!r} is not a valid {type_name}") from None
    return value


def _in_range(number: int, type_name: str) -> int:
    low, high = INTEGER_RANGES[type_name]
    if not low <= number <= high:
        raise PortValueError(f"{number} is not a valid {type_name} ({low} to {high})")
    return number


def _convert_value(value: Any, type_name: str) -> Any:
    try:
        if type_name in INTEGER_RANGES and not isinstance(value, bool):
            if isinstance(value, float) and not value.is_integer():
                raise ValueError
            return _in_range(int(value), type_name)
        if type_name in ("float", "double") and not isinstance(value, bool):
            return float(value)
        if type_name == "bool":
            return bool(value)
        if type_name == "status":
            return Status(value)
    except PortValueError:
        raise
    except (TypeError, ValueError, OverflowError):
        raise PortValueError(f"{value!r} is not a valid {type_name}") from None
    return value


def split_queue(text: str) -> list[str]:
    """The elements of a queue written ``1;2;3`` (LoopInt and its kind), split as BT.CPP's
    ``splitString`` splits: a trailing ``;`` adds no element, ``a;;b`` has an empty one."""
    parts = text.split(";")
    if parts[-1] == "":
        parts.pop()
    return parts


def parse_literal(text: str) -> Any:
    """A SubTree literal as BT.CPP stores it: int, then float, else the string."""
    stripped = text.strip()
    try:
        return int(stripped)
    except ValueError:
        pass
    try:
        return float(stripped)
    except ValueError:
        return text

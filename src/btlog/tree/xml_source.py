"""Untrusted XML in: bounded reading, safe parsing, and the one error of the tree loader.

XML is read as BT.CPP's tinyxml2 reads it (``btlog.tree.xml_syntax``): no entity but XML's
five is expanded, a DTD is refused, nothing is fetched; files are bounded in size (checked
before reading), elements in nesting and attributes; every error is a ``TreeError`` naming
the file, the line and what is wrong. The bounds are in ``btlog.limits``.
"""

from __future__ import annotations

import os

from btlog import limits
from btlog.tree.xml_syntax import XmlElement, XmlLimitError, XmlSyntaxError, parse


class TreeError(ValueError):
    """A tree that cannot be loaded; ``str()`` is one line naming file, line and problem."""

    def __init__(self, message: str, file: str = "", line: int | None = None) -> None:
        self.file, self.line, self.problem = file, line, message
        where = file + (f":{line}" if line else "") if file else ""
        super().__init__(f"{where}: {message}" if where else message)


def parse_xml(data: bytes, file: str) -> XmlElement:
    """Parse untrusted XML bytes as BT.CPP does (tinyxml2's syntax, ``btlog.tree.xml_syntax``)
    and safely: a DOCTYPE is refused, no entity but XML's five is expanded, and a file over
    the size limit, nesting too deep or an element with too many attributes is refused."""
    limit = limits.current().max_file_bytes
    if len(data) > limit:
        raise TreeError(f"file is larger than {limit} bytes (--max-file-size)", file)
    try:
        return parse(data, limits.MAX_XML_NESTING, limits.MAX_ATTRIBUTES)
    except XmlLimitError as error:
        raise TreeError(error.problem, file, error.line) from None
    except XmlSyntaxError as error:
        raise TreeError(f"malformed XML: {error.problem}", file, error.line) from None


def read_xml_file(source: str | os.PathLike) -> bytes:
    """The bytes of an XML file, bounded in size; an unreadable file is a ``TreeError``."""
    try:
        return limits.read_bounded(source)
    except OSError as error:
        raise TreeError(f"cannot read the file: {error.strerror}", str(source)) from None
    except limits.LimitError as error:
        raise TreeError(str(error), str(source)) from None

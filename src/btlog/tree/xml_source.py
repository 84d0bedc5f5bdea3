"""Untrusted XML in: bounded reading, safe parsing, and the one error of the tree loader.

Entities are not resolved, DTDs and network access are refused, files are bounded in size
(checked before reading) and elements in attributes; every error is a ``TreeError`` naming
the file, the line and what is wrong. The bounds are in ``btlog.limits``.
"""

from __future__ import annotations

import os

from lxml import etree

from btlog import limits


class TreeError(ValueError):
    """A tree that cannot be loaded; ``str()`` is one line naming file, line and problem."""

    def __init__(self, message: str, file: str = "", line: int | None = None) -> None:
        self.file, self.line, self.problem = file, line, message
        where = file + (f":{line}" if line else "") if file else ""
        super().__init__(f"{where}: {message}" if where else message)


def _parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_comments=True,
        remove_pis=True,
    )


def parse_xml(data: bytes, file: str) -> etree._Element:
    """Parse untrusted XML bytes safely; a DTD or entity declaration is refused, and so
    is a file over the size limit or an element with too many attributes."""
    limit = limits.current().max_file_bytes
    if len(data) > limit:
        raise TreeError(f"file is larger than {limit} bytes (--max-file-size)", file)
    try:
        document = etree.fromstring(data, _parser()).getroottree()
    except etree.XMLSyntaxError as error:
        line = error.lineno if error.lineno else None
        message = error.msg if hasattr(error, "msg") and error.msg else str(error)
        raise TreeError(f"malformed XML: {message}", file, line) from None
    if document.docinfo.doctype or document.docinfo.internalDTD is not None:
        raise TreeError("DOCTYPE declarations are not allowed", file, 1)
    root = document.getroot()
    for element in root.iter():
        # lxml reads an element's attribute values in quadratic time: bound their count.
        if len(element.attrib) > limits.MAX_ATTRIBUTES:
            raise TreeError(
                f"an element has more than {limits.MAX_ATTRIBUTES} attributes",
                file,
                element.sourceline,
            )
    return root


def read_xml_file(source: str | os.PathLike) -> bytes:
    """The bytes of an XML file, bounded in size; an unreadable file is a ``TreeError``."""
    try:
        return limits.read_bounded(source)
    except OSError as error:
        raise TreeError(f"cannot read the file: {error.strerror}", str(source)) from None
    except limits.LimitError as error:
        raise TreeError(str(error), str(source)) from None

"""XML as BehaviorTree.CPP reads it: tinyxml2's syntax, with no DTD and no entities.

BT.CPP parses trees with tinyxml2, which is more lenient than XML 1.0, and real trees rely
on it: a script ``if="A>-B && color != BLUE"`` with raw ``&``, ``<`` and ``>`` in an
attribute value, a ``<!------->`` comment (``--`` inside a comment), an ``&`` that starts
no entity (kept as it is), an XML declaration after blank lines, attributes with no space
between them (``a="1"b="2"``), ``< Sequence>``, several top-level elements (the first one
is the document's root) and anything after a stray top-level closing tag (ignored).

This reader follows tinyxml2's rules (``XMLDocument::Parse`` in its default mode, as BT.CPP
uses it) and builds a small element tree. It is not a general XML parser, and that is its
safety: only the five predefined entities and numeric character references are replaced,
a ``<!DOCTYPE`` is refused (no DTD is read, no entity declared or expanded, nothing is
fetched), nesting and attributes are bounded, and it loops instead of recursing. Line
numbers count ``\\n`` as tinyxml2 does; an element's line is that of its ``<``. Attribute
values and text keep their whitespace (tinyxml2's PRESERVE_WHITESPACE); line ends are
normalised to ``\\n``. tinyxml2 reads C strings: a NUL byte ends the document and ``&#0;``
ends a value. Bytes that are not UTF-8 are read as U+FFFD.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import overload

#: tinyxml2's name characters: ASCII letters, '_' and ':' (then digits, '.', '-'), and any
#: non-ASCII character.
_NAME = r"[A-Za-z_:\x80-\U0010ffff][A-Za-z0-9_:.\-\x80-\U0010ffff]*"
_SPACE = "[ \t\n\r\v\f]"  # C's isspace
_C_SPACES = " \t\n\r\v\f"
_QUOTED = "(?:\"([^\"]*)\"|'([^']*)')"
_ATTRIBUTE = re.compile(rf"({_NAME}){_SPACE}*={_SPACE}*{_QUOTED}")
_ATTRIBUTE_AT = re.compile(rf"{_SPACE}*{_NAME}{_SPACE}*={_SPACE}*{_QUOTED}")
_START_TAG = re.compile(
    rf"<{_SPACE}*({_NAME})((?:{_SPACE}*{_NAME}{_SPACE}*={_SPACE}*(?:\"[^\"]*\"|'[^']*'))*)"
    rf"{_SPACE}*(/?)>"
)
_END_TAG = re.compile(rf"<{_SPACE}*/({_NAME}){_SPACE}*>")
_TAG = re.compile(rf"<{_SPACE}*(/?)({_NAME})")
_SPACES = re.compile(rf"{_SPACE}*")
_REFERENCE = re.compile(r"&(?:#([0-9]*)|#x([0-9a-fA-F]*)|(quot|amp|apos|lt|gt));")
_ENTITIES = {"quot": '"', "amp": "&", "apos": "'", "lt": "<", "gt": ">"}
_DOCTYPE = re.compile(r"<!(?:DOCTYPE|ENTITY)", re.IGNORECASE)


class XmlSyntaxError(ValueError):
    """XML tinyxml2 would refuse too; ``line`` is where (1-based), ``problem`` what."""

    def __init__(self, problem: str, line: int) -> None:
        super().__init__(problem)
        self.problem, self.line = problem, line


class XmlLimitError(XmlSyntaxError):
    """XML that crosses one of btlog's bounds (nesting, attributes)."""


class XmlElement:
    """An element: tag, attributes in document order, source line, leading text, children.

    ``text`` is the element's first child when that is text (tinyxml2's ``GetText``)."""

    __slots__ = ("_started", "attrib", "children", "sourceline", "tag", "text")

    def __init__(self, tag: str, attrib: dict[str, str], sourceline: int) -> None:
        self.tag, self.attrib, self.sourceline = tag, attrib, sourceline
        self.text: str | None = None
        self.children: list[XmlElement] = []
        self._started = False  # a first child (text, comment or element) was read

    @overload
    def get(self, name: str) -> str | None: ...
    @overload
    def get(self, name: str, default: str) -> str: ...
    def get(self, name: str, default: str | None = None) -> str | None:
        """The value of attribute ``name``, or ``default``."""
        return self.attrib.get(name, default)

    def __iter__(self) -> Iterator[XmlElement]:
        return iter(self.children)

    def __len__(self) -> int:
        return len(self.children)

    def iter(self) -> Iterator[XmlElement]:
        """This element and every element below it, in document order."""
        stack = [self]
        while stack:
            element = stack.pop()
            yield element
            stack.extend(reversed(element.children))

    def __repr__(self) -> str:
        return f"<XmlElement {self.tag} line {self.sourceline}>"


def _character(match: re.Match[str]) -> str:
    decimal, hexadecimal, name = match.groups()
    if name is not None:
        return _ENTITIES[name]
    digits = decimal if decimal is not None else hexadecimal
    code = int(digits, 10 if decimal is not None else 16) if digits else 0
    if code <= 0x10FFFF and not 0xD800 <= code <= 0xDFFF:
        return chr(code)  # "&#;" is 0, as in tinyxml2
    return match.group(0)  # tinyxml2 keeps what it cannot convert


def _lines(raw: str) -> str:
    """Line ends as tinyxml2 normalises them: CR LF, LF CR and CR alone are LF."""
    if "\r" in raw:
        raw = raw.replace("\r\n", "\n").replace("\n\r", "\n").replace("\r", "\n")
    return raw


def _value(raw: str) -> str:
    """Attribute value or text as tinyxml2 gives it: line ends normalised, the predefined
    entities and character references replaced, any other ``&`` kept."""
    raw = _lines(raw)
    if "&" in raw:
        raw = _REFERENCE.sub(_character, raw)
        if "\0" in raw:  # "&#0;": tinyxml2's value is a C string, which ends there
            raw = raw[: raw.index("\0")]
    return raw


class _Reader:
    """One pass over a document, a tag at a time (a regular expression reads each start
    tag whole; on a malformed tag, a slower pass finds what is wrong)."""

    def __init__(self, text: str, max_depth: int, max_attributes: int) -> None:
        self.text = text
        self.max_depth = max_depth
        self.max_attributes = max_attributes
        self._counted, self._line = 0, 1

    def line_at(self, position: int) -> int:
        """The line of ``position`` (positions asked for only grow, but for errors)."""
        if position < self._counted:
            return self.text.count("\n", 0, position) + 1
        self._line += self.text.count("\n", self._counted, position)
        self._counted = position
        return self._line

    def fail(self, problem: str, position: int) -> XmlSyntaxError:
        return XmlSyntaxError(problem, self.line_at(position))

    def until(self, end: str, start: int, what: str) -> int:
        """The position after the ``end`` that closes what starts at ``start``."""
        stop = self.text.find(end, start)
        if stop < 0:
            raise self.fail(f"{what} is never closed ({end!r} missing)", start)
        return stop + len(end)

    def read(self) -> XmlElement:
        text = self.text
        roots: list[XmlElement] = []
        open_elements: list[XmlElement] = []
        only_declarations = True  # nothing but <?…?> so far, at document level
        position = 0
        while True:
            parent = open_elements[-1] if open_elements else None
            start = text.find("<", position)
            if start != position:
                raw = text[position:] if start < 0 else text[position:start]
                if raw.strip(_C_SPACES):
                    if start < 0:
                        skipped = len(raw) - len(raw.lstrip(_C_SPACES))
                        raise self.fail("text after the last tag", position + skipped)
                    only_declarations = False
                    self._text(parent, _value(raw.lstrip(_C_SPACES)))
            if start < 0:
                break
            following = text[start + 1 : start + 2]
            if following == "?":
                if parent is not None or not only_declarations:
                    raise self.fail("a declaration <?…?> is allowed only at the start", start)
                position = self.until("?>", start, "the declaration")
                continue
            only_declarations = False
            if following == "!":
                if text.startswith("<!--", start):
                    position = self.until("-->", start, "the comment")
                    self._not_text(parent)
                elif text.startswith("<![CDATA[", start):
                    position = self.until("]]>", start, "the CDATA section")
                    self._text(parent, _lines(text[start + 9 : position - 3]))
                elif _DOCTYPE.match(text, start):
                    raise self.fail(
                        "DOCTYPE declarations are not allowed (btlog reads no DTD and "
                        "expands no entity)",
                        start,
                    )
                else:
                    position = self.until(">", start, "the <!…> declaration")
                    self._not_text(parent)
                continue
            tag = _START_TAG.match(text, start)
            if tag is None:
                closing = _END_TAG.match(text, start)
                if closing is None:
                    raise self._diagnose(start)
                position = closing.end()
                if not open_elements:
                    break  # tinyxml2 stops at a closing tag at document level
                element = open_elements.pop()
                if element.tag != closing.group(1):
                    raise self.fail(
                        f"</{closing.group(1)}> closes <{element.tag}> opened at line "
                        f"{element.sourceline}",
                        start,
                    )
                continue
            position = tag.end()
            name, block, empty = tag.groups()
            attributes = self._attributes(name, block, tag.start(2)) if block else {}
            element = XmlElement(name, attributes, self.line_at(start))
            self._not_text(parent)
            (parent.children if parent is not None else roots).append(element)
            if empty:
                continue
            if len(open_elements) >= self.max_depth:
                raise XmlLimitError(
                    f"elements nested more than {self.max_depth} deep", element.sourceline
                )
            open_elements.append(element)
        if open_elements:
            unclosed = open_elements[-1]
            raise XmlSyntaxError(f"<{unclosed.tag}> is never closed", unclosed.sourceline)
        if not roots:
            raise XmlSyntaxError("the document has no element", 1)
        return roots[0]

    def _attributes(self, tag: str, block: str, offset: int) -> dict[str, str]:
        """The attributes of a start tag (``block``, found at ``offset``: the text between
        the tag's name and its end)."""
        pairs = _ATTRIBUTE.findall(block)
        if len(pairs) > self.max_attributes:
            raise XmlLimitError(
                f"an element has more than {self.max_attributes} attributes", self.line_at(offset)
            )
        attributes: dict[str, str] = {}
        for name, double, single in pairs:
            value = double or single
            if "&" in value or "\r" in value:
                value = _value(value)
            attributes[name] = value
        if len(attributes) < len(pairs):
            seen: set[str] = set()
            for match in _ATTRIBUTE.finditer(block):
                if match.group(1) in seen:
                    where = offset + match.start()
                    raise self.fail(f"<{tag}>: attribute {match.group(1)!r} is given twice", where)
                seen.add(match.group(1))
        return attributes

    def _diagnose(self, start: int) -> XmlSyntaxError:
        """The error of the malformed tag at ``start``, at the line where it goes wrong."""
        text = self.text
        tag = _TAG.match(text, start)
        if tag is None:
            return self.fail("'<' is not followed by an element name", start)
        closing, name = tag.groups()
        if closing:
            return self.fail(f"</{name}: malformed closing tag", start)
        position = tag.end()
        while True:  # attribute by attribute, to the first that is wrong
            match = _ATTRIBUTE_AT.match(text, position)
            if match is None:
                skipped = _SPACES.match(text, position).end()  # type: ignore[union-attr]
                return self.fail(f"<{name}>: malformed attribute or tag end", skipped)
            position = match.end()

    @staticmethod
    def _text(parent: XmlElement | None, value: str) -> None:
        if parent is not None and not parent._started:
            parent.text, parent._started = value, True

    @staticmethod
    def _not_text(parent: XmlElement | None) -> None:
        """A comment or element child: text after it is not the element's first child."""
        if parent is not None:
            parent._started = True


def parse(data: bytes | str, max_depth: int, max_attributes: int) -> XmlElement:
    """The root element of a document, read as tinyxml2 reads it (see the module's notes);
    raises ``XmlSyntaxError`` (``XmlLimitError`` for a bound crossed)."""
    text = data if isinstance(data, str) else data.decode("utf-8", errors="replace")
    text = text.removeprefix("\ufeff")
    nul = text.find("\0")
    if nul >= 0:
        text = text[:nul]
    return _Reader(text, max_depth, max_attributes).read()

"""User documents (outcomes and expectations files): read YAML, validate by JSON Schema.

A document is read once as YAML (JSON is accepted for ``.json`` files), then checked
against its schema in ``schemas/`` (see docs/design.md, "Input files"). The first problem
becomes one line naming the file, the line, the offending key and what was expected::

    outcomes.yaml:3: nodes['look at chuck']: status must be SUCCESS or FAILURE, got 'MAYBE'

Only what a schema cannot say (a question that parses, a node key that exists) is
checked by the code that uses the document.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Iterator
from functools import cache
from typing import Any

import jsonschema
import yaml
from jsonschema.exceptions import ValidationError, relevance

from btlog import limits
from btlog.schema import schema_text

#: A position in a document: mapping keys and list indexes from the top.
KeyPath = tuple[str | int, ...]


class DocumentError(ValueError):
    """A document that cannot be used; one line naming the file, line and key."""


def where(path: Iterable[str | int]) -> str:
    """A key path as text: ``answers[0]``, ``nodes['look at chuck'][1]``."""
    text = ""
    for part in path:
        if isinstance(part, int):
            text += f"[{part}]"
        elif not text:
            text = str(part)
        else:
            text += f"[{part!r}]"
    return text


def _lines(node: yaml.Node, path: KeyPath, found: dict[KeyPath, int]) -> None:
    """Record the 1-based line where each value starts."""
    found[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            if isinstance(key, yaml.ScalarNode):
                _lines(value, (*path, key.value), found)
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            _lines(item, (*path, index), found)


def _check_expanded(root: yaml.Node, name: str) -> None:
    """Refuse a document whose aliases expand it past ``limits.MAX_DOCUMENT_VALUES``
    values (a "billion laughs" of a few hundred bytes), or refer to themselves; counted
    once per node, without expanding anything."""
    cap = limits.MAX_DOCUMENT_VALUES
    sizes: dict[int, int] = {}
    path = {id(root)}
    stack = [(root, iter(_children(root)))]
    while stack:
        node, pending = stack[-1]
        child = next((c for c in pending if id(c) not in sizes), None)
        if child is not None:
            if id(child) in path:
                line = child.start_mark.line + 1
                raise DocumentError(f"{name}:{line}: a YAML alias refers to itself")
            path.add(id(child))
            stack.append((child, iter(_children(child))))
            continue
        stack.pop()
        path.discard(id(node))
        sizes[id(node)] = min(cap + 1, 1 + sum(sizes[id(c)] for c in _children(node)))
    if sizes[id(root)] > cap:
        raise DocumentError(f"{name}: more than {cap} values once its YAML aliases are expanded")


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def read(path: str | os.PathLike[str], what: str) -> tuple[Any, dict[KeyPath, int]]:
    """The data of a YAML (or ``.json``) file and the line of each key path in it.

    ``what`` names the document in messages ("outcomes file"). Raises ``DocumentError``.
    """
    name = os.fspath(path)
    try:
        text = limits.read_bounded(name).decode("utf-8")
    except FileNotFoundError:
        raise DocumentError(f"{name}: no such {what}") from None
    except (OSError, UnicodeDecodeError, limits.LimitError) as error:
        raise DocumentError(f"{name}: cannot read the {what}: {error}") from None
    if name.endswith(".json"):
        try:
            return json.loads(text), {}
        except json.JSONDecodeError as error:
            raise DocumentError(f"{name}:{error.lineno}: not valid JSON: {error.msg}") from None
    lines: dict[KeyPath, int] = {}
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        if node is not None:
            _check_expanded(node, name)
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise DocumentError(f"{name}{line}: not valid YAML: {problem}") from None
    except RecursionError:
        raise DocumentError(f"{name}: not valid YAML: nested too deeply") from None
    if node is not None:
        _lines(node, (), lines)
    return data, lines


@cache
def _validator(schema_name: str) -> jsonschema.protocols.Validator:
    schema = json.loads(schema_text(f"{schema_name}.schema.json"))
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema)


def _fits(errors: list[ValidationError]) -> bool:
    """False when a branch of ``anyOf`` fails already on the type of the value."""
    for error in errors:
        if error.relative_path:
            continue
        if error.validator == "type":
            return False
        nested = error.validator in ("anyOf", "oneOf") and error.context
        if nested and not any(_fits(subs) for subs in _branches(error).values()):
            return False
    return True


def _branches(error: ValidationError) -> dict[Any, list[ValidationError]]:
    branches: dict[Any, list[ValidationError]] = {}
    for sub in error.context or []:
        branches.setdefault(sub.schema_path[0], []).append(sub)
    return branches


def _narrowest(error: ValidationError) -> ValidationError:
    """Inside ``anyOf``, the error of the one branch whose type fits the value, if one."""
    while error.validator in ("anyOf", "oneOf") and error.context:
        fitting = [subs for subs in _branches(error).values() if _fits(subs)]
        if len(fitting) != 1:
            break
        error = max(fitting[0], key=relevance)
    return error


def _names(value: Any) -> list[str]:
    """The property names of a ``required`` keyword."""
    return [str(name) for name in value] if isinstance(value, list) else []


def _message(error: ValidationError) -> tuple[KeyPath, str]:
    """The key path an error points at and a one-line message for it."""
    path: KeyPath = tuple(error.absolute_path)
    schema = error.schema if isinstance(error.schema, dict) else {}
    value = error.instance
    if error.validator == "additionalProperties" and isinstance(value, dict):
        allowed = list(schema.get("properties", {}))
        unknown = next(k for k in value if k not in allowed)
        expected = f" (expected {', '.join(allowed)})" if allowed else ""
        return (*path, unknown), f"unknown key {str(unknown)!r}{expected}"
    if error.validator == "required" and isinstance(value, dict):
        missing = next(k for k in _names(error.validator_value) if k not in value)
        return path, f"{missing!r} missing"
    if error.validator == "minItems" and value == []:
        return path, "must not be an empty list"
    description = schema.get("description")
    if description is None:
        return path, error.message
    name = schema.get("title")
    if not name or (path and path[-1] == name):
        return path, f"must be {description}, got {value!r}"
    return path, f"{name} must be {description}, got {value!r}"


def errors(data: Any, schema_name: str) -> Iterator[ValidationError]:
    """Every violation of schema ``schemas/<schema_name>.schema.json`` by ``data``."""
    return _validator(schema_name).iter_errors(data)


def complaint(
    found: Iterable[ValidationError], source: str, lines: dict[KeyPath, int] | None = None
) -> str | None:
    """The one-line message for the most relevant error of ``found`` (None when empty)."""
    candidates = list(found)
    if not candidates:
        return None
    path, message = _message(_narrowest(max(candidates, key=relevance)))
    return _located(source, lines, path, message)


def _located(source: str, lines: dict[KeyPath, int] | None, path: KeyPath, message: str) -> str:
    """``file:line: key: message`` for the value at ``path``."""
    line_of = lines or {}
    line = next((line_of[path[:n]] for n in range(len(path), -1, -1) if path[:n] in line_of), 0)
    key = where(path)
    head = f"{source}:{line}" if line else source
    return f"{head}: {key}: {message}" if key else f"{head}: {message}"


def validate(
    data: Any, schema_name: str, source: str, lines: dict[KeyPath, int] | None = None
) -> None:
    """Raise ``DocumentError`` (file:line: key: message) when ``data`` breaks the schema
    or holds a number that is not finite (YAML's ``.nan``, ``.inf``: JSON Schema's bounds
    do not catch NaN)."""
    for path, value in _numbers(data):
        if not math.isfinite(value):
            raise DocumentError(
                _located(source, lines, path, f"must be a finite number, got {value!r}")
            )
    message = complaint(errors(data, schema_name), source, lines)
    if message is not None:
        raise DocumentError(message)


def _numbers(data: Any) -> Iterator[tuple[KeyPath, float]]:
    """Every float in ``data`` with its key path (iteratively: documents may be deep)."""
    stack: list[tuple[KeyPath, Any]] = [((), data)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, float):
            yield path, value
        elif isinstance(value, dict):
            stack.extend(((*path, k), v) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend(((*path, i), v) for i, v in enumerate(value))


def load(path: str | os.PathLike[str], schema_name: str, what: str) -> Any:
    """Read a document and validate it against its schema (see ``read``, ``validate``)."""
    data, lines = read(path, what)
    validate(data, schema_name, os.fspath(path), lines)
    return data

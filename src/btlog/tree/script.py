"""BT.CPP's scripting language: the code of Script, ScriptCondition, Precondition and of
the ``_skipIf``/``_onSuccess``… attributes.

Supported: statements separated by ``;``; assignment ``:=`` (creates the entry), ``=``
(the entry must exist, or be one a port names: BT.CPP creates those with the tree),
``+=``, ``-=``, ``*=``, ``/=``; arithmetic ``+ - * /``, string concatenation ``..`` (and
``+`` of two strings); comparisons ``== != < <= > >=``; logic ``&& || !`` (also ``and``,
``or``, ``not``); bitwise ``& | ^ ~``; the ternary ``c ? a : b``; numbers (integers,
decimals, hex), strings in single or double quotes, ``true``/``false``, and blackboard
keys (``@key`` for the root blackboard). Scripts are compiled once into closures.

A script runs in an environment with ``get(key)``, ``set(key, value)``, ``exists(key)``
and ``declared(key)``.

Scripts come from untrusted XML, so they are bounded (``btlog.limits``): the code's
length and nesting when compiled, and while running the length of a string built with
``..`` and integers to BT.CPP's 64 bits; crossing a bound is a ``ScriptError``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from functools import lru_cache
from typing import Any, Protocol

from btlog import limits


class ScriptError(ValueError):
    """A script that does not parse, or fails while running."""


class MissingVariable(ScriptError):
    """A script read a variable nothing has written (the host program's entry, or one of
    its scripting enums, in BT.CPP)."""


class Environment(Protocol):
    """What a script reads and writes: the node's blackboard."""

    def get(self, key: str) -> Any: ...
    def set(self, key: str, value: Any) -> None: ...
    def exists(self, key: str) -> bool: ...
    def declared(self, key: str) -> bool: ...


_TOKEN = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<num>0[xX][0-9a-fA-F]+|\d+\.\d*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?|\d+(?:[eE][-+]?\d+)?)
  | (?P<str>'[^']*'|"[^"]*")
  | (?P<op>:=|\+=|-=|\*=|/=|==|!=|<=|>=|&&|\|\||\.\.|[-+*/<>=!?:;()&|^~])
  | (?P<id>@?[A-Za-z_][A-Za-z0-9_]*)
""",
    re.VERBOSE,
)

_WORD_OPS = {"and": "&&", "or": "||", "not": "!"}
_INT64 = 2**63
Expr = Callable[[Environment], Any]


def _tokenize(code: str) -> list[tuple[str, str]]:
    tokens: list[tuple[str, str]] = []
    pos = 0
    while pos < len(code):
        match = _TOKEN.match(code, pos)
        if match is None:
            raise ScriptError(f"unexpected character {code[pos]!r} at column {pos + 1}")
        pos = match.end()
        kind = match.lastgroup or ""
        text = match.group()
        if kind == "ws":
            continue
        if kind == "id" and text in _WORD_OPS:
            kind, text = "op", _WORD_OPS[text]
        tokens.append((kind, text))
    tokens.append(("end", ""))
    return tokens


def _number(text: str) -> int | float:
    if text.lower().startswith("0x"):
        return int(text, 16)
    if any(c in text for c in ".eE"):
        return float(text)
    return int(text)


def _to_number(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, str):
        try:
            return _number(value.strip())
        except ValueError:
            raise ScriptError(f"{value!r} is not a number") from None
    return value


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, str) != isinstance(b, str):
        try:
            return _to_number(a) == _to_number(b)
        except ScriptError:
            return False
    return a == b


def _compare(op: str) -> Callable[[Any, Any], bool]:
    def compare(a: Any, b: Any) -> bool:
        if not (isinstance(a, str) and isinstance(b, str)):
            a, b = _to_number(a), _to_number(b)
        if op == "<":
            return a < b
        if op == "<=":
            return a <= b
        if op == ">":
            return a > b
        return a >= b

    return compare


def _divide(a: Any, b: Any) -> Any:
    a, b = _to_number(a), _to_number(b)
    if b == 0:
        # BT.CPP divides as doubles: inf, -inf or nan.
        return math.copysign(math.inf, a) if a else math.nan
    if isinstance(a, int) and isinstance(b, int) and a % b == 0:
        return a // b
    return a / b


def _bounded(value: Any) -> Any:
    """An arithmetic result, refused when an integer leaves BT.CPP's 64 bits (Python's
    integers would otherwise grow without bound)."""
    if isinstance(value, int) and not -_INT64 <= value < _INT64:
        raise ScriptError("integer overflow (scripts compute in 64 bits)")
    return value


def _add(a: Any, b: Any) -> Any:
    if isinstance(a, str) and isinstance(b, str):
        return _concatenate(a, b)  # BT.CPP joins two strings with + too
    return _bounded(_to_number(a) + _to_number(b))


def _concatenate(a: Any, b: Any) -> str:
    left, right = _text(a), _text(b)
    if len(left) + len(right) > limits.MAX_SCRIPT_STRING:
        raise ScriptError(f"a string longer than {limits.MAX_SCRIPT_STRING} characters")
    return left + right


_BINARY: dict[str, Callable[[Any, Any], Any]] = {
    "+": _add,
    "-": lambda a, b: _bounded(_to_number(a) - _to_number(b)),
    "*": lambda a, b: _bounded(_to_number(a) * _to_number(b)),
    "/": _divide,
    "..": _concatenate,
    "==": _equal,
    "!=": lambda a, b: not _equal(a, b),
    "<": _compare("<"),
    "<=": _compare("<="),
    ">": _compare(">"),
    ">=": _compare(">="),
    "&": lambda a, b: int(_to_number(a)) & int(_to_number(b)),
    "|": lambda a, b: int(_to_number(a)) | int(_to_number(b)),
    "^": lambda a, b: int(_to_number(a)) ^ int(_to_number(b)),
}
# BT.CPP's order, loosest first: logic, comparisons, then bitwise binding tighter than
# comparisons (unlike C), then arithmetic.
_PRECEDENCE = [
    ("||",),
    ("&&",),
    ("==", "!=", "<", "<=", ">", ">="),
    ("|", "^"),
    ("&",),
    ("+", "-", ".."),
    ("*", "/"),
]
_COMPARISONS = 2


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def truthy(value: Any) -> bool:
    """BT.CPP's cast to bool: numbers are true when non-zero, strings by their words."""
    if isinstance(value, str):
        lowered = value.strip().lower()
        if lowered in ("true", "false"):
            return lowered == "true"
        return bool(_to_number(value))
    return bool(value)


class _Parser:
    def __init__(self, code: str) -> None:
        if len(code) > limits.MAX_SCRIPT_CODE:
            raise ScriptError(f"the script is longer than {limits.MAX_SCRIPT_CODE} characters")
        self.tokens = _tokenize(code)
        self.pos = 0
        self.nesting = 0

    def nest(self, step: int) -> None:
        """Enter (+1) or leave (-1) a parenthesis, unary operator or ternary branch."""
        self.nesting += step
        if self.nesting > limits.MAX_SCRIPT_NESTING:
            raise ScriptError(f"nested more than {limits.MAX_SCRIPT_NESTING} levels deep")

    def peek(self) -> tuple[str, str]:
        return self.tokens[self.pos]

    def take(self, text: str | None = None) -> tuple[str, str]:
        token = self.tokens[self.pos]
        if text is not None and token[1] != text:
            found = token[1] or "the end"
            raise ScriptError(f"expected {text!r}, found {found!r}")
        self.pos += 1
        return token

    def program(self) -> list[Expr]:
        statements = []
        while self.peek()[0] != "end":
            if self.peek()[1] == ";":
                self.take()
                continue
            statements.append(self.statement())
            if self.peek()[0] != "end":
                self.take(";")
        if not statements:
            raise ScriptError("empty script")
        return statements

    def statement(self) -> Expr:
        kind, text = self.peek()
        following = self.tokens[self.pos + 1][1]
        if kind == "id" and following in (":=", "=", "+=", "-=", "*=", "/="):
            self.take()
            op = self.take()[1]
            value = self.ternary()
            return _assignment(text, op, value)
        return self.ternary()

    def ternary(self) -> Expr:
        condition = self.binary(0)
        if self.peek()[1] != "?":
            return condition
        self.take("?")
        self.nest(1)
        then = self.ternary()
        self.take(":")
        otherwise = self.ternary()
        self.nest(-1)
        return lambda env: then(env) if truthy(condition(env)) else otherwise(env)

    def binary(self, level: int) -> Expr:
        if level == len(_PRECEDENCE):
            return self.unary()
        if level == _COMPARISONS:
            return self.comparison()
        left = self.binary(level + 1)
        while self.peek()[0] == "op" and self.peek()[1] in _PRECEDENCE[level]:
            op = self.take()[1]
            right = self.binary(level + 1)
            left = _logic(op, left, right) if op in ("&&", "||") else _binary(op, left, right)
        return left

    def comparison(self) -> Expr:
        """Comparisons chain as in BT.CPP: ``a < b < c`` means ``a < b && b < c``."""
        operands = [self.binary(_COMPARISONS + 1)]
        ops = []
        while self.peek()[0] == "op" and self.peek()[1] in _PRECEDENCE[_COMPARISONS]:
            ops.append(self.take()[1])
            operands.append(self.binary(_COMPARISONS + 1))
        if not ops:
            return operands[0]
        if len(ops) == 1:
            return _binary(ops[0], operands[0], operands[1])
        functions = [_BINARY[op] for op in ops]

        def chain(env: Environment) -> bool:
            values = [operand(env) for operand in operands]
            return all(f(values[i], values[i + 1]) for i, f in enumerate(functions))

        return chain

    def unary(self) -> Expr:
        kind, text = self.peek()
        if kind == "op" and text in ("-", "!", "~", "+"):
            self.take()
            self.nest(1)
            operand = self.unary()
            self.nest(-1)
            if text == "-":
                return lambda env: _bounded(-_to_number(operand(env)))
            if text == "!":
                return lambda env: not truthy(operand(env))
            if text == "~":
                return lambda env: ~int(_to_number(operand(env)))
            return operand
        return self.primary()

    def primary(self) -> Expr:
        kind, text = self.take()
        if kind == "num":
            value = _number(text)
            return lambda env: value
        if kind == "str":
            literal = text[1:-1]
            return lambda env: literal
        if kind == "id":
            if text in ("true", "false"):
                flag = text == "true"
                return lambda env: flag
            return lambda env: _read(env, text)
        if text == "(":
            self.nest(1)
            inner = self.ternary()
            self.take(")")
            self.nest(-1)
            return inner
        raise ScriptError(f"unexpected {text or 'end of script'!r}")


def _read(env: Environment, key: str) -> Any:
    if not env.exists(key):
        raise MissingVariable(f"variable {key!r} is not on the blackboard")
    return env.get(key)


def _binary(op: str, left: Expr, right: Expr) -> Expr:
    function = _BINARY[op]
    return lambda env: function(left(env), right(env))


def _logic(op: str, left: Expr, right: Expr) -> Expr:
    if op == "&&":
        return lambda env: truthy(left(env)) and truthy(right(env))
    return lambda env: truthy(left(env)) or truthy(right(env))


def _assignment(key: str, op: str, value: Expr) -> Expr:
    def assign(env: Environment) -> Any:
        new = value(env)
        if op == ":=":
            env.set(key, new)
            return new
        if not env.exists(key) and not env.declared(key):
            raise ScriptError(f"variable {key!r} does not exist; use := to create it")
        if op != "=":
            new = _BINARY[op[0]](env.get(key), new)
        env.set(key, new)
        return new

    return assign


@lru_cache(maxsize=4096)
def compile_script(code: str) -> Callable[[Environment], Any]:
    """Compile a script; the result runs it in an environment and returns the last value."""
    statements = _Parser(code).program()
    if len(statements) == 1:
        return statements[0]

    def run(env: Environment) -> Any:
        result = None
        for statement in statements:
            result = statement(env)
        return result

    return run

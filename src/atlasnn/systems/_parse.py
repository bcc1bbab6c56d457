"""The whitelist's names and limits, and the parsing of an expression's text with its checks.

Part of :mod:`atlasnn.systems._expression` (which describes the whitelist and re-exports the public
names): the functions and constants an expression may use (:data:`FUNCTIONS`,
:data:`CONSTANTS`), the size limits (:data:`MAX_EXPRESSION_LENGTH`, :data:`MAX_OPERATIONS`,
:data:`MAX_DEPTH`), the checks of variable and parameter names and values, the mapping of
parser positions to the columns named in error messages, and :func:`_parse`, which turns the
text into an :class:`ast.Expression` (never evaluating it) and refuses one that is empty, too
long, not valid syntax or has too many operations. :mod:`atlasnn.systems._compile` then checks
the tree node by node and builds the JAX function.
"""

from __future__ import annotations

import ast
import keyword
import math
import numbers
import re
import unicodedata
import warnings
from typing import Any, Callable, Mapping, Sequence

import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ExpressionError

__all__ = ["FUNCTIONS", "CONSTANTS", "MAX_EXPRESSION_LENGTH", "MAX_OPERATIONS", "MAX_DEPTH"]

#: Functions an expression may call, each with exactly one positional argument.
FUNCTIONS: dict[str, Callable[[Any], Any]] = {
    "sin": jnp.sin,
    "cos": jnp.cos,
    "tan": jnp.tan,
    "exp": jnp.exp,
    "log": jnp.log,
    "sqrt": jnp.sqrt,
    "tanh": jnp.tanh,
    "sinh": jnp.sinh,
    "cosh": jnp.cosh,
    "abs": jnp.abs,
}

#: Named constants an expression may use.
CONSTANTS: dict[str, float] = {"pi": math.pi}

#: Longest accepted expression text, in characters.
MAX_EXPRESSION_LENGTH = 10_000

#: Most operations (binary and unary operators and function calls) an expression may have.
#: JAX traces every operation several times in a run (H, J∇H by autodiff, the loss and its
#: gradient, the finite and separability checks, the reference solver, the integrators), so the
#: wait before the first epoch grows with their number. Measured with
#: ``python -m benchmarks.expression_size`` (CPU seconds from the config to the first compiled
#: training step of one model, 2-core machine): a non-separable H takes 3.8 s at 55 operations,
#: 5.2 s at 500, 10.7 s at 2 005 (~3.4 ms per operation); a separable H, whose separability check
#: differentiates it twice, 4.9 s at 35, 8.5 s at 500, 14.7 s at 1 205 (~8 ms per operation).
#: 500 keeps both under ~10 s (a run with three models compiles the training three times).
MAX_OPERATIONS = 500

#: Deepest accepted nesting of operations. A left-to-right chain such as ``a + b - c + d``
#: counts as one level however long it is; ``sin(sin(x))`` or ``-(-x)`` add one level each.
MAX_DEPTH = 100


# ---------------------------------------------------------------------- positions
class _Source:
    """The text being parsed and how to turn parser positions into user-facing ones."""

    def __init__(self, text: str) -> None:
        norm = text.replace("\r\n", "\n").replace("\r", "\n")
        stripped = norm.strip()
        lead = norm[: len(norm) - len(norm.lstrip())]
        self.original = text
        self.text = stripped  # what is parsed; leading blanks would be an "unexpected indent"
        self.lines = stripped.split("\n")
        self.line_shift = lead.count("\n")
        self.col_shift = len(lead) - (lead.rfind("\n") + 1)
        self.multiline = len(self.lines) > 1

    def where(self, lineno: int | None, col: int | None) -> str:
        """'column C' (or 'line L, column C') for a 1-based line and a 1-based character column."""
        if lineno is None or col is None or col < 1:
            return "the end of the text" if lineno is None else f"line {lineno + self.line_shift}"
        if lineno == 1:
            col += self.col_shift
        if self.multiline:
            return f"line {lineno + self.line_shift}, column {col}"
        return f"column {col}"

    def node_where(self, node: ast.AST) -> str:
        lineno = getattr(node, "lineno", None)
        byte_col = getattr(node, "col_offset", None)
        if lineno is None or byte_col is None or not 1 <= lineno <= len(self.lines):
            return "an unknown position"
        # ast columns count UTF-8 bytes; users count characters.
        prefix = self.lines[lineno - 1].encode("utf-8")[:byte_col]
        return self.where(lineno, len(prefix.decode("utf-8", errors="replace")) + 1)

    def segment(self, node: ast.AST, limit: int = 60) -> str:
        """The source text of a node, shortened, as a one-line repr."""
        seg = ast.get_source_segment(self.text, node) or type(node).__name__
        seg = " ".join(seg.split())
        if len(seg) > limit:
            seg = seg[: limit - 3] + "..."
        return repr(seg)

    def token_at(self, lineno: int | None, col: int | None) -> str | None:
        """The word or symbol at a 1-based (line, column), for syntax errors."""
        if lineno is None or col is None or not 1 <= lineno <= len(self.lines):
            return None
        line = self.lines[lineno - 1]
        i = col - 1
        if not 0 <= i < len(line) or line[i].isspace():
            return None
        m = re.compile(r"\w+").match(line, i)
        if m is None:
            m = re.compile(r"[^\w\s()\[\]{}]+").match(line, i)
        tok = m.group(0) if m is not None else line[i]
        return tok[:40]


def _one_line(msg: str) -> str:
    return " ".join(str(msg).split())


# ---------------------------------------------------------------------- names
def _check_name(name: Any, what: str) -> str:
    if not isinstance(name, str):
        raise ExpressionError(f"{what} names must be strings, got {name!r}")
    if not name.isidentifier():
        raise ExpressionError(f"{what} name {name!r} is not a valid identifier (use letters, digits and _)")
    if keyword.iskeyword(name):
        raise ExpressionError(f"{what} name {name!r} is a Python keyword; choose another name")
    if unicodedata.normalize("NFKC", name) != name:
        raise ExpressionError(
            f"{what} name {name!r} is not in Unicode NFKC form; Python reads it as "
            f"{unicodedata.normalize('NFKC', name)!r}"
        )
    if name.startswith("__"):
        raise ExpressionError(f"{what} name {name!r} is not allowed (names may not start with '__')")
    if name in FUNCTIONS:
        raise ExpressionError(f"{what} name {name!r} is the name of a function; choose another name")
    if name in CONSTANTS:
        raise ExpressionError(f"{what} name {name!r} is a built-in constant; choose another name")
    return name


def _check_names(variables: Any, params: Mapping[str, Any]) -> tuple[tuple[str, ...], dict[str, float]]:
    if isinstance(variables, str) or not isinstance(variables, Sequence):
        raise ExpressionError(f"variables must be a list of names, got {variables!r}")
    var_names = tuple(_check_name(v, "variable") for v in variables)
    if params is None:
        params = {}
    if not isinstance(params, Mapping):
        raise ExpressionError(f"params must be a mapping of names to numbers, got {type(params).__name__}")
    values: dict[str, float] = {}
    for key, value in params.items():
        _check_name(key, "parameter")
        values[key] = _param_value(key, value)
    seen: set[str] = set()
    for n in var_names + tuple(values):
        if n in seen:
            raise ExpressionError(f"name {n!r} is declared twice (variables and parameters must be distinct)")
        seen.add(n)
    return var_names, values


def _param_value(name: str, value: Any) -> float:
    bad = (
        isinstance(value, (bool, np.bool_, str, bytes))
        or not isinstance(value, (numbers.Real, np.ndarray, np.generic))
        or (isinstance(value, np.ndarray) and value.ndim != 0)
    )
    try:
        out = None if bad else float(value)
    except (TypeError, ValueError, OverflowError):
        out = None
    if out is None or not math.isfinite(out):
        raise ExpressionError(f"parameter {name!r} must be a finite number, got {value!r}")
    return out


# ---------------------------------------------------------------------- parsing
def _parse(src: _Source) -> ast.Expression:
    text = src.original
    if len(text) > MAX_EXPRESSION_LENGTH:
        raise ExpressionError(
            f"expression is too long ({len(text)} characters; at most {MAX_EXPRESSION_LENGTH})"
        )
    if not src.text:
        raise ExpressionError("expression is empty")
    if "\x00" in text:
        raise ExpressionError(f"expression contains a NUL character at position {text.index(chr(0)) + 1}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = ast.parse(src.text, mode="eval")
    except SyntaxError as exc:
        lineno = exc.lineno if isinstance(exc.lineno, int) else None
        offset = exc.offset if isinstance(exc.offset, int) else None
        tok = src.token_at(lineno, offset)
        near = f" near {tok!r}" if tok else ""
        where = f" at {src.where(lineno, offset)}" if offset else ""
        raise ExpressionError(f"syntax error{where}{near}: {_one_line(exc.msg)}") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(
            "expression is too complex to parse (nested too deeply, or a chain of more than about "
            "a thousand operations)"
        ) from None
    except ValueError as exc:  # e.g. over-long integer literals on some Python versions
        raise ExpressionError(f"expression cannot be parsed: {_one_line(str(exc))}") from None
    if not isinstance(tree, ast.Expression):  # pragma: no cover - mode="eval" guarantees it
        raise ExpressionError("expression cannot be parsed as a single expression")
    _check_size(tree, len(text))
    return tree


def _top_level_terms(node: ast.AST) -> int:
    """The number of summands at the top: a + b - c has 3."""
    n = 1
    while isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
        n += 1
        node = node.left
    return n


def _check_size(tree: ast.Expression, length: int) -> None:
    """Refuse an expression with more than MAX_OPERATIONS operations, before anything is built."""
    ops = sum(isinstance(n, (ast.BinOp, ast.UnaryOp, ast.Call)) for n in ast.walk(tree))
    if ops > MAX_OPERATIONS:
        raise ExpressionError(
            f"expression is too large: {ops} operations in {_top_level_terms(tree.body)} terms ({length} "
            f"characters); at most {MAX_OPERATIONS} operations are accepted (compiling a larger one takes "
            "more than ~10 s); simplify it, e.g. collect equal terms, or write H with array operations in a Python "
            "file ([system] python = \"FILE.py:FUNCTION\")"
        )



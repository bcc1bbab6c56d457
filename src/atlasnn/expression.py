"""Hamiltonians written as text, e.g. ``"p**2/2 - cos(q)"``, parsed safely.

The text is parsed with :mod:`ast` (``mode="eval"``) and every node of the tree is checked
against a short whitelist before anything is built:

* numbers (``int`` and ``float`` literals; not ``True``/``False``/``None``, complex or strings),
* names that were declared as variables or parameters, and the constant ``pi``,
* the binary operators ``+ - * / **`` and the unary operators ``+ -`` (parentheses group),
* calls ``f(x)`` of one of :data:`FUNCTIONS` with exactly one positional argument.

Anything else (attribute access, subscripts, lambdas, comprehensions, keyword or starred
arguments, comparisons, boolean operators, conditional expressions, strings, f-strings,
``:=``, unknown or dunder names, ...) is refused with a one-line :class:`ExpressionError` that
names the offending piece and its column. The user's text is never given to ``eval``,
``exec`` or ``compile``: the checked tree is turned into a chain of small Python closures
over :mod:`jax.numpy`, so the result is an ordinary JAX-traceable function (``jax.grad``,
``jax.jit`` and ``jax.vmap`` work on it).

:func:`expression_system` wraps such an expression into a
:class:`~atlasnn.systems.HamiltonianSystem` whose ``spec`` lets
:func:`atlasnn.systems.system_from_spec` rebuild it (e.g. from a checkpoint).
"""

from __future__ import annotations

import ast
import dataclasses
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

__all__ = [
    "FUNCTIONS",
    "CONSTANTS",
    "MAX_EXPRESSION_LENGTH",
    "MAX_OPERATIONS",
    "MAX_DEPTH",
    "CompiledExpression",
    "compile_expression",
    "expression_system",
    "is_syntactically_separable",
]

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

# Integer exponents up to this size use exact repeated multiplication (lax.integer_pow),
# which also has the right derivative at 0; larger ones use the general power.
_MAX_INTEGER_EXPONENT = 1024

_BINARY_OPS: dict[type, tuple[str, Callable[[Any, Any], Any]]] = {
    ast.Add: ("+", jnp.add),
    ast.Sub: ("-", jnp.subtract),
    ast.Mult: ("*", jnp.multiply),
    ast.Div: ("/", jnp.true_divide),
    ast.Pow: ("**", jnp.power),
}

_UNARY_OPS: dict[type, tuple[str, Callable[[Any], Any] | None]] = {
    ast.UAdd: ("+", None),
    ast.USub: ("-", jnp.negative),
}

# Symbols of refused operators, for the error messages.
_OTHER_OPERATORS: dict[type, str] = {
    ast.Mod: "%",
    ast.FloorDiv: "//",
    ast.MatMult: "@",
    ast.LShift: "<<",
    ast.RShift: ">>",
    ast.BitOr: "|",
    ast.BitXor: "^",
    ast.BitAnd: "&",
    ast.Not: "not",
    ast.Invert: "~",
}

# What to call a refused node kind in an error message.
_NODE_WORDS: dict[type, str] = {
    ast.Attribute: "attribute access",
    ast.Subscript: "subscript",
    ast.Slice: "slice",
    ast.Lambda: "lambda",
    ast.ListComp: "comprehension",
    ast.SetComp: "comprehension",
    ast.DictComp: "comprehension",
    ast.GeneratorExp: "generator expression",
    ast.Compare: "comparison",
    ast.BoolOp: "boolean operator",
    ast.IfExp: "conditional expression",
    ast.NamedExpr: "assignment expression ':='",
    ast.JoinedStr: "f-string",
    ast.FormattedValue: "f-string",
    ast.Starred: "starred expression",
    ast.List: "list",
    ast.Tuple: "tuple",
    ast.Set: "set",
    ast.Dict: "dict",
    ast.Await: "await",
    ast.Yield: "yield",
    ast.YieldFrom: "yield",
}

_Evaluator = Callable[[Mapping[str, Any]], Any]


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
            "more than ~10 s); simplify it, e.g. collect equal terms"
        )


class _Compiler:
    """Check a parsed tree against the whitelist and build closures that evaluate it."""

    def __init__(self, src: _Source, variables: Sequence[str], params: Mapping[str, float]) -> None:
        self.src = src
        self.variables = set(variables)
        self.params = dict(params)
        self.used: set[str] = set()

    # errors -----------------------------------------------------------------
    def refuse(
        self, node: ast.AST, what: str, hint: str = "", verb: str = "is not allowed in an expression"
    ) -> ExpressionError:
        where = f"{self.src.node_where(node)}: {self.src.segment(node)}"
        return ExpressionError(f"{what} {verb} (at {where})" + (f"; {hint}" if hint else ""))

    # entry ------------------------------------------------------------------
    def compile(self, node: ast.AST, depth: int) -> _Evaluator:
        if depth > MAX_DEPTH:
            raise ExpressionError(
                f"expression is nested too deeply (more than {MAX_DEPTH} levels) at "
                f"{self.src.node_where(node)}: {self.src.segment(node)}"
            )
        if isinstance(node, ast.Constant):
            value = self.number(node)
            return lambda env: value
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.BinOp):
            return self.binop_chain(node, depth)
        if isinstance(node, ast.UnaryOp):
            return self.unary(node, depth)
        if isinstance(node, ast.Call):
            return self.call(node, depth)
        raise self.refuse(node, self.describe(node))

    def describe(self, node: ast.AST) -> str:
        if isinstance(node, ast.Attribute):
            return f"attribute access '.{node.attr}'"
        if isinstance(node, ast.BoolOp):
            return f"boolean operator '{'and' if isinstance(node.op, ast.And) else 'or'}'"
        if isinstance(node, ast.Compare):
            return "comparison"
        for kind, word in _NODE_WORDS.items():
            if isinstance(node, kind):
                return word
        return f"{type(node).__name__} syntax"

    # leaves -----------------------------------------------------------------
    def number(self, node: ast.Constant) -> float:
        value = node.value
        if isinstance(value, bool) or value is None:
            raise self.refuse(node, f"constant {value!r}")
        if isinstance(value, (str, bytes)):
            raise self.refuse(node, "string literal")
        if isinstance(value, complex):
            raise self.refuse(node, "complex number")
        if not isinstance(value, (int, float)):
            raise self.refuse(node, f"constant {type(value).__name__}")
        try:
            return float(value)
        except OverflowError:
            raise self.refuse(node, "number too large for a float") from None

    def name(self, node: ast.Name) -> _Evaluator:
        ident = node.id
        if not isinstance(node.ctx, ast.Load):  # pragma: no cover - eval mode has no stores
            raise self.refuse(node, f"assignment to {ident!r}")
        if ident in self.variables:
            self.used.add(ident)
            return lambda env: env[ident]
        if ident in self.params:
            value = self.params[ident]
            return lambda env: value
        if ident in CONSTANTS:
            value = CONSTANTS[ident]
            return lambda env: value
        if ident.startswith("__"):
            raise self.refuse(node, f"dunder name {ident!r}")
        if ident in FUNCTIONS:
            raise self.refuse(node, f"function {ident!r}", f"write {ident}(...)", verb="must be called")
        known = sorted(self.variables) + sorted(self.params) + sorted(CONSTANTS)
        raise self.refuse(node, f"unknown name {ident!r}", f"known names: {', '.join(known)}", verb="is not defined")

    # operators --------------------------------------------------------------
    def binop_fn(self, node: ast.BinOp) -> Callable[[Any, Any], Any]:
        entry = _BINARY_OPS.get(type(node.op))
        if entry is None:
            sym = _OTHER_OPERATORS.get(type(node.op), type(node.op).__name__)
            raise self.refuse(node, f"operator '{sym}'")
        return entry[1]

    def integer_exponent(self, node: ast.AST) -> int | None:
        """The exponent as a Python int when it is a (signed) small integer literal."""
        sign = 1
        while isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            if isinstance(node.op, ast.USub):
                sign = -sign
            node = node.operand
        if (
            isinstance(node, ast.Constant)
            and isinstance(node.value, int)
            and not isinstance(node.value, bool)
            and abs(node.value) <= _MAX_INTEGER_EXPONENT
        ):
            return sign * node.value
        return None

    def binop_chain(self, node: ast.BinOp, depth: int) -> _Evaluator:
        # Walk the left spine iteratively, so that a long sum such as q1 + q2 + ... + qn is one
        # level of nesting (and one loop at run time), not n recursive calls.
        spine: list[ast.BinOp] = []
        cur: ast.AST = node
        while isinstance(cur, ast.BinOp):
            spine.append(cur)
            cur = cur.left
        first = self.compile(cur, depth + 1)
        steps: list[tuple[Callable[[Any, Any], Any], _Evaluator]] = []
        for b in reversed(spine):
            fn = self.binop_fn(b)
            n = self.integer_exponent(b.right) if isinstance(b.op, ast.Pow) else None
            if n is not None:
                self.compile(b.right, depth + 1)  # still checked (and depth-limited)
                steps.append((fn, (lambda k: (lambda env: k))(n)))
            else:
                steps.append((fn, self.compile(b.right, depth + 1)))

        def evaluate(env: Mapping[str, Any]) -> Any:
            value = first(env)
            for fn, right in steps:
                value = fn(value, right(env))
            return value

        return evaluate

    def unary(self, node: ast.UnaryOp, depth: int) -> _Evaluator:
        entry = _UNARY_OPS.get(type(node.op))
        if entry is None:
            sym = _OTHER_OPERATORS.get(type(node.op), type(node.op).__name__)
            raise self.refuse(node, f"operator '{sym}'")
        operand = self.compile(node.operand, depth + 1)
        fn = entry[1]
        if fn is None:  # unary plus
            return operand
        return lambda env: fn(operand(env))

    def call(self, node: ast.Call, depth: int) -> _Evaluator:
        func = node.func
        if not isinstance(func, ast.Name):
            # Report what is wrong inside the callee first (e.g. an attribute access).
            self.compile(func, depth + 1)
            raise self.refuse(node, "calling the result of an expression")
        ident = func.id
        if ident not in FUNCTIONS:
            if ident in self.variables or ident in self.params or ident in CONSTANTS:
                raise self.refuse(node, f"call of {ident!r}", f"{ident!r} is not a function")
            raise self.refuse(node, f"call of {ident!r}", f"allowed functions: {', '.join(sorted(FUNCTIONS))}")
        for kw in node.keywords:
            label = f"'{kw.arg}='" if kw.arg is not None else "'**'"
            raise self.refuse(kw, f"keyword argument {label} in a call of {ident!r}")
        for arg in node.args:
            if isinstance(arg, ast.Starred):
                raise self.refuse(arg, f"starred argument in a call of {ident!r}")
        if len(node.args) != 1:
            raise self.refuse(
                node, f"call of {ident!r} with {len(node.args)} arguments", f"{ident} takes exactly one argument"
            )
        arg = self.compile(node.args[0], depth + 1)
        fn = FUNCTIONS[ident]
        return lambda env: fn(arg(env))


# ---------------------------------------------------------------------- public API
class CompiledExpression:
    """A checked expression, callable on JAX arrays.

    Call it with one value per variable, positionally in the order of ``variables`` or by
    keyword: ``f(q_value, p_value)`` or ``f(q=..., p=...)``. Values broadcast like NumPy
    arrays; integer inputs are converted to the default float type. The result is a JAX
    array. The call is pure JAX, so ``jax.grad``, ``jax.jit`` and ``jax.vmap`` apply.

    Attributes:
        text: the expression as given.
        variables: the variable names, in call order.
        params: the parameter values bound into the expression.
        names_used: the variables that actually occur in the expression.
        tree: the parsed (and checked) :class:`ast.Expression`.
    """

    def __init__(
        self,
        text: str,
        variables: tuple[str, ...],
        params: dict[str, float],
        evaluator: _Evaluator,
        names_used: frozenset[str],
        tree: ast.Expression,
    ) -> None:
        self.text = text
        self.variables = variables
        self.params = params
        self.names_used = names_used
        self.tree = tree
        self._evaluator = evaluator

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if len(args) > len(self.variables):
            raise TypeError(f"expression takes {len(self.variables)} values {list(self.variables)}, got {len(args)}")
        env: dict[str, Any] = dict(zip(self.variables, args))
        for key, value in kwargs.items():
            if key not in self.variables:
                raise TypeError(f"unknown variable {key!r}; variables are {list(self.variables)}")
            if key in env:
                raise TypeError(f"variable {key!r} given twice")
            env[key] = value
        missing = [v for v in self.variables if v not in env]
        if missing:
            raise TypeError(f"missing values for variables {missing}")
        for key, value in env.items():
            arr = jnp.asarray(value)
            if not jnp.issubdtype(arr.dtype, jnp.inexact):
                arr = arr.astype(jnp.result_type(float))
            env[key] = arr
        # Literals beyond the float range (e.g. 1e300 in float32) become inf, without warnings.
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return jnp.asarray(self._evaluator(env))

    def __repr__(self) -> str:
        return f"CompiledExpression({self.text!r}, variables={list(self.variables)}, params={self.params})"


def compile_expression(
    text: str, variables: Sequence[str], params: Mapping[str, float] | None = None
) -> CompiledExpression:
    """Parse and check ``text`` and return it as a JAX function of ``variables``.

    Args:
        text: the expression, e.g. ``"p**2/2 - cos(q)"`` (at most
            :data:`MAX_EXPRESSION_LENGTH` characters).
        variables: names of the inputs, in the order the returned function takes them.
        params: named constants with their (finite) values, e.g. ``{"lam": 1.0}``.

    Returns:
        A :class:`CompiledExpression`; call it as ``f(*values)``.

    Raises:
        ExpressionError: one line naming the offending piece and where it is, when the text
            is empty, too long, not valid syntax, nested too deeply, or uses anything outside
            the whitelist described in this module's docstring; or when a name or parameter
            value is unusable.
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expression must be a string, got {type(text).__name__}")
    var_names, param_values = _check_names(variables, params if params is not None else {})
    src = _Source(text)
    tree = _parse(src)
    compiler = _Compiler(src, var_names, param_values)
    evaluator = compiler.compile(tree.body, 1)
    return CompiledExpression(text, var_names, param_values, evaluator, frozenset(compiler.used), tree)


def _state_names(node: ast.AST, state: frozenset[str]) -> set[str]:
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name) and n.id in state}


def _splits(node: ast.AST, qs: frozenset[str], ps: frozenset[str]) -> bool:
    """True if node is syntactically a sum T(p) + V(q) (possibly scaled by constants)."""
    names = _state_names(node, qs | ps)
    if not (names & qs) or not (names & ps):
        return True
    if isinstance(node, ast.UnaryOp):
        return _splits(node.operand, qs, ps)
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
        terms: list[ast.AST] = []
        cur: ast.AST = node
        while isinstance(cur, ast.BinOp) and isinstance(cur.op, (ast.Add, ast.Sub)):
            terms.append(cur.right)
            cur = cur.left
        terms.append(cur)
        return all(_splits(t, qs, ps) for t in terms)
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Mult, ast.Div)):
        # A product of factors: separable if exactly one factor holds state variables, it is
        # not a divisor, and it splits itself (c * (T + V) = c*T + c*V).
        factors: list[tuple[bool, ast.AST]] = []  # (is_divisor, factor)
        cur = node
        while isinstance(cur, ast.BinOp) and isinstance(cur.op, (ast.Mult, ast.Div)):
            factors.append((isinstance(cur.op, ast.Div), cur.right))
            cur = cur.left
        factors.append((False, cur))
        with_state = [(div, f) for div, f in factors if _state_names(f, qs | ps)]
        if len(with_state) != 1 or with_state[0][0]:
            return False
        return _splits(with_state[0][1], qs, ps)
    return False


def is_syntactically_separable(
    text: str,
    coordinates: Sequence[str],
    momenta: Sequence[str],
    params: Mapping[str, float] | None = None,
) -> bool:
    """Whether ``text`` is visibly of the form T(p) + V(q).

    True when the expression is a sum (or difference) of terms that each use only
    coordinates or only momenta, where a term may also be a constant multiple of such a sum
    (``0.5*(p**2 + q**2)``). False means "not visibly separable", not "not separable": e.g.
    ``(q + p)**2 - 2*q*p`` is separable but not recognised. Raises :class:`ExpressionError`
    if the text does not compile.
    """
    qs = _coerce_names(coordinates, "coordinates", "coordinate")
    ps = _coerce_names(momenta, "momenta", "momentum")
    return _separable(compile_expression(text, qs + ps, params), qs, ps)


def _separable(compiled: CompiledExpression, qs: Sequence[str], ps: Sequence[str]) -> bool:
    try:
        return _splits(compiled.tree.body, frozenset(qs), frozenset(ps))
    except RecursionError:  # pragma: no cover - the depth limits make this unreachable
        return False


def _coerce_names(names: Any, what: str, one: str) -> tuple[str, ...]:
    if isinstance(names, str):
        names = [n for n in re.split(r"[\s,]+", names) if n]
    if not isinstance(names, Sequence) or isinstance(names, (bytes, bytearray)):
        raise ExpressionError(f"{what} must be a list of names, got {names!r}")
    return tuple(_check_name(n, one) for n in names)


_SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}")


def expression_system(
    hamiltonian: str,
    coordinates: Sequence[str],
    momenta: Sequence[str],
    params: Mapping[str, float] | None = None,
    name: str = "custom",
    separable: bool | str = False,
    z0: Sequence[float] | None = None,
):
    """A :class:`~atlasnn.systems.HamiltonianSystem` from a Hamiltonian written as text.

    Example::

        expression_system("(px**2+py**2)/2 + (x**2+y**2)/2 + lam*(x**2*y - y**3/3)",
                          coordinates=["x", "y"], momenta=["px", "py"], params={"lam": 1.0},
                          name="hh", separable=True, z0=[0.3, -0.3, 0.3, 0.15])

    Args:
        hamiltonian: the expression H in the coordinate, momentum and parameter names.
        coordinates, momenta: the d coordinate names and the d momentum names (d >= 1);
            a single string "x, y" is split on commas and blanks.
        params: named parameters with finite values.
        name: a short identifier (letters, digits, ``_ . -``; used in file names).
        separable: ``True`` if H = T(p) + V(q) (the user's declaration, not checked),
            ``False``, or ``"auto"`` to decide with :func:`is_syntactically_separable`.
        z0: default initial state, coordinates then momenta.

    Returns:
        The system; its ``spec`` rebuilds it with :func:`atlasnn.systems.system_from_spec`.
    """
    from atlasnn.systems import HamiltonianSystem

    qs = _coerce_names(coordinates, "coordinates", "coordinate")
    ps = _coerce_names(momenta, "momenta", "momentum")
    if len(qs) < 1:
        raise ExpressionError("coordinates must name at least one coordinate")
    if len(qs) != len(ps):
        raise ExpressionError(
            f"coordinates and momenta must have the same length, got {list(qs)} and {list(ps)}"
        )
    if not isinstance(name, str) or not _SAFE_NAME.fullmatch(name):
        raise ExpressionError(
            f"system name must be 1-64 characters of letters, digits, '_', '.', '-', got {name!r}"
        )
    auto = isinstance(separable, str) and separable == "auto"
    if not (isinstance(separable, (bool, np.bool_)) or auto):
        raise ExpressionError(f"separable must be True, False or 'auto', got {separable!r}")

    compiled = compile_expression(hamiltonian, qs + ps, params)
    if auto:
        sep = _separable(compiled, qs, ps)
    else:
        sep = bool(separable)
    d = len(qs)
    names = qs + ps

    def H(q, p):
        q = jnp.asarray(q)
        p = jnp.asarray(p)
        values = [q[..., i] for i in range(d)] + [p[..., i] for i in range(d)]
        return compiled(**dict(zip(names, values)))

    system = HamiltonianSystem(
        H, d, name=name, q_names=qs, p_names=ps, z0=z0, separable=sep, params=dict(compiled.params),
    )
    spec = {
        "kind": "expression",
        "hamiltonian": hamiltonian,
        "coordinates": list(qs),
        "momenta": list(ps),
        "params": dict(compiled.params),
        "name": name,
        "separable": sep,
        "z0": None if system.z0 is None else [float(x) for x in system.z0],
    }
    return dataclasses.replace(system, z0=system.z0, spec=spec)


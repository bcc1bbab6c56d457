"""Compiling a parsed expression: each node checked against the whitelist, then JAX closures.

Part of :mod:`atlasnn.systems._expression` (which describes the whitelist and re-exports these names):
:class:`_Compiler` walks the tree that :mod:`atlasnn.systems._parse` parsed, refuses every node
outside the whitelist with a one-line :class:`~atlasnn.errors.ExpressionError` naming the piece
and its column, and builds a chain of small Python closures over :mod:`jax.numpy`;
:func:`compile_expression` returns them as a :class:`CompiledExpression`, an ordinary
JAX-traceable function. The user's text is never given to ``eval``, ``exec`` or ``compile``.
"""

from __future__ import annotations

import ast
from typing import Any, Callable, Mapping, Sequence

import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ExpressionError
from atlasnn.systems._parse import (
    CONSTANTS,
    FUNCTIONS,
    MAX_DEPTH,
    _check_names,
    _parse,
    _Source,
)

__all__ = ["CompiledExpression", "compile_expression"]

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



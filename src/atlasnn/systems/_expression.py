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
:func:`~atlasnn.systems.system_from_spec` rebuild it (e.g. from a checkpoint).

The parts: :mod:`atlasnn.systems._parse` holds the whitelist's names and limits and parses the
text, :mod:`atlasnn.systems._compile` checks the tree and builds the JAX function
(:func:`compile_expression`); this module holds the separability analysis
(:func:`is_syntactically_separable`) and :func:`expression_system`.
"""

from __future__ import annotations

import ast
import dataclasses
import re
from typing import Any, Mapping, Sequence

import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ExpressionError
from atlasnn.systems._hamiltonian import HamiltonianSystem

from atlasnn.systems._compile import CompiledExpression, compile_expression
from atlasnn.systems._parse import _check_name

__all__ = ["expression_system", "is_syntactically_separable"]


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
    """A [`HamiltonianSystem`][atlasnn.systems.HamiltonianSystem] from a Hamiltonian written as text.

    Example::

        expression_system("(px**2+py**2)/2 + (x**2+y**2)/2 + lam*(x**2*y - y**3/3)",
                          coordinates=["x", "y"], momenta=["px", "py"], params={"lam": 1.0},
                          name="hh", separable=True, z0=[0.3, -0.3, 0.3, 0.15])

    Args:
        hamiltonian: the expression H in the coordinate, momentum and parameter names.
        coordinates: the d coordinate names (d >= 1); a single string "x, y" is split on commas
            and blanks.
        momenta: the d momentum names, the same way.
        params: named parameters with finite values.
        name: a short identifier (letters, digits, ``_ . -``; used in file names).
        separable: ``True`` if H = T(p) + V(q) (the user's declaration, not checked),
            ``False``, or ``"auto"`` to decide with ``is_syntactically_separable``.
        z0: default initial state, coordinates then momenta.

    Returns:
        The system; its ``spec`` rebuilds it with ``system_from_spec``.
    """
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

    param_names = tuple(compiled.params)
    with_inputs = compile_expression(hamiltonian, names + param_names, {})  # θ as inputs (bundles, fits)

    def H_theta(q, p, theta):
        q, p, theta = jnp.asarray(q), jnp.asarray(p), jnp.asarray(theta)
        values = [q[..., i] for i in range(d)] + [p[..., i] for i in range(d)]
        values += [theta[..., i] for i in range(len(param_names))]
        return with_inputs(*values)

    system = HamiltonianSystem(
        H, d, name=name, q_names=qs, p_names=ps, z0=z0, separable=sep, params=dict(compiled.params),
        parametric=H_theta,
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


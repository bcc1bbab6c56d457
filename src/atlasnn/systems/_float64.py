"""Whether a system's H computes in float64 when traced in float64: the check the float64 solvers
run before they compile.

With JAX's x64 mode off (its default), an array that H closes over can reach a float64 program
as float32 without a word: a ``jnp`` array made while x64 was off is float32, and JAX keeps the
float32 copy it makes of a NumPy array the first time H is traced with x64 off (keyed by the
array alone) for as long as a trace holding it lives, and hands that copy to a later float64
trace. A solution then carries the constant's float32 rounding (6.9e-7 off with
``K = np.array([2.3])``) while its error estimate, which only compares the solver with itself,
says 1e-13. H is traced once in float64 here (through a wrapper of its own, so that nothing of
the trace is kept) and refused in one line when it holds such a constant or computes in a
narrower float.
"""

from __future__ import annotations

import weakref
from typing import Any, Iterator

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend import core as jcore

from atlasnn.errors import SystemError_

__all__ = ["require_float64_field", "narrow_floats"]

#: the systems found to compute in float64 (a trace costs ~6 ms, as much as a short solve)
_CHECKED: "weakref.WeakKeyDictionary[Any, bool]" = weakref.WeakKeyDictionary()


def _narrow(aval: Any) -> bool:
    dtype = getattr(aval, "dtype", None)
    if dtype is None or not jnp.issubdtype(dtype, jnp.inexact):
        return False
    return jnp.finfo(dtype).bits < 64


def _subjaxprs(value: Any) -> Iterator[Any]:
    if isinstance(value, jcore.ClosedJaxpr):
        yield value
    elif isinstance(value, jcore.Jaxpr):
        yield jcore.ClosedJaxpr(value, [])
    elif isinstance(value, (tuple, list)):
        for item in value:
            yield from _subjaxprs(item)


def narrow_floats(closed: Any) -> tuple[list[str], list[str]]:
    """The float types narrower than float64 in a traced program and the programs inside it: (the
    constants', e.g. ``["float32[1]"]``, the computed values')."""
    constants, computed = [], []

    def visit(closed):
        jaxpr = closed.jaxpr
        constants.extend(str(v.aval) for v in jaxpr.constvars if _narrow(v.aval))
        for eqn in jaxpr.eqns:
            constants.extend(str(v.aval) for v in eqn.invars if isinstance(v, jcore.Literal)
                             and _narrow(v.aval))
            computed.extend(f"{v.aval} ({eqn.primitive})" for v in eqn.outvars if _narrow(v.aval))
            for param in eqn.params.values():
                for sub in _subjaxprs(param):
                    visit(sub)

    visit(closed)
    return constants, computed


def require_float64_field(system: Any, *, constants: bool = True) -> None:
    """Refuse, in one line, a system whose H (or ``parametric`` H) traced in float64 holds a
    constant narrower than float64 or computes in one (module docstring). Once per system: a
    system found right is not traced again. ``constants=False`` judges only what H computes (the
    traced core: there a float32 array H closes over may be the caller's traced weights, exact once
    promoted)."""
    if _CHECKED.get(system):
        return
    d = system.dim
    calls = [("H(q, p)", system.hamiltonian, 2)]
    if system.parametric is not None:
        calls.append(("parametric(q, p, theta)", system.parametric, 3))
    with jax.enable_x64(True):
        z = np.full(2 * d, 0.5) if system.z0 is None else np.asarray(system.z0, np.float64)
        try:
            theta = np.asarray([float(v) for v in system.params.values()], np.float64)
        except Exception:  # noqa: BLE001 - a traced parameter value (inside jit/grad): H's types are what count
            theta = np.full(len(system.params), 0.5)
        for what, user_fn, count in calls:
            args = (jnp.asarray(z[:d]), jnp.asarray(z[d:]), jnp.asarray(theta))[:count]
            try:
                closed = jax.make_jaxpr(lambda *a, _fn=user_fn: _fn(*a))(*args)
            except Exception:  # noqa: BLE001 - not this check's to judge: the computation that meets it says
                continue
            narrow, computed = narrow_floats(closed)
            if narrow and constants:
                raise SystemError_(
                    f"system {system.name!r}: {what} holds a {narrow[0].split('[')[0]} constant "
                    f"({narrow[0]}) where the float64 solver needs float64 (a jnp array made while JAX's x64 "
                    "mode was off, or JAX's float32 copy of a NumPy array kept from a trace of H with x64 off); make "
                    "it a NumPy array, or turn x64 on before making it or tracing H (atlasnn.precision.enable_x64(), "
                    "or ATLASNN_X64=1)")
            if computed:
                raise SystemError_(
                    f"system {system.name!r}: {what} computes in {computed[0].split('[')[0]} ({computed[0]}) where "
                    "the float64 solver needs float64; remove the cast to the narrower type")
    if constants:
        _CHECKED[system] = True

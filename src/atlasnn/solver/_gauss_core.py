"""The Gauss march as a traceable JAX function: what :func:`atlasnn.solve` runs when its inputs
are traced (inside ``jax.jit``, ``jax.grad``, ``jax.vmap``, ``jax.jvp``), the same windows as the
compiled host march (:mod:`._gauss_march`: the same try of a window, :func:`try_window`, and the
same control) in one loop of at most ``max_windows`` tries, so that shapes are static.

Derivatives are those of the discrete solution over the windows taken: the window lengths are the
control's and carry no derivative (but the last window's, T − t, which carries T's), and each
window's stage equations are differentiated implicitly (``gauss_step(implicit_gradients=True)``:
one linear solve with their Jacobian at the solution, never the iterations). The loop is
Equinox's ``while_loop``: ``"checkpointed"`` for reverse mode (``jax.grad``; every window's state
kept, so memory grows with windows × state, not with iterations), ``"lax"`` for forward mode
(``jax.jvp``, ``jax.jacfwd``), chosen by ``GaussCollocation(differentiation=...)``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from atlasnn.errors import ConfigError
from atlasnn.solutions import TracedSolution, gauss_tableau
from atlasnn.solver._gauss_march import FAILURES, GaussState, started, marching, try_window
from atlasnn.solver._gauss_step import tableau_arrays
from atlasnn.systems import HamiltonianSystem

__all__ = ["gauss_core", "LOOPS"]

#: GaussCollocation.differentiation → the kind of Equinox loop (module docstring)
LOOPS = {"reverse": "checkpointed", "forward": "lax"}

#: the failure codes beyond the march's: the window budget spent before T
_BUDGET = max(FAILURES) + 1


class _Carry(NamedTuple):
    st: GaussState
    streak: jax.Array
    tries: jax.Array
    rows: tuple  # (start, length, z, e, L, accepted), one row per try


def _start(z0: jax.Array, t0: jax.Array, stages: int) -> GaussState:
    zero, izero = jnp.zeros((), z0.dtype), jnp.zeros((), jnp.int64)
    return GaussState(t0, zero, z0, jnp.zeros_like(z0), zero, zero, jnp.zeros((stages,) + z0.shape, z0.dtype),
                      izero, izero, izero, izero, izero, zero, izero)


def _traced_inputs(system: HamiltonianSystem, z0: Any, t0: Any, T: Any) -> tuple[jax.Array, jax.Array, jax.Array]:
    """z0, t0 and T as float64 JAX values, or a one-line refusal."""
    z0 = jnp.asarray(z0)
    if z0.dtype != jnp.float64:
        raise ConfigError(f"solve inside jit/grad/vmap needs float64 states, got z0 of dtype {z0.dtype}: turn on "
                          "JAX's 64-bit mode first, jax.config.update('jax_enable_x64', True)")
    if z0.shape != (system.state_dim,):
        raise ConfigError(f"z0 must have {system.state_dim} components {list(system.state_names)}, got shape "
                          f"{tuple(z0.shape)}")
    return z0, jnp.asarray(t0, jnp.float64), jnp.asarray(T, jnp.float64)


def gauss_core(system: HamiltonianSystem, z0: Any, t0: Any, T: Any, *, stages: int, steps: str, rtol: float,
               atol: float, h: float | None, max_windows: int, differentiation: str, max_iterations: int,
               newton: bool, growth: float, safety: float, warmup: int, max_rejects: int) -> TracedSolution:
    """The march of the module docstring from z0 over [t0, T] (traced or not). A march that fails
    or spends ``max_windows`` tries before T raises when it runs (``eqx.error_if``), naming why."""
    z0, t0, T = _traced_inputs(system, z0, t0, T)
    tab = tableau_arrays(gauss_tableau(stages))
    settings = {"steps": steps, "max_iterations": max_iterations, "newton": newton, "growth": growth,
                "safety": safety, "warmup": warmup, "until": None, "max_rejects": max_rejects, "implicit": True}
    h_given = jnp.asarray(0.0 if h is None else h, jnp.float64)
    n, budget = z0.shape[0], int(max_windows)
    st = started(system, tab, _start(z0, t0, stages), T, h_given)
    rows = (jnp.zeros(budget), jnp.zeros(budget), jnp.zeros((budget, n)), jnp.zeros((budget, n)),
            jnp.zeros((budget, stages, n)), jnp.zeros(budget, bool))

    def body(c: _Carry) -> _Carry:
        st, streak, ok, row = try_window(system, tab, settings, c.st, c.streak, T, rtol, atol, h_given)
        written = tuple(b.at[c.tries].set(x) for b, x in zip(c.rows, (*row[:5], ok)))
        return _Carry(st, streak, c.tries + 1, written)

    try:
        out = eqxi.while_loop(lambda c: marching(c.st, T), body, _Carry(st, jnp.asarray(0), jnp.asarray(0), rows),
                              max_steps=budget, buffers=lambda c: c.rows, kind=LOOPS[differentiation],
                              **({"checkpoints": budget} if differentiation == "reverse" else {}))
    except TypeError as exc:
        if "forward-mode" not in str(exc):
            raise
        raise ConfigError("jax.jvp/jax.jacfwd through solve need GaussCollocation(differentiation='forward') "
                          "(the default, 'reverse', serves jax.grad/jax.vjp)") from None
    return _solution(system, stages, t0, T, out)


def _solution(system: HamiltonianSystem, stages: int, t0, T, out: _Carry) -> TracedSolution:
    """The tries' rows as a TracedSolution, the accepted ones indexed in order; a failed march
    raises at run time."""
    start, length, z, e, L, accepted = out.rows
    budget = start.shape[0]
    position = jnp.arange(budget)
    order = jnp.nonzero(accepted, size=budget, fill_value=0)[0]  # the accepted rows, in order
    count = jnp.sum(accepted)
    st = out.st
    code = jnp.where(st.failed > 0, st.failed, jnp.where(st.t < T, _BUDGET, 0))
    messages = ["", *(f"solve (traced core): {FAILURES[k]}" for k in sorted(FAILURES)),
                f"solve (traced core): the window budget, GaussCollocation(max_windows={budget}), was spent before T: "
                "raise max_windows or loosen the tolerance"]
    starts = eqx.branched_error_if(jnp.where(position < count, start[order], jnp.inf), code > 0, code, messages)
    return TracedSolution(t0, T, starts, order, length, z, e, L, count, st.rejected, st.iterations, stages, system)

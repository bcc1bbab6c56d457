"""The Gauss march as a traceable JAX function: what :func:`atlasnn.solve` runs when its inputs
are traced (inside ``jax.jit``, ``jax.grad``, ``jax.vmap``, ``jax.jvp``), the same windows as the
compiled host march (:mod:`._gauss_march`: the same try of a window, :func:`try_window`, and the
same control) in one loop of at most ``max_windows`` tries, so that shapes are static.

Derivatives are those of the discrete solution over the windows taken: the window lengths are the
control's and carry no derivative (but the last window's, T − t, which carries T's), and each
window's stage equations are differentiated at their solution (implicit function theorem: one
linear solve with their Jacobian, never the iterations). Reverse mode (``jax.grad``; the default,
``GaussCollocation(differentiation="reverse")``) is the march's adjoint, written here
(:func:`_backward`): the forward march keeps every window's start state and stage solution (its
rows), and the backward pass walks the accepted windows back, each by its transposed linear solve
and one derivative of its residual — memory grows with windows × state, not with iterations, and
no window is solved twice. The values H closes over (a network's weights) are made explicit
arguments by ``jax.closure_convert`` so that the adjoint returns their derivatives. Forward mode
(``jax.jvp``, ``jax.jacfwd``; ``differentiation="forward"``) goes through the loop itself, each
window's stages differentiated by ``gauss_step(implicit_gradients=True)``.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from atlasnn.errors import ConfigError
from atlasnn.solutions import TracedSolution, gauss_tableau
from atlasnn.solver._gauss_march import FAILURES, GaussState, started, marching, try_window
from atlasnn.solver._gauss_step import solved_step, tableau_arrays
from atlasnn.solver._gauss_stops import COLLAPSE
from atlasnn.systems import HamiltonianSystem

__all__ = ["compiled_gauss_core", "gauss_core", "FORWARD_NEEDED", "LOOPS", "traced_inputs"]

#: the line a jax.jvp of the reverse-mode core raises
FORWARD_NEEDED = ("jax.jvp/jax.jacfwd through solve need GaussCollocation(differentiation='forward') (the default, "
                  "'reverse', serves jax.grad/jax.vjp)")
#: the line a jax.vmap over a value H closes over raises in reverse mode (JAX's sequential_vmap of
#: the adjoint's forward march asserts on batched closures)
VMAP_CLOSURE = ("jax.vmap over a value that H closes over needs GaussCollocation(differentiation='forward') "
                "(the default, 'reverse', maps over z0, t0 and T, and serves jax.grad with respect to the value)")
#: GaussCollocation.differentiation → how (module docstring)
LOOPS = {"reverse": "the march's adjoint", "forward": "through the loop"}

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


def traced_inputs(system: HamiltonianSystem, z0: Any, t0: Any, T: Any) -> tuple[jax.Array, jax.Array, jax.Array]:
    """z0, t0 and T as float64 JAX values, or a one-line refusal."""
    z0 = jnp.asarray(z0)
    if z0.dtype != jnp.float64:
        remedy = ("pass z0 as float64, e.g. jnp.asarray(z0, jnp.float64)" if jax.config.jax_enable_x64 else
                  "turn on JAX's 64-bit mode first, jax.config.update('jax_enable_x64', True)")
        raise ConfigError(f"solve inside jit/grad/vmap needs float64 states, got z0 of dtype {z0.dtype}: {remedy}")
    if z0.shape != (system.state_dim,):
        raise ConfigError(f"z0 must have {system.state_dim} components {list(system.state_names)}, got shape "
                          f"{tuple(z0.shape)}")
    t0, T = jnp.asarray(t0, jnp.float64), jnp.asarray(T, jnp.float64)
    for name, value in (("t0", t0), ("T", T)):
        if value.shape != ():
            raise ConfigError(f"solve inside jit/grad/vmap takes one interval: {name} must be a number, got shape "
                              f"{tuple(value.shape)} (jax.vmap over the intervals for several)")
    known = not any(isinstance(x, jax.core.Tracer) for x in (z0, t0, T))
    if known and not (np.all(np.isfinite(z0)) and np.isfinite(t0) and np.isfinite(T) and T > t0):
        raise ConfigError(f"solve needs a finite z0 and an interval with finite ends and T > t0, got t0 = {float(t0)}, "
                          f"T = {float(T)}, z0 {'finite' if np.all(np.isfinite(z0)) else 'not finite'}")
    if not known:  # checked when the program runs (a march that never started would give NaN)
        bad = ~(jnp.all(jnp.isfinite(z0)) & jnp.isfinite(t0) & jnp.isfinite(T) & (T > t0))
        T = eqx.error_if(T, bad, "solve (traced core): z0 must be finite and the interval's ends finite with T > t0")
    return z0, t0, T


class _Field:
    """What the march reads of a system — its vector field on rows of states, their Jacobians and
    its declared linear part — made from f(z, *consts) for one state, the values H closes over as
    explicit arguments (the adjoint returns their derivatives)."""

    def __init__(self, f1, consts, linear_part=None):
        self.f1, self.consts, self.linear_part = f1, tuple(consts), linear_part

    def vector_field(self, Z):
        return jax.vmap(lambda z: self.f1(z, *self.consts))(Z)

    def jacobian(self, Z):
        return jax.vmap(jax.jacfwd(lambda z: self.f1(z, *self.consts)))(Z)


class _Static(NamedTuple):
    """The core's settings (hashable: they select the traced program)."""

    stages: int
    steps: str
    rtol: float
    atol: float
    h: float | None
    budget: int
    max_iterations: int
    newton: bool
    growth: float
    safety: float
    warmup: int
    max_rejects: int


def _march(field, static: _Static, z0, t0, T, kind: str, implicit: bool) -> _Carry:
    """The loop of the module docstring, its rows written once per try."""
    tab = tableau_arrays(gauss_tableau(static.stages))
    settings = {"steps": static.steps, "max_iterations": static.max_iterations, "newton": static.newton,
                "growth": static.growth, "safety": static.safety, "warmup": static.warmup, "until": None,
                "max_rejects": static.max_rejects, "implicit": implicit}
    h_given = jnp.asarray(0.0 if static.h is None else static.h, jnp.float64)
    n, budget = z0.shape[0], static.budget
    st = started(field, tab, _start(z0, t0, static.stages), T, h_given)
    rows = (jnp.zeros(budget), jnp.zeros(budget), jnp.zeros((budget, n)), jnp.zeros((budget, n)),
            jnp.zeros((budget, static.stages, n)), jnp.zeros(budget, bool))

    def body(c: _Carry) -> _Carry:
        st, streak, ok, row = try_window(field, tab, settings, c.st, c.streak, T, static.rtol, static.atol, h_given)
        written = tuple(b.at[c.tries].set(x) for b, x in zip(c.rows, (*row[:5], ok)))
        return _Carry(st, streak, c.tries + 1, written)

    return eqxi.while_loop(lambda c: marching(c.st, T), body, _Carry(st, jnp.asarray(0), jnp.asarray(0), rows),
                           max_steps=budget, buffers=lambda c: c.rows, kind=kind)


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1, 2))
def _adjoint_march(f1, static: _Static, linear, consts, z0, t0, T) -> _Carry:
    """The march, differentiated in reverse by its adjoint (:func:`_backward`); ``linear``: the
    system's declared linear part or None."""
    return _primal(f1, static, linear, consts, z0, t0, T)


def _forward(f1, static, linear, consts, z0, t0, T):
    out = _primal(f1, static, linear, consts, z0, t0, T)
    return out, (out.rows, consts, t0, T)


def _primal(f1, static: _Static, linear, consts, z0, t0, T) -> _Carry:
    """The march of the adjoint's forward pass; under ``jax.vmap`` on a CPU its members marched
    one after the other (a loop over them, as ``solve_batch`` does there: in lock step every member
    pays for the longest one's windows and its batched loop: 4–10× slower measured), on an accelerator in
    lock step. (The custom batching sits inside the custom VJP, which differentiates it.)"""

    def run(consts, z0, t0, T):
        return _march(_Field(f1, consts, linear), static, z0, t0, T, "lax", False)

    if jax.default_backend() == "cpu":
        run = jax.custom_batching.sequential_vmap(run)
    return run(consts, z0, t0, T)


def _backward(f1, static: _Static, linear, residuals, cotangent: _Carry):
    """The adjoint of the march: its accepted windows walked back, each through its step from the
    stored stage solution (:func:`solved_step`: the transposed linear solve and one derivative of
    the residual, never the stage iteration again). The cotangents of the rows (start, length, z, e,
    L) come from the solution's evaluation; a start depends on t0, the last length (T − t) on T
    and t0, the others on nothing."""
    (start, length, z, e, L, accepted), consts, t0, T = residuals
    start_bar, length_bar, z_bar, e_bar, L_bar = cotangent.rows[:5]
    tab = tableau_arrays(gauss_tableau(static.stages))
    count = jnp.sum(accepted)
    order = jnp.nonzero(accepted, size=accepted.shape[0], fill_value=0)[0]

    def step(zk, ek, hk, cs, Lk):
        return solved_step(_Field(f1, cs).vector_field, tab, zk, ek, hk, Lk, static.max_iterations, linear)

    def body(j, carry):
        lam_z, lam_e, cs_bar, t0_bar, T_bar = carry
        w = count - 1 - j
        r = order[w]
        _, pull = jax.vjp(lambda zk, ek, hk, cs: step(zk, ek, hk, cs, L[r]), z[r], e[r], length[r], consts)
        zk_bar, ek_bar, hk_bar, c_bar = pull((L_bar[r], lam_z, lam_e))
        h_total = jnp.where(w == count - 1, hk_bar + length_bar[r], 0.0)
        cs_bar = jax.tree_util.tree_map(jnp.add, cs_bar, c_bar)
        return (zk_bar + z_bar[r], ek_bar + e_bar[r], cs_bar, t0_bar + start_bar[r] - h_total, T_bar + h_total)

    zero = jnp.zeros_like(z[0])
    init = (zero, zero, jax.tree_util.tree_map(jnp.zeros_like, consts), jnp.zeros_like(t0), jnp.zeros_like(T))
    z0_bar, _, consts_bar, t0_bar, T_bar = lax.fori_loop(0, count, body, init)
    return consts_bar, z0_bar, t0_bar, T_bar


_adjoint_march.defvjp(_forward, _backward)


def gauss_core(system: HamiltonianSystem, z0: Any, t0: Any, T: Any, *, stages: int, steps: str, rtol: float,
               atol: float, h: float | None, max_windows: int, differentiation: str, max_iterations: int,
               newton: bool, growth: float, safety: float, warmup: int, max_rejects: int) -> TracedSolution:
    """The march of the module docstring from z0 over [t0, T] (traced or not). A march that fails
    or spends ``max_windows`` tries before T raises when it runs (``eqx.error_if``), naming why."""
    z0, t0, T = traced_inputs(system, z0, t0, T)
    static = _Static(int(stages), str(steps), float(rtol), float(atol), None if h is None else float(h),
                     int(max_windows), int(max_iterations), bool(newton), float(growth), float(safety), int(warmup),
                     int(max_rejects))
    if differentiation == "forward":
        out = _march(system, static, z0, t0, T, "lax", True)
    else:
        f1, consts = jax.closure_convert(lambda z: system.vector_field(z[None])[0], z0)
        try:
            out = _adjoint_march(f1, static, system.linear_part, consts, z0, t0, T)
        except TypeError as exc:
            if "forward-mode" not in str(exc):
                raise
            raise ConfigError(FORWARD_NEEDED) from None
        except AssertionError:
            if not system.traced:
                raise
            raise ConfigError(VMAP_CLOSURE) from None
    return _solution(system, stages, t0, T, out)


def compiled_gauss_core(system: HamiltonianSystem, z0: Any, t0: Any, T: Any, **settings: Any) -> TracedSolution:
    """:func:`gauss_core` compiled once per system and settings (static, hashed by identity and
    value): ``jax.grad`` or ``jax.vmap`` of a solve without an outer ``jax.jit`` reuse it and its
    derivative programs instead of tracing the march every call (as Diffrax's ``diffeqsolve``
    does); inside an outer ``jax.jit`` it is inlined. For a system whose H closes over no traced
    value (those cannot be a program's constants)."""
    try:
        return _compiled_core(system, z0, t0, T, tuple(sorted(settings.items())))
    except TypeError as exc:  # jax.jvp of the program: met where the program is differentiated
        if "forward-mode" not in str(exc):
            raise
        raise ConfigError(FORWARD_NEEDED) from None


@eqx.filter_jit
def _compiled_core(system: HamiltonianSystem, z0, t0, T, settings: tuple) -> TracedSolution:
    return gauss_core(system, z0, t0, T, **dict(settings))


def _solution(system: HamiltonianSystem, stages: int, t0, T, out: _Carry) -> TracedSolution:
    """The tries' rows as a TracedSolution, the accepted ones indexed in order; a failed march
    raises at run time."""
    start, length, z, e, L, accepted = out.rows
    budget = start.shape[0]
    position = jnp.arange(budget)
    order = jnp.nonzero(accepted, size=budget, fill_value=0)[0]  # the accepted rows, in order
    count = jnp.sum(accepted)
    st = out.st
    # a budget spent on windows that shrank COLLAPSE-fold below the longest (a kink in H) is said so
    kept = jnp.where(accepted, length, 0.0)
    last = length[order[jnp.maximum(count - 1, 0)]]
    collapsed = (count > 0) & (last * COLLAPSE <= jnp.max(kept))
    code = jnp.where(st.failed > 0, st.failed, jnp.where(st.t < T, jnp.where(collapsed, _BUDGET + 1, _BUDGET), 0))
    messages = ["", *(f"solve (traced core): {FAILURES[k]}" for k in sorted(FAILURES)),
                f"solve (traced core): the window budget, GaussCollocation(max_windows={budget}), was spent before T: "
                "raise max_windows or loosen the tolerance",
                f"solve (traced core): the window budget, GaussCollocation(max_windows={budget}), was spent on windows "
                f"that shrank {COLLAPSE:.0e}-fold or more: H is probably not smooth there (abs, a kink, jnp.where); "
                "smooth it (docs/SOLVER.md, 'Non-smooth Hamiltonians')"]
    starts = eqx.branched_error_if(jnp.where(position < count, start[order], jnp.inf), code > 0, code, messages)
    # the offsets of the starts' float64 numbers (edge_offsets): 0 in exact arithmetic, so no derivative
    gaps = jnp.where(position[1:] < count, length[order][:-1] - (start[order][1:] - start[order][:-1]), 0.0)
    offsets = lax.stop_gradient(jnp.concatenate([jnp.zeros(1, gaps.dtype), jnp.cumsum(gaps)]))
    return TracedSolution(t0, T, starts, offsets, order, length, z, e, L, count, st.rejected, st.iterations, stages,
                          system)

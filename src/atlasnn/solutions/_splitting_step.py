"""One step of an explicit splitting method, in JAX: for a separable H = T(p) + V(q), or for
H = ½ zᵀ S z + N(z) with S's flow and N's declared (a split-step method for a PDE).

A scheme of :mod:`._splitting_tables` is the sequence of exact flows

    B(b_0) A(a_0) B(b_1) A(a_1) … A(a_{m−1}) B(b_m),

A(c) the drift q ← q + c·h·T'(p) and B(c) the kick p ← p − c·h·V'(q). Each flow is exact and
symplectic, so the step is too, for any h. The state is summed with compensation (q + e_q is the
coordinate, e_q what float64 could not hold of it; the same for p), so that a march of millions of
steps gathers round-off like a random walk rather than linearly.

For H = ½ zᵀ S z + N(z) with a declared ``linear_part`` (S) and ``nonlinear_flow`` (N's exact flow),
A(c) is the linear flow exp(c·h·JS) and B(c) N's flow over c·h: the same compositions, the
split-step Fourier method of a PDE at any of their orders.

Forces: a kick needs V'(q) at the current q. A scheme that starts and ends with a kick carries the
last force of a step into the next (first same as last): m evaluations of V' a step. A scheme that
starts with a drift (b_0 = b_m = 0) computes each force after the drift before it.

Everything here is traceable (``jax.jit``, ``jax.grad``, ``jax.vmap``); the march, the dense output
and the traced core all take their steps through :func:`split_step`.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.solutions._splitting_tables import SplittingScheme

__all__ = ["SplitState", "split_step", "start_state", "force", "partial_step", "kick_first", "stability_limit",
           "lax_steps", "linear_splitting", "looped_step", "partial_rate"]


class SplitState(NamedTuple):
    """Where a march stands: q, p with their compensations, and V'(q) (valid for a scheme that
    starts with a kick; unused otherwise)."""

    q: jax.Array
    p: jax.Array
    eq: jax.Array
    ep: jax.Array
    F: jax.Array


def force(system: Any, q: jax.Array, p: jax.Array) -> jax.Array:
    """V'(q) = ∂H/∂q for a separable H (p only completes H's arguments)."""
    return system.dH_dq(q, p)


def velocity(system: Any, q: jax.Array, p: jax.Array) -> jax.Array:
    """T'(p) = ∂H/∂p for a separable H."""
    return system.dH_dp(q, p)


def kick_first(scheme: SplittingScheme) -> bool:
    """Whether the scheme's step begins with a kick (its force then carries over between steps)."""
    return float(scheme.b_f[0]) != 0.0


def _add(x: jax.Array, e: jax.Array, d: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(x, e) + d with compensation: x + e is the value before and after."""
    y = d + e
    s = x + y
    return s, (x - s) + y


def linear_splitting(system: Any) -> bool:
    """Whether ``system`` is split into its linear part's flow and the rest's (a declared
    ``linear_part`` and ``nonlinear_flow``) rather than into T and V."""
    return getattr(system, "linear_part", None) is not None and getattr(system, "nonlinear_flow", None) is not None


def start_state(system: Any, z: jax.Array, e: jax.Array | None = None) -> SplitState:
    """The state a march starts from at z (and its compensation e), with its force (zeros for a
    linear splitting, which has none)."""
    d = system.dim
    e = jnp.zeros_like(z) if e is None else e
    q, p = z[:d], z[d:]
    return SplitState(q, p, e[:d], e[d:], jnp.zeros_like(q) if linear_splitting(system) else force(system, q, p))


def _linear_step(system: Any, scheme: SplittingScheme, st: SplitState, h: jax.Array) -> SplitState:
    """One step with A the linear part's exact flow and B the declared flow of the rest."""
    a, b = scheme.a_f, scheme.b_f
    d = system.dim
    z, e = jnp.concatenate([st.q, st.p]), jnp.concatenate([st.eq, st.ep])
    for i in range(len(a) + 1):
        if b[i] != 0.0:
            z, e = _add(z, e, system.nonlinear_flow(z, b[i] * h) - z)
        if i < len(a) and a[i] != 0.0:
            z, e = _add(z, e, system.linear_part.flow(z, a[i] * h) - z)
    return SplitState(z[:d], z[d:], e[:d], e[d:], st.F)


def split_step(system: Any, scheme: SplittingScheme, st: SplitState, h: jax.Array) -> SplitState:
    """One step of length h (any sign) of ``scheme`` from ``st`` (one state, q and p of shape (d,))."""
    if linear_splitting(system):
        return _linear_step(system, scheme, st, h)
    a, b = scheme.a_f, scheme.b_f
    q, p, eq, ep, F = st
    fresh = kick_first(scheme)  # whether F is V' at the current q
    for i in range(len(a) + 1):
        if b[i] != 0.0:
            if not fresh:
                F, fresh = force(system, q, p), True
            p, ep = _add(p, ep, -(b[i] * h) * F)
        if i < len(a) and a[i] != 0.0:
            q, eq = _add(q, eq, (a[i] * h) * velocity(system, q, p))
            fresh = False
    return SplitState(q, p, eq, ep, F)


def looped_step(system: Any, scheme: SplittingScheme, st: SplitState, h: jax.Array) -> SplitState:
    """:func:`split_step` with its stages in a loop rather than written out: the same operations in
    the same order (the same numbers), a program that compiles in a fraction of the time and runs
    slower on small states — for the dense output, where compiling dominates."""
    if linear_splitting(system):
        return _linear_step(system, scheme, st, h)
    a, b = np.asarray(scheme.a_f), np.asarray(scheme.b_f)
    first = kick_first(scheme)
    q, p, eq, ep, F = st
    if first:
        p, ep = _add(p, ep, -(b[0] * h) * F)
    inner = len(a) if first else len(a) - 1  # a drift-first scheme ends with its last drift alone

    def stage(carry, ab):  # a drift, the force at the new q, the kick after it
        q, p, eq, ep, _ = carry
        q, eq = _add(q, eq, (ab[0] * h) * velocity(system, q, p))
        F = force(system, q, p)
        p, ep = _add(p, ep, -(ab[1] * h) * F)
        return (q, p, eq, ep, F), None

    coefficients = jnp.asarray(np.stack([a[:inner], b[1:inner + 1]], axis=1))
    (q, p, eq, ep, F), _ = jax.lax.scan(stage, (q, p, eq, ep, F), coefficients)
    if not first:
        q, eq = _add(q, eq, (a[-1] * h) * velocity(system, q, p))
        if b[-1] != 0.0:  # an unsymmetric scheme that starts with a drift and ends with a kick
            F = force(system, q, p)
            p, ep = _add(p, ep, -(b[-1] * h) * F)
    return SplitState(q, p, eq, ep, F)


def partial_step(system: Any, scheme: SplittingScheme, z: jax.Array, e: jax.Array, steps: jax.Array,
                 h: jax.Array, tau: jax.Array) -> jax.Array:
    """The dense output: from the state z + e, ``steps`` full steps of length h, then one step of
    length tau of the same method — the state at that time with the method's own accuracy. One
    state; ``steps`` may vary under ``jax.vmap`` (a static 0: no loop)."""
    st = start_state(system, z, e)
    if not (isinstance(steps, int) and steps == 0):
        st = jax.lax.fori_loop(0, steps, lambda _, s: looped_step(system, scheme, s, h), st)
    out = looped_step(system, scheme, st, tau)
    return jnp.concatenate([out.q + out.eq, out.p + out.ep])


def partial_rate(system: Any, scheme: SplittingScheme, z: jax.Array, e: jax.Array, steps: jax.Array,
                 h: jax.Array, tau: jax.Array) -> tuple[jax.Array, jax.Array]:
    """:func:`partial_step` and its rate d/dτ: the derivative of the dense output, which differs
    from J∇H there by the method's defect."""
    return jax.jvp(lambda s: partial_step(system, scheme, z, e, steps, h, s), (tau,), (jnp.ones_like(tau),))


def lax_steps(system: Any, scheme: SplittingScheme, st: SplitState, h: jax.Array, steps: jax.Array) -> SplitState:
    """``steps`` full steps of length h (a loop; ``steps`` may be traced)."""
    return jax.lax.fori_loop(0, steps, lambda _, s: split_step(system, scheme, s, h), st)


def stability_limit(scheme: SplittingScheme) -> float:
    """The scheme's stability limit x* for the harmonic oscillator: its step is stable for h·ω < x*
    (the one-step map's trace within (−2, 2)). A step beyond it makes any mode of frequency ω grow
    exponentially from round-off, however small that mode starts (a chain excited in its slow modes
    blows up in its fast ones)."""
    return _stability_limit(scheme.name, scheme.a_f, scheme.b_f)


@functools.lru_cache(maxsize=None)
def _stability_limit(name: str, a: tuple[float, ...], b: tuple[float, ...]) -> float:
    x = np.linspace(1e-3, 8.0, 16_000)
    M = np.broadcast_to(np.eye(2), (x.size, 2, 2)).copy()
    for i in range(len(a) + 1):  # on (ωq, p): a drift u += c·x·p, a kick p −= c·x·u
        if b[i] != 0.0:
            K = np.zeros((x.size, 2, 2))
            K[:, 0, 0] = K[:, 1, 1] = 1.0
            K[:, 1, 0] = -b[i] * x
            M = K @ M
        if i < len(a) and a[i] != 0.0:
            D = np.zeros((x.size, 2, 2))
            D[:, 0, 0] = D[:, 1, 1] = 1.0
            D[:, 0, 1] = a[i] * x
            M = D @ M
    unstable = np.abs(M[:, 0, 0] + M[:, 1, 1]) >= 2.0 - 1e-9
    return float(x[np.argmax(unstable)]) if unstable.any() else float(x[-1])

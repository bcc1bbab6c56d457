"""The collocation march as one compiled program: windows in a ``lax.while_loop``, each solved by
Gauss–Newton in float64, accepted or rejected by its estimated error, as an adaptive ODE solver
treats a step.

One window (local time s ∈ [0, h], normalised τ = s/h; see :mod:`._features`):

* basis at the P collocation nodes: values B_v = f(s) φ(τ) and rates B_r = ḟ(s) φ(τ) + f(s) φ'(τ)/h,
  so ẑ_i = z_k + W B_v,i and dẑ_i/ds = W B_r,i. With B_r = Q R (thin QR) and V = W Rᵀ the rates are
  V Qᵀ with orthonormal Q, which keeps Gauss–Newton's normal equations well conditioned (their
  matrix is I − h(X + Xᵀ) + O(h²) with X of the size of the window's Lipschitz constant);
* the residual E_i = V Q_i − F(z_k + V C_i) (C = B_v R⁻¹, F = J∇H) is driven to zero by Gauss–Newton
  steps (J has blocks Q_ij I − C_ij A(ẑ_i), A = DF), from the constant-rate guess V Qᵀ = F(z_k) 1ᵀ,
  until the step stops shrinking or falls below round-off;
* its error: δ' = A(ẑ)δ + r along the window (r the residual), integrated by RK4 on a check grid
  finer than the nodes, twice at once: from δ = 0 (the window's local error, which decides
  acceptance against atol + rtol·|z|) and from the δ carried over from the previous window (the
  running a-posteriori estimate of the global error, the linearised estimate of
  :mod:`atlasnn.solutions._estimate` computed on the fly);
* the next length: h · clip(0.8 ε^(−1/q), 0.2, growth) with ε the local error over its tolerance
  (shrunk to at most half on a rejection).

The program marches at most ``chunk`` accepted windows per call and returns; the caller calls it
again from where it stopped, so one program serves every interval length, and progress can be
shown between calls. Its arguments that vary (features, nodes, z, t, T, tolerances) are traced:
a new seed, state or interval reuses the compiled program.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from atlasnn.compile_cache import program_cache
from atlasnn.precision import trace_settings
from atlasnn.solver._exported import exported_program
from atlasnn.solver._features import window_scaling

__all__ = ["MarchState", "ChunkResult", "compiled_march"]


class MarchState(NamedTuple):
    """Where a march stands between calls (float64 arrays)."""

    t: jax.Array
    z: jax.Array
    h: jax.Array
    delta: jax.Array  # the running estimate of z − ẑ at t
    rejected: jax.Array
    newton: jax.Array  # Gauss–Newton iterations, all windows tried
    failed: jax.Array  # 1 once the window length fell below its floor


class ChunkResult(NamedTuple):
    """Up to ``chunk`` accepted windows: their starts, lengths, start states, output weights W
    (2d × M), max ‖δ‖∞ of the running estimate in each, its local error over tolerance; and the
    state after them."""

    count: jax.Array
    start: jax.Array
    length: jax.Array
    z_start: jax.Array
    weights: jax.Array
    est_max: jax.Array
    local_ratio: jax.Array
    state: MarchState


def _basis(features, tau, h, shape, scaling):
    """(values B_v, rates d/ds B_v) of f(s)φ(τ) at normalised times τ: each (len(τ), M)."""
    a, b = features
    s = h * tau
    phi = jnp.tanh(tau[:, None] * a + b)
    dphi = (1.0 - phi ** 2) * a
    f = scaling.value(s, h, shape)[:, None]
    df = scaling.rate(s, h, shape)[:, None]
    return f * phi, df * phi + f * dphi / h


def _window(system, scaling, settings, features, nodes, check, z, h, delta, shape):
    """Solve one window from state z over length h; returns (W, ẑ(h), carried δ, max‖δ‖∞ carried,
    local error over tolerance unscaled (max |δ_loc| per component), Newton iterations)."""
    bv, br = _basis(features, nodes, h, shape, scaling)
    q, r = jnp.linalg.qr(br)
    rinv = jax.scipy.linalg.solve_triangular(r, jnp.eye(r.shape[0], dtype=r.dtype), lower=False)
    v, iters = _gauss_newton(system, settings, q, bv @ rinv, z)
    zc, dd, path = _window_error(system, scaling, settings, features, check, rinv, v, z, h, delta, shape)
    w = (rinv @ v.T).T
    return w, zc[-1], dd[:, 0], jnp.max(path[:, :, 0]), jnp.max(path[:, :, 1], axis=0), iters


def _gauss_newton(system, settings, q, c, z):
    """The window's unknowns V (2d × M) with rates V Qᵀ and values z + V Cᵀ at the nodes, from the
    constant-rate guess, by Gauss–Newton on the residual; returns (V, iterations)."""
    n = z.shape[0]
    field, jac = system.vector_field, system.jacobian
    v = field(z[None])[0][:, None] * jnp.sum(q, axis=0)[None, :]

    def normal_matrix(zz):
        # JᵀJ of J[(i,a),(b,j)] = δ_ab Q_ij − A_i[a,b] C_ij from its Kronecker structure (QᵀQ = I):
        # JᵀJ = I − X − Xᵀ + Y, X[b,j,c,k] = Σ_i Q_ij A_i[b,c] C_ik, Y = Σ_i C_ij (A_iᵀA_i)[b,c] C_ik
        a = jac(zz)
        x = jnp.einsum("ij,ibc,ik->bjck", q, a, c).reshape(v.size, v.size)
        y = jnp.einsum("ij,ibc,ik->bjck", c, jnp.einsum("iab,iac->ibc", a, a), c).reshape(v.size, v.size)
        return a, jnp.linalg.cholesky(jnp.eye(v.size, dtype=z.dtype) - x - x.T + y)

    def step(carry):
        v, it, dn, prev, a, chol = carry
        zz = z + c @ v.T
        e = q @ v.T - field(zz)
        # a fresh Jacobian for the first iterations, then the last one kept (simplified Newton:
        # one factorisation serves the rest)
        a, chol = lax.cond(it < settings["fresh"], normal_matrix, lambda _: (a, chol), zz)
        rhs = (q.T @ e).T - jnp.einsum("ij,iab,ia->bj", c, a, e)  # Jᵀe, (b, j)
        d = jax.scipy.linalg.cho_solve((chol, True), -rhs.reshape(-1))
        return v + d.reshape(v.shape), it + 1, jnp.max(jnp.abs(d)), dn, a, chol

    def going(carry):
        v, it, dn, prev = carry[:4]
        floor = settings["newton_tol"] * (1.0 + jnp.max(jnp.abs(v)))
        stalled = (it >= 3) & (dn > 0.5 * prev) & (dn < 1e-9 * (1.0 + jnp.max(jnp.abs(v))))
        return (it < settings["max_newton"]) & (dn > floor) & ~stalled & ((it == 0) | jnp.isfinite(dn))

    inf = jnp.asarray(jnp.inf, z.dtype)
    start = (v, 0, inf, inf, jnp.zeros((q.shape[0], n, n), z.dtype), jnp.eye(v.size, dtype=z.dtype))
    return lax.while_loop(going, step, start)[:2]


def _window_error(system, scaling, settings, features, check, rinv, v, z, h, delta, shape):
    """The error along the window: RK4 on δ' = Aδ + r over the check grid — 2K + 1 points τ(u) at
    u = 0, 1/2K, …, 1 with their rates τ'(u) (uniform: τ = u; Chebyshev: finer near the ends), K
    steps in u — for δ carried in and for δ = 0 at once; returns (ẑ on the grid, δ at the end
    (2d, 2), |δ| along the grid (K, 2d, 2))."""
    tau_c, speed = check
    cv, cr = _basis(features, tau_c, h, shape, scaling)
    zc = z + (cv @ rinv) @ v.T
    res = (cr @ rinv) @ v.T - system.vector_field(zc)
    ac = system.jacobian(zc)
    steps = (tau_c.shape[0] - 1) // 2
    du = 1.0 / steps

    def rk4(dd, i):
        j = 2 * i
        g = lambda k, x: (h * speed[k]) * (ac[k] @ x + res[k][:, None])  # noqa: E731
        k1 = g(j, dd)
        k2 = g(j + 1, dd + 0.5 * du * k1)
        k3 = g(j + 1, dd + 0.5 * du * k2)
        k4 = g(j + 2, dd + du * k3)
        dd = dd + du / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return dd, jnp.abs(dd)

    d0 = jnp.stack([delta, jnp.zeros_like(delta)], axis=1)
    dd, path = lax.scan(rk4, d0, jnp.arange(steps), unroll=settings["unroll"])
    return zc, dd, path


def _first_length(system, z, span):
    """A first window length from the vector field's Jacobian at z: 1/‖A‖ (at most the interval)."""
    a = system.jacobian(z[None])[0]
    return jnp.minimum(span, 1.0 / jnp.maximum(jnp.linalg.norm(a, 2), 1e-300))


@program_cache
@functools.lru_cache(maxsize=32)
def _cached(system, scaling_name, chunk, max_newton, newton_tol, fresh, unroll, order, growth, max_rejects, safety,
            settings_key):
    scaling = window_scaling(scaling_name)
    settings = {"max_newton": max_newton, "newton_tol": newton_tol, "fresh": fresh, "unroll": unroll}

    def run(features, nodes, check, shape, state: MarchState, T, rtol, atol):
        n = state.z.shape[0]
        m = features[0].shape[0]
        dt = state.z.dtype
        buf = (jnp.zeros(chunk, dt), jnp.zeros(chunk, dt), jnp.zeros((chunk, n), dt), jnp.zeros((chunk, n, m), dt),
               jnp.zeros(chunk, dt), jnp.zeros(chunk, dt))
        span = T - state.t
        # the first length from the Jacobian only on the first call (later calls carry theirs)
        h0 = lax.cond(state.h > 0, lambda: state.h, lambda: _first_length(system, state.z, span))
        floor = 1e-12 * jnp.maximum(jnp.abs(T), 1.0)

        def going(c):
            k, st, streak, _ = c
            return (st.t < T) & (k < chunk) & (st.failed == 0)

        def body(c):
            k, st, streak, buf = c
            last = st.t + st.h >= T - floor
            h = jnp.where(last, T - st.t, st.h)
            w, z1, d1, est, loc, it = _window(system, scaling, settings, features, nodes, check, st.z, h,
                                               st.delta, shape)
            tol = atol + rtol * jnp.maximum(jnp.abs(st.z), jnp.abs(z1))
            ratio = safety * jnp.max(loc / tol)
            ok = jnp.isfinite(ratio) & (ratio <= 1.0) & jnp.all(jnp.isfinite(z1))
            fac = jnp.clip(0.8 * ratio ** (-1.0 / order), 0.2, growth)
            fac = jnp.where(jnp.isfinite(fac), fac, 0.2)
            fac = jnp.where(ok, fac, jnp.minimum(fac, 0.5))
            h_next = jnp.where(ok & last, st.h, h * fac)  # the clipped last window does not set the length
            streak = jnp.where(ok, 0, streak + 1)
            failed = ((h_next < floor) | (streak > max_rejects)).astype(st.failed.dtype)
            rows = (st.t, h, st.z, w, est, ratio)
            buf = tuple(jnp.where(ok, b.at[k].set(x), b) for b, x in zip(buf, rows))
            new = MarchState(jnp.where(ok, jnp.where(last, T, st.t + h), st.t), jnp.where(ok, z1, st.z), h_next,
                             jnp.where(ok, d1, st.delta), st.rejected + (~ok).astype(st.rejected.dtype),
                             st.newton + it, jnp.where(ok, 0, failed))
            return k + ok.astype(k.dtype), new, streak, buf

        start = (jnp.asarray(0), state._replace(h=h0), jnp.asarray(0), buf)
        k, st, _, buf = lax.while_loop(going, body, start)
        return ChunkResult(k, *buf, st)

    # members (seeds and initial states) on a leading axis: one program marches them all, each with
    # windows of its own (the loop runs until the last member is done); one member alone runs the
    # plain loop (the batched program costs twice the compilation for nothing)
    batched = jax.vmap(run, in_axes=(0, None, None, None, 0, None, None, None))

    def alone(features, nodes, check, shape, state, T, rtol, atol):
        one = jax.tree_util.tree_map(lambda x: x[0], (features, state))
        out = run(one[0], nodes, check, shape, one[1], T, rtol, atol)
        return jax.tree_util.tree_map(lambda x: x[None], out)

    return jax.jit(batched), jax.jit(alone)


#: the tree of a program's result (a ChunkResult holding a MarchState), for its exported form
_OUT_TREE = jax.tree_util.tree_structure(
    ChunkResult(*([0] * (len(ChunkResult._fields) - 1)), MarchState(*([0] * len(MarchState._fields)))))


def compiled_march(system: Any, scaling: str, *, chunk: int, max_newton: int, newton_tol: float, fresh: int,
                   unroll: int, order: float, growth: float, max_rejects: int, safety: float, members: int):
    """The compiled march for a system and these settings, over ``members`` members (features and
    state with a leading axis, also for one); one program per shape, cached, keyed also by the
    trace settings so that a program traced under others is never reused; served from its
    exported form on disk where the system qualifies (:mod:`._exported`)."""
    settings = (scaling, int(chunk), int(max_newton), float(newton_tol), int(fresh), int(unroll), float(order),
                float(growth), int(max_rejects), float(safety), trace_settings())
    jitted = _cached(system, *settings)[int(members == 1)]
    return exported_program(jitted, system, {"settings": settings, "alone": members == 1}, _OUT_TREE)

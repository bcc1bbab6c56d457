"""The linearised error equation of an approximate solution of Hamilton's equations, integrated.

For dz/dt = f(z) = J∇H(z) and an approximation ẑ with residual r = dẑ/dt − f(ẑ), the error
e = z − ẑ obeys e' = f(ẑ + e) − f(ẑ) − r exactly. Linearised about ẑ:

    δ' = A(t) δ − r(t),    A(t) = Df(ẑ(t)) = J∇²H(ẑ(t)),    δ(t0) = z0 − ẑ(t0),          (1)

exact for a quadratic H (a linear f). A time-marching solution jumps by j_k = ẑ(t_k⁺) − ẑ(t_k⁻)
at a window edge (float rounding) while z is continuous, so δ(t_k⁺) = δ(t_k⁻) − j_k.

Everything here works on arrays sampled on a grid, in float64; nothing needs the solution
classes. Grid layout: one RK4 step spans two equal grid intervals, the middle sample being the
step's midpoint, so each segment holds an odd number of samples t_0, t_½, t_1, …; a time that
appears twice in a row is a window edge (left limit, then right limit). RK4 was chosen by
measurement against 4th-order Magnus, implicit midpoint and the trapezoidal rule on trained
networks (docs/ESTIMATE.md): as accurate as Magnus at an eighth of the cost, and 30–100× fewer
steps than the second-order rules for the same accuracy. Each step of (1) is an affine map
y ↦ M_n y + c_n; all maps are built at once with batched linear algebra and only the
recurrence over n runs in a loop.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import program_cache

__all__ = ["residual_and_jacobian", "propagate", "segments", "steps_for", "residual_bandwidth", "segment_bandwidths",
           "dense_grid", "MAX_STEPS_PER_WINDOW", "ESTIMATE_MEMORY_BYTES", "max_total_steps"]


#: rows per compiled call of the estimate's evaluations (network samples, field and Jacobian)
CHUNK = 1024


@program_cache
@functools.lru_cache(maxsize=64)
def _compiled_field(system: Any):
    """jit-compiled z ↦ (f(z), Df(z)) for a batch z of shape (N, 2d), traced in float64."""
    d = int(system.dim)

    def h(z):
        return jnp.asarray(system.hamiltonian(z[:d], z[d:])).reshape(())

    def field(z):
        g = jax.grad(h)(z)
        return jnp.concatenate([g[d:], -g[:d]])

    return jax.jit(jax.vmap(lambda z: (field(z), jax.jacfwd(field)(z))))


def residual_and_jacobian(system: Any, z: Any, dz: Any) -> tuple[np.ndarray, np.ndarray]:
    """r = dẑ/dt − J∇H(ẑ) of shape (N, 2d) and A = D(J∇H)(ẑ) of shape (N, 2d, 2d), in float64,
    from samples z, dz of ẑ and dẑ/dt (any float dtype: promoted to float64 first)."""
    z = np.asarray(z, dtype=np.float64)
    dz = np.asarray(dz, dtype=np.float64)
    m = 2 * int(system.dim)
    if z.ndim != 2 or z.shape[1] != m or dz.shape != z.shape:
        raise ValueError(f"z and dz must both have shape (N, {m}), got {z.shape} and {dz.shape}")
    n = z.shape[0]
    # CHUNK rows a call, the last chunk padded with the last state: one compiled program for every
    # grid size (each row is computed on its own, so the values do not depend on the chunking)
    size = max(-(-n // CHUNK), 1) * CHUNK
    zp = np.concatenate([z, np.repeat(z[-1:], size - n, axis=0)]) if size > n else z
    field = _compiled_field(system)
    with jax.enable_x64(True), np.errstate(all="ignore"):
        parts = [field(jax.device_put(zp[i:i + CHUNK])) for i in range(0, size, CHUNK)]
        f = np.concatenate([np.asarray(p[0], dtype=np.float64) for p in parts])[:n]
        a = np.concatenate([np.asarray(p[1], dtype=np.float64) for p in parts])[:n]
    return dz - f, a


def _rk4_maps(h, a0, am, a1, r0, rm, r1):
    """One classical RK4 step of (1) per row, as y ↦ M y + c (stages at t, t + h/2 twice, t + h)."""
    eye = np.eye(a0.shape[-1])
    hh = (0.5 * h)[:, None, None]
    hv = (0.5 * h)[:, None]
    k1, k1c = a0, -r0
    y2, y2c = eye + hh * a0, hv * (-r0)
    k2, k2c = am @ y2, np.einsum("nij,nj->ni", am, y2c) - rm
    y3, y3c = eye + hh * k2, hv * k2c
    k3, k3c = am @ y3, np.einsum("nij,nj->ni", am, y3c) - rm
    y4, y4c = eye + 2 * hh * k3, 2 * hv * k3c
    k4, k4c = a1 @ y4, np.einsum("nij,nj->ni", a1, y4c) - r1
    w = h / 6.0
    return eye + w[:, None, None] * (k1 + 2 * k2 + 2 * k3 + k4), w[:, None] * (k1c + 2 * k2c + 2 * k3c + k4c)


def segments(t: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges between repeated times (window edges)."""
    cut = np.nonzero(np.diff(t) == 0)[0]
    starts = np.concatenate([[0], cut + 1])
    stops = np.concatenate([cut + 1, [t.size]])
    return list(zip(starts.tolist(), stops.tolist()))


def _check_grid(t: np.ndarray) -> list[tuple[int, int]]:
    if t.ndim != 1 or t.size < 3 or not np.all(np.isfinite(t)):
        raise ValueError("t must be a finite 1-D array of at least 3 times")
    dt = np.diff(t)
    if np.any(dt < 0) or np.any((dt[1:] == 0) & (dt[:-1] == 0)):
        raise ValueError("t must be non-decreasing, a time repeated at most once (a window edge)")
    segs = segments(t)
    for a, b in segs:
        tt = t[a:b]
        if tt.size < 3 or tt.size % 2 == 0:
            raise ValueError(f"every segment needs an odd number (>= 3) of samples, got {tt.size} in "
                             f"[{tt[0]:.6g}, {tt[-1]:.6g}]")
        if np.any(np.abs(tt[1::2] - 0.5 * (tt[:-1:2] + tt[2::2])) > 1e-3 * (tt[2::2] - tt[:-1:2])):
            raise ValueError("every odd sample must be the midpoint of its step")
    return segs


def _affine_recurrence(M: np.ndarray, c: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """y_0 = y0, y_{n+1} = M_n y_n + c_n; returns (n + 1, m)."""
    out = np.empty((c.shape[0] + 1, c.shape[1]))
    out[0] = y = y0
    for i in range(c.shape[0]):
        y = M[i] @ y + c[i]
        out[i + 1] = y
    return out


def propagate(t: Any, A: Any, r: Any, *, jumps: Any = None, y0: Any = None):
    """Integrate y' = A(t) y − r(t), y(t[0]) = y0 (default 0), by RK4 on the grid ``t``.

    At a window edge (a repeated time) y jumps by −jumps[k] instead. Returns (node times, y at
    the nodes, the nodes' indices into t); nodes are every other sample of each segment.
    """
    t = np.asarray(t, dtype=np.float64)
    A = np.asarray(A, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    segs = _check_grid(t)
    m = r.shape[-1]
    if A.shape != (t.size, m, m) or r.shape != (t.size, m):
        raise ValueError(f"A and r must have shapes (N, m, m) and (N, m); got {A.shape}, {r.shape} for N={t.size}")
    jumps = np.zeros((len(segs) - 1, m)) if jumps is None else np.asarray(jumps, np.float64).reshape(-1, m)
    y = np.zeros(m) if y0 is None else np.asarray(y0, dtype=np.float64).reshape(m)
    t_out, y_out, i_out = [], [], []
    for k, (a, b) in enumerate(segs):
        if k > 0:
            y = y - jumps[k - 1]
        i0 = np.arange(a, b - 1, 2)
        M, c = _rk4_maps(t[i0 + 2] - t[i0], A[i0], A[i0 + 1], A[i0 + 2], r[i0], r[i0 + 1], r[i0 + 2])
        with np.errstate(over="ignore", invalid="ignore"):  # an estimate that overflows is inf: failed
            ys = _affine_recurrence(M, c, y)
        y = ys[-1]
        nodes = np.arange(a, b, 2)
        t_out.append(t[nodes])
        y_out.append(ys)
        i_out.append(nodes)
    return np.concatenate(t_out), np.concatenate(y_out), np.concatenate(i_out)


#: The grid rule's constants (docs/ESTIMATE.md, "grid"): RK4 steps h ≤ 1/64 and h·ω_c ≤ 0.5.
STEPS_PER_UNIT_TIME = 64
STEP_TIMES_OMEGA = 0.5
MIN_STEPS_PER_WINDOW = 128
#: the most RK4 steps of one window, and the memory all windows' steps may take together (the
#: samples, Jacobians and step maps of the grid, float64): a grid that would need more is left
#: coarser and the estimate marked not converged, instead of running out of memory
MAX_STEPS_PER_WINDOW = 1 << 16
ESTIMATE_MEMORY_BYTES = 1 << 30


def max_total_steps(state_dim: int) -> int:
    """The most RK4 steps of a whole grid for a state of ``state_dim`` components (about 6
    (2d)²-matrices and 10 vectors of float64 per step), from :data:`ESTIMATE_MEMORY_BYTES`."""
    return max(MIN_STEPS_PER_WINDOW, ESTIMATE_MEMORY_BYTES // (8 * (6 * state_dim**2 + 10 * state_dim)))


def steps_for(length: float, omega_c: float | None = None) -> int:
    """RK4 steps for a window: max(128, ⌈64·length⌉, ⌈length·ω_c/0.5⌉), ω_c the residual's bandwidth
    if known, at most :data:`MAX_STEPS_PER_WINDOW`. Measured on trained sin networks: h·ω_c = 0.5
    leaves a relative quadrature error ≤ 3e-4 in δ, h·ω_c = 1 about 5e-3."""
    n = max(MIN_STEPS_PER_WINDOW, math.ceil(STEPS_PER_UNIT_TIME * float(length)))
    if omega_c is not None and omega_c > 0:
        n = max(n, math.ceil(float(length) * float(omega_c) / STEP_TIMES_OMEGA))
    return int(min(n, MAX_STEPS_PER_WINDOW))


def segment_bandwidths(t: Any, r: Any, quantile: float = 0.9999) -> list[float]:
    """Per segment (window) of a uniformly sampled grid, ω_c: the angular frequency below which
    ``quantile`` of the residual's energy lies (0 where it cannot be told). The Hann taper
    matters: a window's residual is not periodic, and untapered the jump between its ends leaks
    power everywhere."""
    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    out = []
    for a, b in segments(t):
        n = b - a
        rk = r[a:b] - r[a:b].mean(0)
        power = (np.abs(np.fft.rfft(rk * np.hanning(n)[:, None], axis=0)) ** 2).sum(1) if n >= 8 else np.zeros(1)
        if not power.sum() > 0 or not np.isfinite(power.sum()):
            out.append(0.0)
            continue
        omega = 2 * np.pi * np.fft.rfftfreq(n, d=(t[b - 1] - t[a]) / (n - 1))
        share = np.cumsum(power) / power.sum()
        out.append(float(omega[min(np.searchsorted(share, quantile), omega.size - 1)]))
    return out


def residual_bandwidth(t: Any, r: Any, quantile: float = 0.9999) -> float:
    """ω_c of the whole grid: the largest of :func:`segment_bandwidths`."""
    return max(segment_bandwidths(t, r, quantile), default=0.0)


def dense_grid(edges: Any, steps: int | list[int]) -> np.ndarray:
    """The grid over windows [edges[k], edges[k+1]]: 2·steps + 1 samples each, interior edges twice."""
    edges = np.asarray(edges, dtype=np.float64)
    if edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError("edges must be increasing, at least two of them")
    nw = edges.size - 1
    steps = [int(steps)] * nw if np.ndim(steps) == 0 else [int(s) for s in steps]
    parts = []
    for k in range(nw):
        g = np.linspace(edges[k], edges[k + 1], 2 * steps[k] + 1)
        g[-1] = edges[k + 1]
        parts.append(g)
    return np.concatenate(parts)

"""Collocation times: a uniform grid on [t0, T], jittered afresh every epoch.

Each epoch draws t_n = g_n + Δt·σ·ε_n from the base grid g (ε ~ N(0, 1), Δt the grid spacing),
the release's scale convention: σ is in units of Δt. Points that leave [t0, T] are reflected
back (t < t0 → 2t0 − t, t > T → 2T − t), repeatedly if the jitter is larger than the interval.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from atlasnn.errors import ConfigError


def check_interval(t0: float, T: float, n_points: int) -> None:
    """One-line errors for a bad interval or point count."""
    if not (math.isfinite(t0) and math.isfinite(T)) or T <= t0:
        raise ConfigError(f"interval must satisfy t0 < T (finite), got t0={t0!r}, T={T!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 2:
        raise ConfigError(f"number of collocation points K must be an integer >= 2, got {n_points!r}")


def uniform_grid(t0: float, T: float, n_points: int, dtype=None) -> jax.Array:
    """K equally spaced times from t0 to T inclusive."""
    check_interval(t0, T, n_points)
    return jnp.linspace(t0, T, n_points, dtype=dtype)


def reflect_into(t: jax.Array, t0: float, T: float) -> jax.Array:
    """Fold t into [t0, T] by mirror reflection at both ends (a triangle wave)."""
    length = T - t0
    u = jnp.mod(t - t0, 2 * length)
    return t0 + jnp.where(u > length, 2 * length - u, u)


def jittered(grid: jax.Array, key: jax.Array, sigma: float | jax.Array, t0: float, T: float) -> jax.Array:
    """The grid moved by N(0, (Δt·σ)²) noise per point and reflected into [t0, T]."""
    dt = (T - t0) / (grid.shape[0] - 1)
    noise = jax.random.normal(key, grid.shape, grid.dtype) * (dt * sigma)
    return reflect_into(grid + noise, t0, T)


def with_release_fixed_point(t: jax.Array, t0: float, T: float) -> jax.Array:
    """The authors' release's quirk: every epoch its third collocation time is set to t0 − 1
    before the reflection, so one point always sits at t0 + 1 (when T − t0 ≥ 1)."""
    return t.at[2].set(reflect_into(jnp.asarray(t0 - 1.0, t.dtype), t0, T))

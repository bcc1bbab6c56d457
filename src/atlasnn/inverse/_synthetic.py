"""Synthetic observations: noisy samples of some state components along a reference trajectory."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.evaluation import reference_solution
from atlasnn.observations import Observations
from atlasnn.systems import HamiltonianSystem

__all__ = ["synthetic_observations", "finite_number"]


def synthetic_observations(system: HamiltonianSystem, z0: Any, times: Any, names: Sequence[str], noise: float,
                           seed: int, *, t0: float = 0.0) -> Observations:
    """Noisy samples of some state components along the reference trajectory.

    The reference solution (DOP853, rtol = atol = 1e-12) from ``z0`` at ``t0`` (default 0, where the
    fits start) with the system's own parameters, plus to component c Gaussian noise of standard
    deviation ``noise × RMS_c`` (RMS_c = sqrt(mean of z_c(t_i)²) over the times: ``noise=0.01`` is
    "1 % noise"), drawn from ``numpy.random.default_rng(seed)``.

    Args:
        system: the Hamiltonian system (its parameters are the truth).
        z0: the state at t0, or ``None`` for the system's default.
        times: strictly increasing, finite 1-D times (at least 2), all ≥ t0.
        names: the observed state components, e.g. ``["x"]``.
        noise: the relative noise level, finite and ≥ 0.
        seed: the seed of the noise generator (equal seeds give equal data).
    """
    if not isinstance(system, HamiltonianSystem):
        raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    t = _times(times, "times")
    start = finite_number(t0, "t0")
    if start > t[0]:
        raise ConfigError(f"t0={start!r} lies after the first time {float(t[0])!r}")
    level = finite_number(noise, "noise")
    if level < 0:
        raise ConfigError(f"noise must be ≥ 0 (a fraction of each component's RMS), got {noise!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ConfigError(f"seed must be an integer, got {seed!r}")
    probe = Observations(t=t, values=np.zeros((t.size, len(names))), names=tuple(names), source="synthetic")
    idx = probe.indices(system.state_names)
    grid = t if start == t[0] else np.concatenate([[start], t])
    clean = reference_solution(system, z0, grid)[grid.size - t.size:, idx]
    rms = np.sqrt(np.mean(clean**2, axis=0))
    rng = np.random.default_rng(int(seed))
    values = clean + level * rms * rng.standard_normal(clean.shape)
    return Observations(t=t, values=values, names=probe.names, source="synthetic")


def finite_number(value: Any, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise ConfigError(f"{what} must be a finite number, got {value!r}")
    return v


def _times(times: Any, what: str) -> np.ndarray:
    try:
        t = np.asarray(times, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a 1-D array of numbers") from None
    if t.ndim != 1 or t.size < 2:
        raise ConfigError(f"{what} must be a 1-D array of at least 2 times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ConfigError(f"{what} must be finite, {int(np.sum(~np.isfinite(t)))} entries are not")
    if not np.all(np.diff(t) > 0):
        i = int(np.argmax(~(np.diff(t) > 0)))
        raise ConfigError(f"{what} must be strictly increasing, got {what}[{i}]={float(t[i])!r} >= "
                          f"{what}[{i + 1}]={float(t[i + 1])!r}")
    return t

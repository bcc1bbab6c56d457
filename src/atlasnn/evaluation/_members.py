"""References for many members of a family (z0_i, θ_i): one DOP853 solve each, on one compiled
right-hand side f(z, θ) with θ an argument (nothing recompiles from member to member)."""

from __future__ import annotations

from typing import Any

import numpy as np

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.evaluation._integrators import REFERENCE_ATOL, REFERENCE_RTOL
from atlasnn.evaluation._parametric import ParametricSolveFailed, solve_parametric
from atlasnn.systems import BundleBox, HamiltonianSystem

__all__ = ["reference_members"]


def reference_members(system: HamiltonianSystem, box: BundleBox, z0: Any, lam: Any, t: Any,
                      rtol: float = REFERENCE_RTOL, atol: float = REFERENCE_ATOL) -> np.ndarray:
    """Reference trajectories (N, T, 2d) of members z0 (N, 2d), λ (N, P) of ``box``'s varying
    parameters, at times t (T,) from ``box.t0`` (DOP853, float64)."""
    z0 = np.asarray(z0, np.float64).reshape(-1, system.state_dim)
    theta = box.full_theta(system, lam)
    t = np.asarray(t, np.float64).reshape(-1)
    if theta.shape[0] != z0.shape[0]:
        raise ConfigError(f"reference_members: {z0.shape[0]} initial states but {theta.shape[0]} parameter rows")
    if system.params:
        system.require_parametric("reference_members")
    out = np.empty((z0.shape[0], t.size, system.state_dim))
    for i in range(z0.shape[0]):
        try:
            out[i] = solve_parametric(system, z0[i], theta[i], box.t0, t, rtol, atol)[0]
        except ParametricSolveFailed as exc:
            raise AtlasError(f"reference of member {i} (z0 = {z0[i].tolist()}) failed: {exc}") from None
    return out

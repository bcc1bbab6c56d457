"""The time scale of an inverse problem's dynamics: the field's Jacobian norm over the unknowns' range."""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.observations import INITIAL_STATE_PREFIX, Unknown
from atlasnn.systems import HamiltonianSystem, parametric_field

__all__ = ["field_scale"]


def field_scale(system: HamiltonianSystem, unknowns: Sequence[Unknown], z0: np.ndarray) -> float:
    """‖A‖₂ with A = D(J∇H) at z0 (its unknown components at their guesses), the largest over the
    unknown parameters at their guesses, lows and highs: 1/‖A‖ is the time over which the orbit
    changes, whatever the guess (windows and segments are cut from it)."""
    field = parametric_field(system)
    params = [u for u in unknowns if not u.name.startswith(INITIAL_STATE_PREFIX)]
    state = np.array(z0, np.float64)
    for u in unknowns:
        if u.name.startswith(INITIAL_STATE_PREFIX):
            state[system.state_names.index(u.name[len(INITIAL_STATE_PREFIX):])] = u.guess

    norm = 0.0
    with jax.enable_x64(True):
        for pick in ("guess", "low", "high"):
            theta = jnp.asarray(system.param_vector(**{u.name: getattr(u, pick) for u in params}))
            norm = max(norm, float(np.linalg.norm(np.asarray(jax.jacfwd(field)(jnp.asarray(state), theta)), 2)))
    return norm

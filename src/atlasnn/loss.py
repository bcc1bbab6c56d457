"""The physics loss: Hamilton's-equation residual plus an energy penalty (no data).

At collocation times t_1..t_K,

    L = (1/K) Σ_n ‖dẑ/dt(t_n) − J∇H(ẑ(t_n))‖²  +  λ_reg · (1/K) Σ_n (H(ẑ(t_n)) − E0)²,

with E0 = H(z0). The first term equals the release's mean(r_q1²) + … + mean(r_pd²).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from atlasnn.model import TrialSolution
from atlasnn.systems import HamiltonianSystem


def hamilton_residual(model: TrialSolution, system: HamiltonianSystem, t: jax.Array):
    """r(t_n) = dẑ/dt(t_n) − J∇H(ẑ(t_n)); returns (r, ẑ), each (K, 2d)."""
    z, dz = model.value_and_rate(t)
    return dz - system.vector_field(z), z


def physics_loss(
    model: TrialSolution, system: HamiltonianSystem, t: jax.Array, energy0: jax.Array, lam_reg: jax.Array
) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
    """(L, (residual term, energy penalty)) at collocation times t; see the module docstring."""
    r, z = hamilton_residual(model, system, t)
    residual = jnp.mean(jnp.sum(r**2, axis=-1))
    energy_penalty = jnp.mean((system.energy(z) - energy0) ** 2)
    return residual + lam_reg * energy_penalty, (residual, energy_penalty)

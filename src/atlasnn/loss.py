"""The physics loss: Hamilton's-equation residual plus an energy penalty (no data).

At collocation times t_1..t_K,

    L = (1/K) Σ_n ‖dẑ/dt(t_n) − J∇H(ẑ(t_n))‖²  +  λ_reg · (1/K) Σ_n (H(ẑ(t_n)) − E0)²,

with E0 = H(z0). The first term equals the release's mean(r_q1²) + … + mean(r_pd²).

H(ẑ(t_n)) and ∇H(ẑ(t_n)) come from one reverse pass through the batched energy: each H(z_n)
depends on z_n alone, so the gradient of Σ_n H(z_n) with respect to z is the stack of the ∇H(z_n)
(for any user Hamiltonian, not only the built-ins).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from atlasnn.model import TrialSolution
from atlasnn.systems import HamiltonianSystem


def energy_and_vector_field(system: HamiltonianSystem, z: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(H(z_n), J∇H(z_n)) for states z of shape (K, 2d), by one vjp of the batched energy."""
    energy, pullback = jax.vjp(system.energy, z)
    (grad,) = pullback(jnp.ones_like(energy))
    d = system.dim
    return energy, jnp.concatenate([grad[..., d:], -grad[..., :d]], axis=-1)


def _residual_and_energy(model: TrialSolution, system: HamiltonianSystem, t: jax.Array):
    z, dz = model.value_and_rate(t)
    energy, field = energy_and_vector_field(system, z)
    return dz - field, z, energy


def hamilton_residual(model: TrialSolution, system: HamiltonianSystem, t: jax.Array):
    """r(t_n) = dẑ/dt(t_n) − J∇H(ẑ(t_n)); returns (r, ẑ), each (K, 2d)."""
    r, z, _ = _residual_and_energy(model, system, t)
    return r, z


def physics_loss(
    model: TrialSolution, system: HamiltonianSystem, t: jax.Array, energy0: jax.Array, lam_reg: jax.Array
) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
    """(L, (residual term, energy penalty)) at collocation times t; see the module docstring."""
    r, _, energy = _residual_and_energy(model, system, t)
    residual = jnp.mean(jnp.sum(r**2, axis=-1))
    energy_penalty = jnp.mean((energy - energy0) ** 2)
    return residual + lam_reg * energy_penalty, (residual, energy_penalty)

"""The physics loss: Hamilton's-equation residual plus an energy penalty (no data).

At collocation times t_1..t_K,

    L = (1/K) Σ_n ‖dẑ/dt(t_n) − J∇H(ẑ(t_n))‖²  +  λ_reg · (1/K) Σ_n (H(ẑ(t_n)) − E0)²,

with E0 = H(z0). The first term equals the release's mean(r_q1²) + … + mean(r_pd²).

H(ẑ(t_n)) and ∇H(ẑ(t_n)) come from one reverse pass through the batched energy: each H(z_n)
depends on z_n alone, so the gradient of Σ_n H(z_n) with respect to z is the stack of the ∇H(z_n)
(for any user Hamiltonian, not only the built-ins).

Causal weighting (optional; Wang, Sankaran & Perdikaris, "Respecting causality is all you need
for training physics-informed neural networks", 2022): with the collocation times sorted,
t_1 < … < t_K, and the per-point loss L_n = ‖r(t_n)‖² + λ_reg (H(ẑ(t_n)) − E0)², the objective is

    L_causal = (1/K) Σ_n w_n L_n,   w_n = exp(−ε Σ_{m<n} L_m Δt),

with Δt = (T − t0)/(K − 1), so the exponent is ε times the loss integrated over [t0, t_n): a point
is weighted down until the residual before it has been driven to zero. The weights carry no
gradient. ε = 0 gives the plain loss.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from atlasnn.nn import TrialSolution
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


def point_losses(
    model: TrialSolution, system: HamiltonianSystem, t: jax.Array, energy0: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Per collocation time: (‖r(t_n)‖², (H(ẑ(t_n)) − E0)²), each of shape (K,)."""
    r, _, energy = _residual_and_energy(model, system, t)
    return jnp.sum(r**2, axis=-1), (energy - energy0) ** 2


def causal_weights(point_loss: jax.Array, dt: jax.Array | float, eps: jax.Array | float) -> jax.Array:
    """w_n = exp(−ε Σ_{m<n} L_m Δt) for per-point losses L ordered in time (no gradient).

    w_1 = 1 always, and w_n = 1 wherever every earlier point has zero loss.
    """
    before = jnp.cumsum(point_loss) - point_loss  # Σ_{m<n} L_m (exclusive prefix sum)
    return jax.lax.stop_gradient(jnp.exp(-eps * dt * before))


def causal_physics_loss(
    model: TrialSolution, system: HamiltonianSystem, t_sorted: jax.Array, energy0: jax.Array,
    lam_reg: jax.Array, eps: jax.Array, dt: jax.Array,
) -> tuple[jax.Array, tuple[jax.Array, jax.Array, jax.Array]]:
    """(L_causal, (L, residual term, energy penalty)) at increasing times ``t_sorted``.

    The first value is the objective to differentiate; the others are the unweighted physics loss
    and its two parts (what is recorded, compared with the tolerance and used by the best rule).
    """
    res, en = point_losses(model, system, t_sorted, energy0)
    per_point = res + lam_reg * en
    w = causal_weights(per_point, dt, eps)
    residual, energy_penalty = jnp.mean(res), jnp.mean(en)
    return jnp.mean(w * per_point), (residual + lam_reg * energy_penalty, residual, energy_penalty)


def physics_loss(
    model: TrialSolution, system: HamiltonianSystem, t: jax.Array, energy0: jax.Array, lam_reg: jax.Array
) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
    """(L, (residual term, energy penalty)) at collocation times t; see the module docstring."""
    res, en = point_losses(model, system, t, energy0)
    residual, energy_penalty = jnp.mean(res), jnp.mean(en)
    return residual + lam_reg * energy_penalty, (residual, energy_penalty)

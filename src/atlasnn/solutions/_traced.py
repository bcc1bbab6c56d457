"""The Gauss collocation's solution as JAX values: what ``atlasnn.solve`` returns when it runs
inside ``jax.jit``, ``jax.grad``, ``jax.vmap`` or ``jax.jvp`` (its traceable core,
``atlasnn/solver/_gauss_core.py``). The same polynomials as ``PolynomialSolution`` — window k
covers [t_k, t_k + h_k] and ẑ(t) = z_k + Σ_j L_kj Λ_j(θ)/b_j there — held in arrays of a fixed
number of rows (the window budget), of which the first ``count`` are the windows; evaluating it is
a JAX function of the times and of every array, so it can be returned from ``jit`` and
differentiated.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from atlasnn.errors import ConfigError
from atlasnn.solutions._base import INTERVAL_SLACK, finite_times
from atlasnn.solutions._tableau import gauss_tableau, shifted_legendre

__all__ = ["TracedSolution", "TracedReading"]


def _real_times(t):
    """``t`` if it is real numbers: traced ones of a real or integer type, or finite host numbers;
    else a one-line refusal (a complex time would otherwise lose its imaginary part in silence)."""
    if isinstance(t, jax.core.Tracer):
        if not (jnp.issubdtype(t.dtype, jnp.floating) or jnp.issubdtype(t.dtype, jnp.integer)):
            raise ConfigError(f"times must be real numbers, got a traced {t.dtype} array")
        return t
    return finite_times(t)


class TracedReading(eqx.Module):
    """What a solution held as JAX values offers, from its ``_values(t) -> (ẑ, dẑ/dt)``: ẑ(t),
    dẑ/dt(t) and H(ẑ(t)) (an abstract base: its subclasses hold the arrays and ``system``)."""

    def _values(self, t) -> tuple[jax.Array, jax.Array]:
        raise NotImplementedError

    def __call__(self, t) -> jax.Array:
        """ẑ(t), shape t.shape + (2d,); NaN outside [t0, T]."""
        return self._values(t)[0]

    def derivative(self, t) -> jax.Array:
        """dẑ/dt(t), shape t.shape + (2d,)."""
        return self._values(t)[1]

    def energy(self, t) -> jax.Array:
        """H(ẑ(t)), shape t.shape."""
        return self.system.energy(self(t))


class TracedSolution(TracedReading):
    """A Gauss collocation solution over [t0, T] as a pytree of arrays, callable at any times
    inside it; a time outside (beyond the relative slack ``INTERVAL_SLACK`` of the host
    solutions) gives NaN, as no warning can be raised inside a trace.

    Attributes:
        t0: the start of the interval.
        T: its end.
        starts: each window's start t_k in order (budget,); entries past ``count`` are +inf.
        offsets: what each start's float64 number leaves out (budget,): the start is t_k + o_k
            (as a `PolynomialSolution`'s `offsets`).
        rows: the row of window k in the arrays below (budget,): they hold every try of a window,
            accepted or not, in the order tried (sorting them would copy them all).
        lengths: each try's length (budget,).
        z: each try's start state (budget, 2d); ``e``: its compensation.
        L: each try's stage increments (budget, s, 2d).
        count: the number of windows.
        rejected: windows tried and rejected.
        iterations: stage iterations over the march.
        stages: s.
        system: the Hamiltonian system (for ``energy``).
    """

    t0: jax.Array
    T: jax.Array
    starts: jax.Array
    offsets: jax.Array
    rows: jax.Array
    lengths: jax.Array
    z: jax.Array
    e: jax.Array
    L: jax.Array
    count: jax.Array
    rejected: jax.Array
    iterations: jax.Array
    stages: int = eqx.field(static=True)
    system: object = eqx.field(static=True)

    def _window(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(row of the window, θ) of each time: window k with t_k ≤ t < t_{k+1}, clipped to the windows."""
        k = jnp.clip(jnp.searchsorted(self.starts, t, side="right") - 1, 0, self.count - 1)
        row = self.rows[k]
        return row, ((t - self.starts[k]) - self.offsets[k]) / self.lengths[row]

    def _values(self, t) -> tuple[jax.Array, jax.Array]:
        t = jnp.asarray(_real_times(t), self.z.dtype)
        flat = t.reshape(-1)
        tab = gauss_tableau(self.stages)
        row, theta = self._window(flat)
        basis = shifted_legendre(theta, self.stages, jnp)  # (m, s + 1)
        value = theta[:, None] * (basis[:, :-1] @ jnp.asarray(tab.value.T, t.dtype))
        rate = basis @ jnp.asarray(tab.rate.T, t.dtype)
        L = self.L[row]  # (m, s, 2d)
        z = self.z[row] + (self.e[row] + jnp.einsum("ms,msn->mn", value, L))
        dz = jnp.einsum("ms,msn->mn", rate, L) / self.lengths[row][:, None]
        slack = INTERVAL_SLACK * (self.T - self.t0)
        outside = ((flat < self.t0 - slack) | (flat > self.T + slack))[:, None]
        z, dz = jnp.where(outside, jnp.nan, z), jnp.where(outside, jnp.nan, dz)
        shape = t.shape + (self.z.shape[-1],)
        return z.reshape(shape), dz.reshape(shape)

    @property
    def end_state(self) -> jax.Array:
        """ẑ(T)."""
        return self(self.T)

    @property
    def interval(self) -> tuple[jax.Array, jax.Array]:
        """(t0, T)."""
        return self.t0, self.T

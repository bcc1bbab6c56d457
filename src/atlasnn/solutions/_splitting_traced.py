"""An explicit splitting method's solution as JAX values: what ``atlasnn.solve`` returns for a
``SplittingComposition(steps=N)`` inside ``jax.jit``, ``jax.grad`` or ``jax.vmap``. The march is a
``lax.scan`` of N steps keeping every state, so reverse-mode differentiation goes through it
exactly (the gradient of the discrete method); between step points the same method's partial step
gives the dense output, as on numbers."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from atlasnn.solutions._splitting_step import partial_rate, split_step, start_state
from atlasnn.solutions._splitting_tables import splitting_scheme
from atlasnn.solutions._traced import TracedReading, _real_times

__all__ = ["TracedSplittingSolution"]


class TracedSplittingSolution(TracedReading):
    """A splitting solution over [t0, T] as a pytree of arrays, callable at any times inside it.

    Attributes:
        t0: the start; ``h``: the step ((T − t0)/N).
        z: the state at every step point (N + 1, 2d); ``e``: its compensation.
        scheme: the scheme's name; ``system``: the Hamiltonian system (both static).
    """

    t0: jax.Array
    h: jax.Array
    z: jax.Array
    e: jax.Array
    scheme: str = eqx.field(static=True)
    system: Any = eqx.field(static=True)

    @classmethod
    def march(cls, system: Any, scheme: str, z0: Any, t0: Any, T: Any, steps: int) -> "TracedSplittingSolution":
        """N = ``steps`` steps from z0 over [t0, T] (a scan; every state kept)."""
        sch = splitting_scheme(scheme)
        z0 = jnp.asarray(z0, jnp.float64)
        t0, T = jnp.asarray(t0, jnp.float64), jnp.asarray(T, jnp.float64)
        h = (T - t0) / steps
        d = system.dim

        def body(st, _):
            st = split_step(system, sch, st, h)
            return st, (jnp.concatenate([st.q, st.p]), jnp.concatenate([st.eq, st.ep]))

        _, (zs, es) = jax.lax.scan(body, start_state(system, z0), None, length=steps)
        z = jnp.concatenate([z0[None], zs])
        e = jnp.concatenate([jnp.zeros((1, 2 * d), z.dtype), es])
        return cls(t0, h, z, e, scheme, system)

    def _values(self, t) -> tuple[jax.Array, jax.Array]:
        t = jnp.asarray(_real_times(t), self.z.dtype)
        n = self.z.shape[0] - 1
        flat = t.reshape(-1)
        j = jnp.clip(jnp.floor((flat - self.t0) / self.h), 0, n - 1).astype(jnp.int32)
        tau = (flat - self.t0) - j * self.h
        sch = splitting_scheme(self.scheme)
        z, dz = jax.vmap(lambda zj, ej, s: partial_rate(self.system, sch, zj, ej, 0, self.h, s))(
            self.z[j], self.e[j], tau)
        outside = (flat < self.t0 - 1e-9 * n * self.h) | (flat > self.t0 + (1 + 1e-9) * n * self.h)
        z, dz = (jnp.where(outside[:, None], jnp.nan, x) for x in (z, dz))
        shape = t.shape + (self.z.shape[1],)
        return z.reshape(shape), dz.reshape(shape)

    @property
    def end_state(self) -> jax.Array:
        """ẑ(T): the last step's end."""
        return self.z[-1] + self.e[-1]

    @property
    def interval(self) -> tuple[jax.Array, jax.Array]:
        return self.t0, self.t0 + (self.z.shape[0] - 1) * self.h

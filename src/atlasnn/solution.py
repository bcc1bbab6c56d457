"""A trained model as a solution of Hamilton's equations, callable at any times.

``Solution(model, system)`` evaluates ẑ(t), dẑ/dt(t) and H(ẑ(t)) at any array of times,
inside the training interval or beyond it (where it is an extrapolation and should be
judged as one). Results are NumPy arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.model import TrialSolution
from atlasnn.systems import HamiltonianSystem


@jax.jit
def _evaluate(model: TrialSolution, t: jax.Array):
    return model.value_and_rate(t)


@dataclass(eq=False)
class Solution:
    """A trained trial solution for one system.

    Attributes:
        model: the trained :class:`~atlasnn.model.TrialSolution`.
        system: its Hamiltonian system.
        interval: the (t0, T) it was trained on, if known.
        info: free-form record (model name, training summary).
    """

    model: TrialSolution
    system: HamiltonianSystem
    interval: tuple[float, float] | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def _times(self, t) -> tuple[jax.Array, tuple[int, ...]]:
        arr = np.asarray(t, dtype=np.float64)
        if not np.all(np.isfinite(arr)):
            raise ValueError("times must be finite")
        return jnp.asarray(arr.reshape(-1), dtype=self.model.z0.dtype), arr.shape

    def __call__(self, t) -> np.ndarray:
        """ẑ(t): shape t.shape + (2d,)."""
        tt, shape = self._times(t)
        z, _ = _evaluate(self.model, tt)
        return np.asarray(z).reshape(shape + (self.system.state_dim,))

    def derivative(self, t) -> np.ndarray:
        """dẑ/dt(t): shape t.shape + (2d,)."""
        tt, shape = self._times(t)
        _, dz = _evaluate(self.model, tt)
        return np.asarray(dz).reshape(shape + (self.system.state_dim,))

    def energy(self, t) -> np.ndarray:
        """H(ẑ(t)), evaluated in float64: shape t.shape."""
        z = self(t)
        with jax.enable_x64(True):
            return np.asarray(self.system.energy(jnp.asarray(z, dtype=jnp.float64)))

    def residual(self, t) -> np.ndarray:
        """dẑ/dt − J∇H(ẑ) at t: how far the network is from Hamilton's equations there."""
        tt, shape = self._times(t)
        z, dz = _evaluate(self.model, tt)
        r = dz - self.system.vector_field(z)
        return np.asarray(r).reshape(shape + (self.system.state_dim,))

    @property
    def scaling_name(self) -> str:
        return self.model.scaling.name

    @property
    def gamma(self) -> dict[str, float]:
        """The learned (or fixed) time-scaling parameters γ."""
        return {k: float(v) for k, v in self.model.scaling.gamma().items()}

    @property
    def z0(self) -> np.ndarray:
        return np.asarray(self.model.z0, dtype=np.float64)

    @property
    def t0(self) -> float:
        return float(self.model.t0)

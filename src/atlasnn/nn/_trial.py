"""The trial solution ẑ(t) = z0 + f(t − t0; γ) N(t; θ) of the symplectic-aware HNN and ATLAS-NN.

N is a fully connected network from the scalar time t to R^{2d}. The trial solution equals z0
at t0 exactly, whatever θ and γ are. Its time derivative

    dẑ/dt = ḟ(t − t0; γ) N(t; θ) + f(t − t0; γ) dN/dt

is computed in forward mode in one pass through the batched network: every layer carries its
values and their time derivatives together (h, dh/dt), so dN/dt costs one extra matrix product
per layer, not one reverse pass per output component; ḟ is the scaling's closed form.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn._mlp import MLP
from atlasnn.nn._models import make_scaling
from atlasnn.nn._scaling import TimeScaling
from atlasnn.precision import default_float, on_device

__all__ = ["TrialSolution", "make_model"]


class TrialSolution(eqx.Module):
    """ẑ(t) = z0 + f(t − t0; γ) N(t; θ).

    Fields: ``net`` (θ), ``scaling`` (f and its γ), ``z0`` (the initial state, never trained) and
    ``t0`` (the initial time, static).
    """

    net: MLP
    scaling: TimeScaling
    z0: jax.Array
    t0: float = eqx.field(static=True)

    def __call__(self, t: jax.Array) -> jax.Array:
        """ẑ at times t of shape (K,); returns (K, 2d)."""
        t = jnp.asarray(t, dtype=self.z0.dtype).reshape(-1)
        z0 = jax.lax.stop_gradient(self.z0)
        return z0 + self.scaling(t - self.t0)[:, None] * self.net(t)

    def value_and_rate(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(ẑ(t), dẑ/dt(t)) by one forward-mode pass; each of shape (K, 2d).

        dẑ/dt = ḟ(t − t0) N(t) + f(t − t0) dN/dt with (N, dN/dt) from
        :meth:`MLP.value_and_rate` and ḟ from :meth:`TimeScaling.derivative`.
        """
        t = jnp.asarray(t, dtype=self.z0.dtype).reshape(-1)
        z0 = jax.lax.stop_gradient(self.z0)
        n, dn = self.net.value_and_rate(t)
        s = t - self.t0
        f = self.scaling(s)[:, None]
        df = self.scaling.derivative(s)[:, None]
        return z0 + f * n, df * n + f * dn

    @property
    def state_dim(self) -> int:
        return int(self.z0.shape[0])

    def architecture(self) -> dict[str, Any]:
        """What is needed to rebuild the same model shape."""
        return {
            "width": self.net.width,
            "depth": self.net.depth,
            "activation": self.net.activation,
            "state_dim": self.state_dim,
            "scaling": self.scaling.name,
            "t0": float(self.t0),
        }


def make_model(
    z0: Any,
    *,
    scaling: str | TimeScaling = "rational_exp",
    width: int = 50,
    depth: int = 2,
    t0: float = 0.0,
    gamma: dict[str, float] | None = None,
    activation: str = "sin",
    seed: int | jax.Array = 0,
    first_layer_scale: float = 1.0,
) -> TrialSolution:
    """Build a trial solution for initial state z0 (length 2d) at time t0.

    ``scaling`` is a scaling instance or a name: ``"exp_decay"`` (HNN baseline), ``"tanh"`` or
    ``"rational_exp"`` (ATLAS-NN), ``"linear"`` (f = t, the collocation solver's); paper model
    names ``"hnn"``, ``"atlas_tanh"``, ``"atlas_exp"`` are accepted too. ``gamma`` gives the initial γ (default 1.0 for each, as in the paper).
    ``first_layer_scale`` scales the first layer's initial weights (see ``MLP``); it is an
    initialisation choice only (a checkpoint stores the weights, not the scale).
    """
    z0 = np.asarray(z0, dtype=np.float64).reshape(-1)
    if z0.size < 2 or z0.size % 2 or not np.all(np.isfinite(z0)):
        raise ConfigError(f"z0 must be an even number (2d) of finite values, got {z0.tolist()}")
    if isinstance(scaling, str):
        scaling = make_scaling(scaling, gamma)
    elif gamma:
        raise ConfigError("give gamma only together with a scaling name, not with a scaling instance")
    key = seed if isinstance(seed, jax.Array) else jax.random.PRNGKey(int(seed))
    net = MLP(z0.size, width, depth, key, activation, first_layer_scale)
    return TrialSolution(net, scaling, on_device(z0, default_float()), float(t0))

"""The trial solution ẑ(t) = z0 + f(t − t0; γ) N(t; θ) of the symplectic-aware HNN and ATLAS-NN.

N is a fully connected network from the scalar time t to R^{2d}. The trial solution equals z0
at t0 exactly, whatever θ and γ are. Its time derivative

    dẑ/dt = ḟ(t − t0; γ) N(t; θ) + f(t − t0; γ) dN/dt

is computed by forward-mode autodiff (one ``jax.jvp`` with tangent 1 through the batched
network), not by one reverse pass per output component.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.precision import default_float
from atlasnn.scaling import TimeScaling, make_scaling

ACTIVATIONS = {"sin": jnp.sin, "tanh": jnp.tanh, "softplus": jax.nn.softplus, "silu": jax.nn.silu}

# The scaling each model name of the paper uses.
MODEL_SCALINGS = {"hnn": "exp_decay", "atlas_tanh": "tanh", "atlas_exp": "rational_exp"}


class MLP(eqx.Module):
    """A fully connected network t ↦ N(t) ∈ R^{out}, applied to a batch of times at once.

    ``depth`` hidden layers of ``width`` units with activation ``activation`` (sin by default, as in
    the authors' release) and a linear output layer. Initialisation as PyTorch's ``nn.Linear``:
    weights and biases uniform in ±1/sqrt(fan_in).
    """

    weights: list[jax.Array]
    biases: list[jax.Array]
    activation: str = eqx.field(static=True)

    def __init__(self, out_size: int, width: int, depth: int, key: jax.Array, activation: str = "sin"):
        for name, v in (("width", width), ("depth", depth), ("out_size", out_size)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ConfigError(f"network {name} must be a positive integer, got {v!r}")
        if activation not in ACTIVATIONS:
            raise ConfigError(f"unknown activation {activation!r}; choose one of {sorted(ACTIVATIONS)}")
        sizes = [1] + [int(width)] * int(depth) + [int(out_size)]
        keys = jax.random.split(key, 2 * (len(sizes) - 1))
        dtype = default_float()
        self.weights, self.biases = [], []
        for i, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            bound = 1.0 / np.sqrt(fan_in)
            self.weights.append(jax.random.uniform(keys[2 * i], (fan_out, fan_in), dtype, -bound, bound))
            self.biases.append(jax.random.uniform(keys[2 * i + 1], (fan_out,), dtype, -bound, bound))
        self.activation = activation

    @property
    def width(self) -> int:
        return int(self.weights[0].shape[0])

    @property
    def depth(self) -> int:
        return len(self.weights) - 1

    @property
    def out_size(self) -> int:
        return int(self.weights[-1].shape[0])

    def __call__(self, t: jax.Array) -> jax.Array:
        """N(t) for t of shape (K,); returns (K, out_size)."""
        act = ACTIVATIONS[self.activation]
        h = t[:, None]
        for w, b in zip(self.weights[:-1], self.biases[:-1]):
            h = act(h @ w.T + b)
        return h @ self.weights[-1].T + self.biases[-1]


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
        """(ẑ(t), dẑ/dt(t)) by one forward-mode pass; each of shape (K, 2d)."""
        t = jnp.asarray(t, dtype=self.z0.dtype).reshape(-1)
        return jax.jvp(self.__call__, (t,), (jnp.ones_like(t),))

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
) -> TrialSolution:
    """Build a trial solution for initial state z0 (length 2d) at time t0.

    ``scaling`` is a scaling instance or a name: ``"exp_decay"`` (HNN baseline), ``"tanh"`` or
    ``"rational_exp"`` (ATLAS-NN); paper model names ``"hnn"``, ``"atlas_tanh"``, ``"atlas_exp"``
    are accepted too. ``gamma`` gives the initial γ (default 1.0 for each, as in the paper).
    """
    z0 = np.asarray(z0, dtype=np.float64).reshape(-1)
    if z0.size < 2 or z0.size % 2 or not np.all(np.isfinite(z0)):
        raise ConfigError(f"z0 must be an even number (2d) of finite values, got {z0.tolist()}")
    if isinstance(scaling, str):
        scaling = make_scaling(MODEL_SCALINGS.get(scaling, scaling), gamma)
    elif gamma:
        raise ConfigError("give gamma only together with a scaling name, not with a scaling instance")
    key = seed if isinstance(seed, jax.Array) else jax.random.PRNGKey(int(seed))
    net = MLP(z0.size, width, depth, key, activation)
    return TrialSolution(net, scaling, jnp.asarray(z0, dtype=default_float()), float(t0))

"""The network N(t; θ): a fully connected map from the scalar time to R^{2d}, with its time rate.

Forward mode by hand: every layer carries its values and their time derivatives together
(h, dh/dt), so dN/dt costs one extra matrix product per layer, not one reverse pass per output
component.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn._sincos import sin, sin_cos
from atlasnn.precision import default_float

__all__ = ["ACTIVATIONS", "MLP"]

ACTIVATIONS = {"sin": sin, "tanh": jnp.tanh, "softplus": jax.nn.softplus, "silu": jax.nn.silu}


def _activation_with_rate(name: str, a: jax.Array, da: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(σ(a), σ'(a)·da): a layer's activation and its time derivative."""
    if name == "sin":
        s, c = sin_cos(a)
        return s, c * da
    return jax.jvp(ACTIVATIONS[name], (a,), (da,))


@functools.partial(jax.jit, static_argnums=(2, 3))
def _initial_parameters(key: jax.Array, scale: jax.Array | None, sizes: tuple[int, ...], dtype):
    """Every layer's (weights, biases), uniform in ±1/sqrt(fan_in), as one compiled program.

    Drawn one by one outside jit, each layer shape and each small operation (split, scale) was a
    program of its own: about a second of compiling in a cold run. Under jit the draws are the
    same bits (the same threefry calls on the same keys). ``scale`` (None: 1) multiplies the
    first layer's weights.
    """
    keys = jax.random.split(key, 2 * (len(sizes) - 1))
    weights, biases = [], []
    for i, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        bound = 1.0 / np.sqrt(fan_in)
        w = jax.random.uniform(keys[2 * i], (fan_out, fan_in), dtype, -bound, bound)
        weights.append(w * scale if (i == 0 and scale is not None) else w)
        biases.append(jax.random.uniform(keys[2 * i + 1], (fan_out,), dtype, -bound, bound))
    return weights, biases


class MLP(eqx.Module):
    """A fully connected network t ↦ N(t) ∈ R^{out}, applied to a batch of times at once.

    ``depth`` hidden layers of ``width`` units with activation ``activation`` (sin by default, as in
    the authors' release) and a linear output layer. Initialisation as PyTorch's ``nn.Linear``:
    weights and biases uniform in ±1/sqrt(fan_in); ``first_layer_scale`` c multiplies the first
    layer's weights after that draw (so its features sin(c·w·t + b) start with angular frequencies
    up to c instead of 1, as SIREN's ω0 does; c = 1 is the plain initialisation).
    """

    weights: list[jax.Array]
    biases: list[jax.Array]
    activation: str = eqx.field(static=True)

    def __init__(self, out_size: int, width: int, depth: int, key: jax.Array, activation: str = "sin",
                 first_layer_scale: float = 1.0):
        for name, v in (("width", width), ("depth", depth), ("out_size", out_size)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ConfigError(f"network {name} must be a positive integer, got {v!r}")
        if activation not in ACTIVATIONS:
            raise ConfigError(f"unknown activation {activation!r}; choose one of {sorted(ACTIVATIONS)}")
        c = first_layer_scale
        if isinstance(c, bool) or not isinstance(c, (int, float, np.integer, np.floating)) or not np.isfinite(c) or c <= 0:
            raise ConfigError(f"network first_layer_scale must be a finite number > 0, got {c!r}")
        sizes = tuple([1] + [int(width)] * int(depth) + [int(out_size)])
        dtype = default_float()
        scale = jnp.asarray(c, dtype) if c != 1 else None
        weights, biases = _initial_parameters(key, scale, sizes, jnp.dtype(dtype))
        self.weights, self.biases = list(weights), list(biases)
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
        h = act(t[:, None] * self.weights[0][:, 0] + self.biases[0])  # fan-in 1: t Wᵀ is a product
        for w, b in zip(self.weights[1:-1], self.biases[1:-1]):
            h = act(h @ w.T + b)
        return h @ self.weights[-1].T + self.biases[-1]

    def value_and_rate(self, t: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(N(t), dN/dt(t)) for t of shape (K,); each (K, out_size).

        Forward mode by hand: layer by layer, a = h Wᵀ + b and da/dt = (dh/dt) Wᵀ, then
        h = σ(a) and dh/dt = σ'(a) da/dt (for sin, σ and σ' come from one :func:`sin_cos`).
        Equal to ``jax.jvp(self, (t,), (ones,))`` up to rounding.
        """
        w0 = self.weights[0][:, 0]
        a = t[:, None] * w0 + self.biases[0]  # = t[:, None] @ W0ᵀ + b0 (fan-in 1)
        da = jnp.broadcast_to(w0, a.shape)
        h, dh = _activation_with_rate(self.activation, a, da)
        for w, b in zip(self.weights[1:-1], self.biases[1:-1]):
            h, dh = _activation_with_rate(self.activation, h @ w.T + b, dh @ w.T)
        w, b = self.weights[-1], self.biases[-1]
        return h @ w.T + b, dh @ w.T

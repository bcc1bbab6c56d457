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


def _flat_draws_are_prefixes() -> bool:
    """Whether a uniform draw of n values is the first n of a longer draw with the same key: true of
    JAX's default threefry with partitionable counters (each value depends on its key and its
    flat index only), which :func:`_initial_parameters` relies on to draw every layer at once."""
    return bool(jax.config.jax_threefry_partitionable) and jax.config.jax_default_prng_impl == "threefry2x32"


@functools.partial(jax.jit, static_argnums=(2, 3, 4))
def _initial_parameters(key: jax.Array, scale: jax.Array | None, sizes: tuple[int, ...], dtype, batched: bool):
    """Every layer's (weights, biases), uniform in ±1/sqrt(fan_in), as one compiled program.

    Drawn one by one outside jit, each layer shape and each small operation (split, scale) was a
    program of its own. Compiling is dominated by the threefry hash, once per draw, so with
    ``batched`` all draws are one vmapped draw of the largest size, each layer keeping the first
    values of its row: the same bits as drawing it alone (see :func:`_flat_draws_are_prefixes`).
    ``scale`` (None: 1) multiplies the first layer's weights.
    """
    keys = jax.random.split(key, 2 * (len(sizes) - 1))
    shapes, bounds = [], []
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        shapes += [(fan_out, fan_in), (fan_out,)]
        bounds += [1.0 / np.sqrt(fan_in)] * 2
    if batched:
        size = max(int(np.prod(s)) for s in shapes)
        b = jnp.asarray(bounds, dtype)  # the same rounding of ±bound as a scalar argument gets
        rows = jax.vmap(lambda k, lo, hi: jax.random.uniform(k, (size,), dtype, lo, hi))(keys, -b, b)
        draws = [rows[i, : int(np.prod(s))].reshape(s) for i, s in enumerate(shapes)]
    else:
        draws = [jax.random.uniform(k, s, dtype, -bd, bd) for k, s, bd in zip(keys, shapes, bounds)]
    weights, biases = draws[0::2], draws[1::2]
    if scale is not None:
        weights[0] = weights[0] * scale
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
        scale = jax.device_put(np.asarray(c, dtype)) if c != 1 else None
        weights, biases = _initial_parameters(key, scale, sizes, jnp.dtype(dtype), _flat_draws_are_prefixes())
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

"""The bundle trial solution ẑ(t; z0, λ) = z0 + f(t − t0; γ)·N(t, z0, λ; θ).

One network answers a whole family: every initial state z0 of a box and every value λ of the
varying parameters. ẑ(t0; z0, λ) = z0 exactly for every member, whatever θ and γ are. The inputs
are centred on the box and the state and parameter inputs scaled to [−1, 1] by its half-widths
(static, never trained); time keeps its own unit, and the first layer's time weights start uniform
in ±1 as in :class:`MLP`, so its sin features start with angular frequencies up to 1 per unit time,
matched to the dynamics rather than to the interval's length (scaling t to [−1, 1] too was measured:
a 4π oscillator bundle stalled at a loss of 0.3). The time rate dẑ/dt = ḟ N + f ∂N/∂t is carried forward layer by layer as in :class:`MLP` (only the
time column of the first layer has a rate).
"""

from __future__ import annotations

from typing import Any, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn._mlp import ACTIVATIONS, _activation_with_rate
from atlasnn.nn._models import model_kind
from atlasnn.nn._scaling import TimeScaling
from atlasnn.precision import default_float

__all__ = ["BundleTrial", "make_bundle_model"]


class BundleTrial(eqx.Module):
    """ẑ(t; z0, λ) = z0 + f(t − t0; γ)·N(t, z0, λ; θ) for batches of members.

    Fields: ``weights``/``biases`` (θ), ``scaling`` (f and γ); static: ``t0``, the input
    ``centre`` and ``inv_half`` (1/half-width) of (t, z0, λ), ``activation``.
    """

    weights: list[jax.Array]
    biases: list[jax.Array]
    scaling: TimeScaling
    t0: float = eqx.field(static=True)
    centre: tuple[float, ...] = eqx.field(static=True)
    inv_half: tuple[float, ...] = eqx.field(static=True)
    activation: str = eqx.field(static=True)

    @property
    def state_dim(self) -> int:
        return int(self.weights[-1].shape[0])

    @property
    def n_params(self) -> int:
        """The number of varying parameters λ (network inputs after t and z0)."""
        return len(self.centre) - 1 - self.state_dim

    def _inputs(self, t, z0, lam):
        dtype = self.weights[0].dtype
        t = jnp.asarray(t, dtype).reshape(-1, 1)
        z0 = jnp.asarray(z0, dtype).reshape(t.shape[0], self.state_dim)
        lam = jnp.asarray(lam, dtype).reshape(t.shape[0], self.n_params)
        u = jnp.concatenate([t, z0, lam], axis=1)
        return (u - jnp.asarray(self.centre, dtype)) * jnp.asarray(self.inv_half, dtype), t[:, 0], z0

    def _net(self, u):
        act = ACTIVATIONS[self.activation]
        h = u
        for w, b in zip(self.weights[:-1], self.biases[:-1]):
            h = act(h @ w.T + b)
        return h @ self.weights[-1].T + self.biases[-1]

    def __call__(self, t: jax.Array, z0: jax.Array, lam: jax.Array | None = None,
                 start: jax.Array | None = None) -> jax.Array:
        """ẑ for K members at K times: t (K,), z0 (K, 2d), λ (K, P); returns (K, 2d).

        ``start`` (K, 2d): the state at this model's t0 where it is not z0 (a later window of a
        time-marched bundle starts from the previous window's end, still indexed by the member's z0)."""
        lam = jnp.zeros((jnp.size(t), 0)) if lam is None else lam
        u, t, z0 = self._inputs(t, z0, lam)
        base = z0 if start is None else jnp.asarray(start, z0.dtype).reshape(z0.shape)
        return base + self.scaling(t - self.t0)[:, None] * self._net(u)

    def value_and_rate(self, t: jax.Array, z0: jax.Array, lam: jax.Array | None = None,
                       start: jax.Array | None = None):
        """(ẑ, ∂ẑ/∂t), each (K, 2d), by one forward-mode pass (``start`` as in ``__call__``)."""
        lam = jnp.zeros((jnp.size(t), 0)) if lam is None else lam
        u, t, z0 = self._inputs(t, z0, lam)
        base = z0 if start is None else jnp.asarray(start, z0.dtype).reshape(z0.shape)
        w0 = self.weights[0]
        a = u @ w0.T + self.biases[0]
        da = jnp.broadcast_to(w0[:, 0] * jnp.asarray(self.inv_half[0], w0.dtype), a.shape)
        h, dh = _activation_with_rate(self.activation, a, da)
        for w, b in zip(self.weights[1:-1], self.biases[1:-1]):
            h, dh = _activation_with_rate(self.activation, h @ w.T + b, dh @ w.T)
        n, dn = h @ self.weights[-1].T + self.biases[-1], dh @ self.weights[-1].T
        s = t - self.t0
        f, df = self.scaling(s)[:, None], self.scaling.derivative(s)[:, None]
        return base + f * n, df * n + f * dn

    def architecture(self) -> dict[str, Any]:
        return {"width": int(self.weights[0].shape[0]), "depth": len(self.weights) - 1,
                "activation": self.activation, "state_dim": self.state_dim, "scaling": self.scaling.name,
                "t0": float(self.t0), "centre": list(self.centre), "inv_half": list(self.inv_half)}


def make_bundle_model(centre: Sequence[float], half_width: Sequence[float], state_dim: int, *,
                      scaling: str | TimeScaling = "rational_exp", width: int = 64, depth: int = 2,
                      t0: float = 0.0, gamma: dict[str, float] | None = None, activation: str = "sin",
                      seed: int | jax.Array = 0) -> BundleTrial:
    """A bundle model whose inputs (t, z0, λ) are normalised by ``centre`` and ``half_width``
    (from :meth:`atlasnn.systems.BundleBox.centre` / ``half_width``). Initialisation as
    PyTorch's ``nn.Linear`` (uniform in ±1/√fan_in)."""
    centre = tuple(float(c) for c in centre)
    half = np.asarray(half_width, np.float64)
    if len(centre) != half.size or len(centre) < 1 + state_dim or np.any(~np.isfinite(half)) or np.any(half <= 0):
        raise ConfigError(f"bundle inputs: centre and half_width must give 1 + {state_dim} + P finite entries, "
                          f"half-widths > 0; got {len(centre)} and {half.tolist()}")
    for name, v in (("width", width), ("depth", depth)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ConfigError(f"bundle network {name} must be a positive integer, got {v!r}")
    if activation not in ACTIVATIONS:
        raise ConfigError(f"unknown activation {activation!r}; choose one of {sorted(ACTIVATIONS)}")
    if isinstance(scaling, str):
        scaling = model_kind(scaling).make_scaling(gamma)
    key = seed if isinstance(seed, jax.Array) else jax.random.PRNGKey(int(seed))
    sizes = [len(centre)] + [int(width)] * int(depth) + [int(state_dim)]
    keys = jax.random.split(key, 2 * (len(sizes) - 1))
    dtype = default_float()
    weights, biases = [], []
    for i, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        bound = 1.0 / np.sqrt(fan_in)
        weights.append(jax.random.uniform(keys[2 * i], (fan_out, fan_in), dtype, -bound, bound))
        biases.append(jax.random.uniform(keys[2 * i + 1], (fan_out,), dtype, -bound, bound))
    w0 = weights[0]  # time column: ±1 (time in its own unit, see the module docstring)
    weights[0] = w0.at[:, 0].set(w0[:, 0] * np.sqrt(sizes[0]))
    inv_half = (1.0, *(float(v) for v in 1 / half[1:]))
    return BundleTrial(weights, biases, scaling, float(t0), centre, inv_half, activation)

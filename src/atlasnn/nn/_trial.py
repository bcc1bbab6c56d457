"""The trial solution ẑ(t) = z0 + f(t − t0; γ) N(t; θ) of the symplectic-aware HNN and ATLAS-NN.

N is a fully connected network from the scalar time t to R^{2d}. The trial solution equals z0
at t0 exactly, whatever θ and γ are. Its time derivative

    dẑ/dt = ḟ(t − t0; γ) N(t; θ) + f(t − t0; γ) dN/dt

is computed in forward mode in one pass through the batched network: every layer carries its
values and their time derivatives together (h, dh/dt), so dN/dt costs one extra matrix product
per layer, not one reverse pass per output component; ḟ is the scaling's closed form.

Speed notes (see docs/PERFORMANCE.md): on CPU, XLA's sine and cosine are slow (about 2.7 ns
per element on the reference machine, against 0.5 ns for exp) and XLA recomputes them inside
every fused kernel that uses them, while the sin network needs sin and cos of every
pre-activation in the forward, tangent and backward passes. In float32, :func:`sin_cos` evaluates both with one shared range reduction and
polynomials (absolute error ≤ 5e-8 for |x| ≤ 8192, ≤ 0.8 ulp for |x| ≤ 100; XLA's sin/cos are
used for larger arguments and in float64), 3–4× faster than XLA's pair on a [500, 80] array;
through its custom JVP the tangent and backward passes reuse the same sin and cos.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.precision import default_float
from atlasnn.nn._scaling import TimeScaling, make_scaling

# ------------------------------------------------------------------ sin and cos, float32
# Cody–Waite reduction by π/2 = P1 + P2 + P3: P1 has 8 significant bits, P2 11, so j·P1 and
# j·P2 are exact for |j| < 2^13; the two subtractions are carried with their rounding errors.
_PIO2_1 = np.float32(1.5703125)
_PIO2_2 = np.float32(4.837512969970703125e-4)
_PIO2_3 = np.float32(7.54978995489188216e-8)
_TWO_OVER_PI = np.float32(2 / np.pi)


def _fit_sincos_coefficients() -> tuple[tuple[np.float32, ...], tuple[np.float32, ...]]:
    """Polynomial coefficients for sin and cos on [−π/4, π/4], fitted here in float64.

    sin r = r + r·z·(s0 + s1 z + s2 z² + s3 z³) and cos r = 1 − z/2 + z²·(c0 + c1 z + c2 z²),
    z = r², by least squares on 400 Chebyshev nodes in z (max error 3e-12 for sin and 1e-10 for
    cos in float64, far below float32's rounding; tests/test_model_loss.py checks the float32
    result against jnp.sin/cos).
    """
    zmax = (np.pi / 4) ** 2
    k = np.arange(400)
    z = zmax * (1 - np.cos(np.pi * (k + 0.5) / 400)) / 2
    r = np.sqrt(z)
    s = np.linalg.lstsq(np.vander(z, 4, increasing=True) * (r * z)[:, None], np.sin(r) - r, rcond=None)[0]
    c = np.linalg.lstsq(np.vander(z, 3, increasing=True) * (z * z)[:, None], np.cos(r) - 1 + z / 2, rcond=None)[0]
    return tuple(np.float32(v) for v in s), tuple(np.float32(v) for v in c)


_S, _C = _fit_sincos_coefficients()
# Largest |x| for the polynomial path; beyond it XLA's sin/cos are used.
SINCOS_FAST_LIMIT = 8192.0


def _two_diff(a, b):
    """a − b = s + e exactly (Knuth's TwoSum)."""
    s = a - b
    bv = s - a
    av = s - bv
    return s, (a - av) - (b + bv)


def _sin_cos_poly(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(sin x, cos x) in float32 for |x| ≤ SINCOS_FAST_LIMIT, with one shared range reduction."""
    f32 = np.float32
    j = jnp.round(x * _TWO_OVER_PI)
    r1, e1 = _two_diff(x - j * _PIO2_1, j * _PIO2_2)
    r, e2 = _two_diff(r1, j * _PIO2_3)
    lo = e1 + e2  # x − jπ/2 = r + lo to about 2^-48 relative
    z = r * r
    hz = f32(0.5) * z
    w = f32(1) - hz
    sin_r = r + ((r * z) * (_S[0] + z * (_S[1] + z * (_S[2] + z * _S[3]))) + lo * w)
    cos_r = w + ((((f32(1) - w) - hz) + z * z * (_C[0] + z * (_C[1] + z * _C[2]))) - r * lo)
    q = j.astype(jnp.int32)
    odd = (q & 1) == 1
    s = jnp.where(odd, cos_r, sin_r)
    c = jnp.where(odd, sin_r, cos_r)
    return jnp.where((q & 2) == 2, -s, s), jnp.where(((q + 1) & 2) == 2, -c, c)


def _sin_cos_xla(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    return jnp.sin(x), jnp.cos(x)


@jax.custom_batching.custom_vmap
def _sin_cos_f32(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    fast = jnp.max(jnp.abs(x), initial=0.0) <= SINCOS_FAST_LIMIT
    return jax.lax.cond(fast, _sin_cos_poly, _sin_cos_xla, x)


@_sin_cos_f32.def_vmap
def _sin_cos_f32_batched(axis_size, in_batched, x):
    # Elementwise, so a batch (e.g. of seeds trained together) is one array: one test of the
    # range for the whole batch keeps a single branch, where plain vmap would turn the cond into
    # a select and evaluate both branches.
    return _sin_cos_f32(x), (in_batched[0], in_batched[0])


@jax.custom_jvp
def sin_cos(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(sin x, cos x) elementwise, differentiable to any order (d sin = cos, d cos = −sin).

    float32 arguments with |x| ≤ ``SINCOS_FAST_LIMIT`` use a shared Cody–Waite reduction and
    minimax polynomials: absolute error ≤ 5e-8 (XLA's: 3.3e-8), at most 0.8 ulp for |x| ≤ 100
    (XLA's: 0.56), mean 0.25 ulp like XLA's; near the zeros of sin/cos at |x| ≳ 1000 the error in
    ulps of the (tiny) result grows, the absolute error does not. Otherwise (a larger argument
    anywhere in x, NaN, float64) ``jnp.sin`` and ``jnp.cos``; under ``vmap`` the range test covers
    the whole batch.
    """
    x = jnp.asarray(x)
    if x.dtype != jnp.float32:
        return _sin_cos_xla(x)
    return _sin_cos_f32(x)


@sin_cos.defjvp
def _sin_cos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sin_cos(x)
    return (s, c), (c * dx, -s * dx)


def sin(x: jax.Array) -> jax.Array:
    """sin x by :func:`sin_cos` (the network's default activation)."""
    return sin_cos(x)[0]


ACTIVATIONS = {"sin": sin, "tanh": jnp.tanh, "softplus": jax.nn.softplus, "silu": jax.nn.silu}

# The scaling each model name of the paper uses.
MODEL_SCALINGS = {"hnn": "exp_decay", "atlas_tanh": "tanh", "atlas_exp": "rational_exp"}


def _activation_with_rate(name: str, a: jax.Array, da: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(σ(a), σ'(a)·da): a layer's activation and its time derivative."""
    if name == "sin":
        s, c = sin_cos(a)
        return s, c * da
    return jax.jvp(ACTIVATIONS[name], (a,), (da,))


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
        sizes = [1] + [int(width)] * int(depth) + [int(out_size)]
        keys = jax.random.split(key, 2 * (len(sizes) - 1))
        dtype = default_float()
        self.weights, self.biases = [], []
        for i, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            bound = 1.0 / np.sqrt(fan_in)
            w = jax.random.uniform(keys[2 * i], (fan_out, fan_in), dtype, -bound, bound)
            self.weights.append(w * jnp.asarray(c, dtype) if (i == 0 and c != 1) else w)
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
    ``"rational_exp"`` (ATLAS-NN); paper model names ``"hnn"``, ``"atlas_tanh"``, ``"atlas_exp"``
    are accepted too. ``gamma`` gives the initial γ (default 1.0 for each, as in the paper).
    ``first_layer_scale`` scales the first layer's initial weights (see :class:`MLP`); it is an
    initialisation choice only (a checkpoint stores the weights, not the scale).
    """
    z0 = np.asarray(z0, dtype=np.float64).reshape(-1)
    if z0.size < 2 or z0.size % 2 or not np.all(np.isfinite(z0)):
        raise ConfigError(f"z0 must be an even number (2d) of finite values, got {z0.tolist()}")
    if isinstance(scaling, str):
        scaling = make_scaling(MODEL_SCALINGS.get(scaling, scaling), gamma)
    elif gamma:
        raise ConfigError("give gamma only together with a scaling name, not with a scaling instance")
    key = seed if isinstance(seed, jax.Array) else jax.random.PRNGKey(int(seed))
    net = MLP(z0.size, width, depth, key, activation, first_layer_scale)
    return TrialSolution(net, scaling, jnp.asarray(z0, dtype=default_float()), float(t0))

"""Time scalings f(t; γ), the heart of ATLAS-NN.

The trial solution is ẑ(t) = z0 + f(t − t0; γ) N(t; θ). Every scaling here satisfies

    f(0; γ) = 0,   ḟ(t; γ) > 0 for t ≥ 0,   f(t; γ) → 1 as t → ∞,

so ẑ(t0) = z0 exactly and the network's output is switched on smoothly. The learnable
parameters γ are stored raw and mapped through softplus, which keeps them positive.

Each scaling is an Equinox module (a frozen pytree); its only array leaves are the raw γ.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.precision import default_float, on_device


def softplus(x: jax.Array) -> jax.Array:
    """log(1 + e^x), computed stably."""
    return jax.nn.softplus(x)


def inverse_softplus(y: float) -> float:
    """The raw value whose softplus is y > 0 (y = log(1 + e^x)  ⇔  x = log(e^y − 1))."""
    y = float(y)
    if not np.isfinite(y) or y <= 0:
        raise ConfigError(f"initial gamma must be a finite positive number, got {y!r}")
    # log(expm1(y)) loses accuracy for large y; there x ≈ y.
    return float(y + np.log(-np.expm1(-y)))


class TimeScaling(eqx.Module):
    """Base class: a map t ↦ f(t; γ) with f(0) = 0, ḟ > 0, f → 1.

    A subclass states, as class variables, its ``name``, ``gamma_names`` (its positional
    ``__init__`` arguments, each defaulting to 1.0), ``formula`` (f in text) and ``rate_names``:
    the γ entries r with 0 ≤ f(t) ≤ r·t, which the quality verdict watches for collapse. A new
    scaling is such a class and one :func:`atlasnn.nn.register_model` entry.
    """

    name: ClassVar[str] = "base"
    gamma_names: ClassVar[tuple[str, ...]] = ()
    formula: ClassVar[str] = ""
    rate_names: ClassVar[tuple[str, ...]] = ()

    def __call__(self, t: jax.Array) -> jax.Array:  # pragma: no cover - abstract
        raise NotImplementedError

    def derivative(self, t: jax.Array) -> jax.Array:
        """ḟ(t; γ), by forward-mode autodiff of f (elementwise)."""
        t = jnp.asarray(t)
        _, df = jax.jvp(self.__call__, (t,), (jnp.ones_like(t),))
        return df

    def gamma(self) -> dict[str, jax.Array]:
        """The positive parameters γ by name (empty for the HNN baseline)."""
        return {}

    def gamma_array(self) -> jax.Array:
        """γ as one array in the order of ``gamma_names`` (shape (0,) when there is none)."""
        g = self.gamma()
        if not g:
            return jnp.zeros((0,))
        return jnp.stack([jnp.asarray(g[k]).reshape(()) for k in self.gamma_names])


class ExpDecay(TimeScaling):
    """f(t) = 1 − e^{−t}: the fixed scaling of the HNN baseline (no parameters)."""

    name: ClassVar[str] = "exp_decay"
    gamma_names: ClassVar[tuple[str, ...]] = ()
    formula: ClassVar[str] = "f(t) = 1 − e^(−t)"

    def __call__(self, t):
        return -jnp.expm1(-t)

    def derivative(self, t):
        return jnp.exp(-t)


class Tanh(TimeScaling):
    """f(t; m) = tanh(m t), m = softplus(raw_m) > 0: ATLAS-NN scheme I."""

    name: ClassVar[str] = "tanh"
    gamma_names: ClassVar[tuple[str, ...]] = ("m",)
    formula: ClassVar[str] = "f(t) = tanh(m t)"
    rate_names: ClassVar[tuple[str, ...]] = ("m",)
    raw_m: jax.Array

    def __init__(self, m: float = 1.0):
        self.raw_m = on_device(inverse_softplus(m), default_float())

    @property
    def m(self) -> jax.Array:
        return softplus(self.raw_m)

    def __call__(self, t):
        return jnp.tanh(self.m * t)

    def derivative(self, t):
        m = self.m
        e = jnp.exp(-2 * m * jnp.abs(t))  # sech² x = 4e^{-2|x|}/(1+e^{-2|x|})², no cancellation
        return 4 * m * e / (1 + e) ** 2

    def gamma(self):
        return {"m": self.m}


class RationalExp(TimeScaling):
    """f(t; α, β) = (1 − e^{−αt}) / (1 + β e^{−αt}), α, β = softplus(raw) > 0: ATLAS-NN scheme II.

    β = 1 gives tanh(αt/2); β → 0 gives 1 − e^{−αt}. ḟ = α(1 + β) e^{−αt} / (1 + β e^{−αt})².
    """

    name: ClassVar[str] = "rational_exp"
    gamma_names: ClassVar[tuple[str, ...]] = ("alpha", "beta")
    formula: ClassVar[str] = "f(t) = (1 − e^(−αt))/(1 + β e^(−αt))"
    rate_names: ClassVar[tuple[str, ...]] = ("alpha",)  # β is a shape parameter (β → 0 is legitimate)
    raw_alpha: jax.Array
    raw_beta: jax.Array

    def __init__(self, alpha: float = 1.0, beta: float = 1.0):
        self.raw_alpha = on_device(inverse_softplus(alpha), default_float())
        self.raw_beta = on_device(inverse_softplus(beta), default_float())

    @property
    def alpha(self) -> jax.Array:
        return softplus(self.raw_alpha)

    @property
    def beta(self) -> jax.Array:
        return softplus(self.raw_beta)

    def __call__(self, t):
        e = jnp.exp(-self.alpha * t)
        return -jnp.expm1(-self.alpha * t) / (1 + self.beta * e)

    def derivative(self, t):
        a, b = self.alpha, self.beta
        e = jnp.exp(-a * t)
        return a * (1 + b) * e / (1 + b * e) ** 2

    def gamma(self):
        return {"alpha": self.alpha, "beta": self.beta}


class Linear(TimeScaling):
    """f(t) = t: no parameters, no saturation — the constrained form z0 + t·N(t) of X-TFC, which the
    float64 collocation solver (:mod:`atlasnn.solver`) uses on short windows by default. Unlike
    the paper's scalings it does not tend to 1, so it suits a window, not a whole long interval."""

    name: ClassVar[str] = "linear"
    gamma_names: ClassVar[tuple[str, ...]] = ()
    formula: ClassVar[str] = "f(t) = t"

    def __call__(self, t):
        return t

    def derivative(self, t):
        return jnp.ones_like(t)


def build_scaling(cls: type[TimeScaling], gamma: dict[str, float] | None = None) -> TimeScaling:
    """An instance of the scaling class ``cls`` with initial γ (each defaults to
    ``cls.gamma_defaults``, 1.0 as the paper says), after checking every given γ by name."""
    gamma = dict(gamma or {})
    unknown = set(gamma) - set(cls.gamma_names)
    if unknown:
        raise ConfigError(
            f"scaling {cls.name!r} has parameters {list(cls.gamma_names) or 'none'}, got unknown {sorted(unknown)}"
        )
    for k, v in gamma.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
            raise ConfigError(f"initial gamma {k} must be a finite positive number, got {v!r}")
    return cls(**{k: float(v) for k, v in gamma.items()})

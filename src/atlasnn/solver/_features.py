"""The fixed part of a collocation window: random tanh features, collocation nodes, time scalings.

Every window k of the collocation solver holds the trial solution of ATLAS-NN on its local time
s = t − t_k ∈ [0, h] with a network of one hidden layer whose weights are fixed:

    ẑ_k(s) = z_k + f(s; γ) W_k φ(s / h),    φ_j(τ) = tanh(a_j τ + b_j),  j = 1..M,

so only the output layer W_k (2d × M) is unknown. The features live on the normalised time
τ = s/h ∈ [0, 1]: their scales follow the window length, and one draw (one seed) serves every
window of every length. The slopes a_j are uniform in ±``scale`` and the centres −b_j/a_j uniform
in [0, 1] (each feature turns inside the window). ẑ_k(0) = z_k exactly, whatever W_k is.

The time scaling f is one of ATLAS-NN's, with γ set from the window length (the argument of f is
s/h times a constant, so every window sees the same shape): ``linear`` f(s) = s (X-TFC's form),
``tanh`` f(s) = tanh(m s) with m h = γ̂, ``rational_exp`` f(s) = (1 − e^{−αs})/(1 + βe^{−αs}) with
α h = γ̂ and β = 1/4 (docs/SOLVER.md measures which lets windows grow).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError

__all__ = ["RandomFeatures", "collocation_nodes", "check_grid", "WINDOW_SCALINGS", "window_scaling"]


def collocation_nodes(points: int, kind: str = "chebyshev") -> np.ndarray:
    """``points`` nodes τ_i in (0, 1] on which a window's residual is driven to zero: the
    Chebyshev–Lobatto points without τ = 0 (where ẑ = z_k holds anyway), or Gauss–Legendre nodes
    shifted to (0, 1)."""
    if kind == "chebyshev":
        k = np.arange(1, points + 1)
        return 0.5 * (1.0 - np.cos(np.pi * k / points))
    if kind == "gauss":
        x, _ = np.polynomial.legendre.leggauss(points)
        return 0.5 * (x + 1.0)
    raise ConfigError(f"collocation nodes must be 'chebyshev' or 'gauss', got {kind!r}")


def check_grid(points: int, kind: str = "uniform") -> tuple[np.ndarray, np.ndarray]:
    """The grid on which a window's error is integrated: τ(u) and τ'(u) at ``points`` equally
    spaced u in [0, 1]; ``"uniform"`` (τ = u) or ``"chebyshev"`` (τ = (1 − cos πu)/2)."""
    u = np.linspace(0.0, 1.0, points)
    if kind == "uniform":
        return u, np.ones_like(u)
    if kind == "chebyshev":
        return 0.5 * (1.0 - np.cos(np.pi * u)), 0.5 * np.pi * np.sin(np.pi * u)
    raise ConfigError(f"collocation check_grid must be 'uniform' or 'chebyshev', got {kind!r}")


@dataclass(frozen=True)
class RandomFeatures:
    """M fixed tanh features φ_j(τ) = tanh(a_j τ + b_j) on τ ∈ [0, 1], drawn from ``seed``.

    Attributes:
        a, b: slopes and offsets (float64, shape (M,)).
    """

    a: np.ndarray
    b: np.ndarray

    @classmethod
    def draw(cls, count: int, scale: float, seed: int) -> "RandomFeatures":
        """``count`` features with slopes uniform in ±``scale`` and centres uniform in [0, 1]."""
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EED]))
        a = rng.uniform(-scale, scale, count)
        centre = rng.uniform(0.0, 1.0, count)
        return cls(a, -a * centre)

    @property
    def count(self) -> int:
        return int(self.a.size)


@dataclass(frozen=True)
class WindowScaling:
    """A time scaling as the collocation window uses it: f(s) and ḟ(s) given the window length h
    and the fixed shape constant γ̂ (traceable), and the γ of the trial solution it amounts to."""

    name: str
    value: Callable
    rate: Callable
    gamma: Callable  # (h, ĝ) -> {name: value} for the TrialSolution's scaling


def _lin_value(s, h, g):
    return s


def _lin_rate(s, h, g):
    return jnp.ones_like(s)


def _tanh_value(s, h, g):
    return jnp.tanh(g * s / h)


def _tanh_rate(s, h, g):
    m = g / h
    return m / jnp.cosh(m * s) ** 2


def _rexp_value(s, h, g):
    e = jnp.exp(-g * s / h)
    return (1.0 - e) / (1.0 + REXP_BETA * e)


def _rexp_rate(s, h, g):
    a = g / h
    e = jnp.exp(-a * s)
    return a * (1.0 + REXP_BETA) * e / (1.0 + REXP_BETA * e) ** 2


#: β of the rational-exp scaling in a window (β = 1 would make it tanh(αs/2), the tanh shape again)
REXP_BETA = 0.25

#: the time scalings a collocation window can use, by the name of the TimeScaling it builds
WINDOW_SCALINGS: dict[str, WindowScaling] = {
    "linear": WindowScaling("linear", _lin_value, _lin_rate, lambda h, g: {}),
    "tanh": WindowScaling("tanh", _tanh_value, _tanh_rate, lambda h, g: {"m": g / h}),
    "rational_exp": WindowScaling("rational_exp", _rexp_value, _rexp_rate,
                                  lambda h, g: {"alpha": g / h, "beta": REXP_BETA}),
}


def window_scaling(name: str) -> WindowScaling:
    """The window scaling of a name (one line naming the choices when it is unknown)."""
    if name not in WINDOW_SCALINGS:
        raise ConfigError(f"collocation scaling must be one of {sorted(WINDOW_SCALINGS)}, got {name!r}")
    return WINDOW_SCALINGS[name]

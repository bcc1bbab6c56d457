"""A bundle as one float64 flow map, composed window after window.

For an autonomous system the map from a state z (and parameters λ) to the state a time s later,
s ∈ [0, h], is the same in every window. :class:`FlowMapBundle` holds it as ATLAS-NN's trial
solution with the linear time scaling and a fixed basis,

    ẑ(s; z, λ) = z + s · W φ(s, z, λ),

φ the products of Chebyshev polynomials T_i(s) · Π_c T_{α_c}(z_c) · Π_j T_{β_j}(λ_j) (inputs scaled
to [−1, 1] over the region the map was fitted on; i ≤ time degree, |α| ≤ state degree, |β| ≤
parameter degree), W found by Gauss–Newton (:class:`atlasnn.solver.FlowMap`). A member's state at
t is the map applied ⌊(t − t0)/h⌋ times at s = h from z0, then once at the remainder: ẑ(t0) = z0
exactly, and the windows join exactly.

Evaluation is NumPy in float64, factorised so that memory grows with the members × times and the
spatial basis, not the whole basis: the spatial part R(z, λ) (n × M_space) is multiplied by W
first, then combined with the time polynomials.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solutions._piecewise import window_edges
from atlasnn.systems import BundleBox

__all__ = ["ChebyshevBasis", "FlowMapBundle", "chebyshev"]

_CHUNK = 4096  # rows evaluated at once


def chebyshev(u: np.ndarray, n: int, rate: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """T_0..T_n at u (shape (..., n + 1)); with ``rate`` also dT/du."""
    T = [np.ones_like(u), u]
    D = [np.zeros_like(u), np.ones_like(u)]
    for m in range(1, n):
        T.append(2 * u * T[m] - T[m - 1])
        if rate:
            D.append(2 * T[m] + 2 * u * D[m] - D[m - 1])
    values = np.stack(T[: n + 1], -1)
    return (values, np.stack(D[: n + 1], -1)) if rate else values


def _multi_indices(dims: int, degree: int) -> np.ndarray:
    """Every multi-index of ``dims`` entries with total degree ≤ ``degree``, (count, dims)."""
    if dims == 0:
        return np.zeros((1, 0), np.int64)
    return np.asarray([a for a in itertools.product(range(degree + 1), repeat=dims) if sum(a) <= degree], np.int64)


@dataclass(frozen=True)
class ChebyshevBasis:
    """φ(s, z, λ) over s ∈ [0, h] and the box [low, high] of the inputs (z, λ)."""

    time_degree: int
    state_degree: int
    param_degree: int
    state_dim: int
    low: tuple[float, ...]  # (2d + P,): the region of (z, λ) the basis is scaled to
    high: tuple[float, ...]
    h: float

    @property
    def n_params(self) -> int:
        return len(self.low) - self.state_dim

    @property
    def space_index(self) -> np.ndarray:
        """Multi-indices (α, β) of the spatial factors, (M_space, 2d + P)."""
        a, b = _multi_indices(self.state_dim, self.state_degree), _multi_indices(self.n_params, self.param_degree)
        return np.asarray([np.concatenate([x, y]) for x in a for y in b], np.int64)

    @property
    def n_space(self) -> int:
        return len(self.space_index)

    @property
    def n_features(self) -> int:
        return (self.time_degree + 1) * self.n_space

    def space(self, inputs: np.ndarray) -> np.ndarray:
        """R(z, λ) for inputs (n, 2d + P): (n, M_space)."""
        low, high = np.asarray(self.low), np.asarray(self.high)
        u = (2 * np.asarray(inputs, np.float64) - (low + high)) / (high - low)
        idx = self.space_index
        top = max(self.state_degree, self.param_degree)
        T = chebyshev(u, top)  # (n, 2d + P, top + 1)
        out = np.ones((u.shape[0], len(idx)))
        for c in range(u.shape[1]):
            out *= T[:, c, idx[:, c]]
        return out

    def time(self, s: np.ndarray, rate: bool = False):
        """T_i(2s/h − 1) (n, S + 1); with ``rate`` also its s-derivative."""
        u = 2 * np.asarray(s, np.float64) / self.h - 1
        if not rate:
            return chebyshev(u, self.time_degree)
        T, D = chebyshev(u, self.time_degree, rate=True)
        return T, D * (2 / self.h)

    def contains(self, inputs: np.ndarray, slack: float = 1e-9) -> np.ndarray:
        """Whether each row of (z, λ) lies in the fitted region (a bool per row)."""
        low, high = np.asarray(self.low), np.asarray(self.high)
        pad = slack * (high - low)
        return np.all((inputs >= low - pad) & (inputs <= high + pad), axis=1)


def _shown(values: np.ndarray) -> str:
    """Numbers as a message shows them: [1.2, -0.5], four significant digits."""
    return "[" + ", ".join(f"{v:.4g}" for v in np.asarray(values, np.float64).tolist()) + "]"


@dataclass
class FlowMapBundle:
    """The solution of [`atlasnn.solver.solve_bundle`][atlasnn.solver.solve_bundle]: ``W`` (2d, S + 1, M_space) over
    ``basis``, ``windows`` windows of length h = (T − t0)/windows over ``box``; ``info``: how it
    was fitted (seconds, residual, region rounds)."""

    basis: ChebyshevBasis
    W: np.ndarray
    box: BundleBox
    windows: int
    info: dict[str, Any]

    @property
    def edges(self) -> np.ndarray:
        return window_edges(self.box.t0, self.box.T, self.windows)

    def coefficients(self, z: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """C(z, λ) with ẑ(s) = z + s Σ_i C_i T_i(2s/h − 1): (n, 2d, S + 1), rows in chunks."""
        z, lam = np.asarray(z, np.float64), np.asarray(lam, np.float64).reshape(len(z), -1)
        flat = self.W.reshape(-1, self.W.shape[-1]).T  # (M_space, 2d·(S+1))
        out = np.empty((len(z), z.shape[1], self.W.shape[1]))
        for c in range(0, len(z), _CHUNK):
            rows = slice(c, c + _CHUNK)
            R = self.basis.space(np.concatenate([z[rows], lam[rows]], axis=1))
            out[rows] = (R @ flat).reshape(-1, z.shape[1], self.W.shape[1])
        return out

    def from_coefficients(self, C: np.ndarray, z: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(ẑ(s), ∂ẑ/∂s) of rows whose window starts at z with coefficients C (``coefficients``)."""
        s = np.asarray(s, np.float64).reshape(-1)
        T, D = self.basis.time(s, rate=True)
        G = np.einsum("nci,ni->nc", C, T)
        return z + s[:, None] * G, G + s[:, None] * np.einsum("nci,ni->nc", C, D)

    def advance(self, s: np.ndarray, z: np.ndarray, lam: np.ndarray, rate: bool = False):
        """ẑ(s; z, λ) for rows of s (n,), z (n, 2d), λ (n, P): (n, 2d); with ``rate`` also ∂ẑ/∂s."""
        z = np.asarray(z, np.float64)
        out, speed = self.from_coefficients(self.coefficients(z, lam), z, s)
        return (out, speed) if rate else out

    def __call__(self, t: Any, z0: Any, lam: Any) -> np.ndarray:
        """States at times ``t`` (sorted, in [t0, T]) of members z0 (N, 2d), λ (N, P): (N, len(t), 2d).

        One evaluation of the spatial basis per member and window: the window's coefficients
        C(z_k, λ) give every time in the window and the next window's start z_k + h Σ_i C_i.
        Members outside the region the map was fitted on, and times outside [t0, T], are refused
        (the Chebyshev basis does not extrapolate)."""
        t, z0, lam = self._checked(t, z0, lam)
        return self.compose(t, z0, lam)

    def _checked(self, t: Any, z0: Any, lam: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d, n_p = self.basis.state_dim, self.basis.n_params
        t = np.asarray(t, np.float64).reshape(-1)
        z0, lam = np.atleast_2d(np.asarray(z0, np.float64)), np.asarray(lam, np.float64)
        lam = lam.reshape(-1, n_p) if lam.size or n_p == 0 else lam.reshape(len(z0), 0)
        if z0.ndim != 2 or z0.shape[1] != d or lam.shape != (len(z0), n_p):
            raise ConfigError(f"members must be z0 of shape (N, {d}) and lam of shape (N, {n_p}); got "
                              f"{np.shape(z0)} and {np.shape(lam)}")
        t0, T = self.box.t0, self.box.T
        if not np.all(np.isfinite(t)):
            raise ConfigError("times must be finite numbers")
        if t.size and (t.min() < t0 - 1e-12 * max(1.0, abs(t0)) or t.max() > T + 1e-12 * max(1.0, abs(T))):
            raise ConfigError(f"times must lie in the bundle's interval [{t0:g}, {T:g}]; got [{t.min():g}, {t.max():g}]")
        inside = self.basis.contains(np.concatenate([z0, lam], axis=1))
        if not np.all(inside):
            i = int(np.nonzero(~inside)[0][0])
            low, high = np.asarray(self.basis.low), np.asarray(self.basis.high)
            raise ConfigError(f"member {i} (z0 = {_shown(z0[i])}, lam = {_shown(lam[i])}) lies outside the region the "
                              f"flow map was fitted on (states {_shown(low[:d])} to {_shown(high[:d])}, "
                              f"parameters {_shown(low[d:])} to {_shown(high[d:])}); give members inside it, or "
                              "solve the bundle over a box that holds them")
        return t, z0, lam

    def compose(self, t: np.ndarray, z0: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """The composed map at sorted times t, without ``__call__``'s checks (the solver's
        scouting carries members past the region on purpose, to find where they go)."""
        t0 = self.box.t0
        h = self.basis.h
        k_of_t = np.clip(np.floor((t - t0) / h).astype(np.int64), 0, self.windows - 1)
        last = int(k_of_t.max()) if t.size else -1
        out = np.empty((len(z0), t.size, z0.shape[1]))
        z = z0.copy()
        for k in range(last + 1):
            C = self.coefficients(z, lam)
            sel = np.nonzero(k_of_t == k)[0]
            if sel.size:
                s = t[sel] - t0 - k * h
                out[:, sel] = z[:, None, :] + s[None, :, None] * np.einsum("nci,ti->ntc", C, self.basis.time(s))
            z = z + h * C.sum(axis=2)  # T_i(1) = 1
        return out

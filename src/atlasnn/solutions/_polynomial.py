"""The Gauss collocation's solution: one polynomial trial solution per window, the windows held in
arrays (a long march has millions of them).

Window k covers [t_k, t_k + h_k]; on it, with θ = (t − t_k)/h_k,

    ẑ(t) = z_k + θ h_k · N_k(θ)  =  z_k + Σ_j L_kj Λ_j(θ)/b_j,

N_k a polynomial of degree s − 1 (the trial solution with the linear time scaling), fixed by the
stage increments L_k (s × 2d) of :mod:`atlasnn.solutions._tableau`; z_k is the previous window's end
(the solution is continuous, and exact at t0). Evaluation finds each time's window by a search over
the edges and sums the shifted-Legendre form of the polynomial, in float64 NumPy. Where a march kept
only its window starts (``L`` is None: it was too long to keep every polynomial), the windows a
call needs are solved again from their starts by ``resolve`` (the same equations; the same
polynomial to round-off).

Its error estimate compares it with a companion solution over the same interval, computed with
the same method on windows half as long (:attr:`estimator`, supplied by the solver): the
companion's error is 2^(s+1) times smaller along the windows and 2^(2s) times smaller at their
ends, so the difference is the error of this one (docs/SOLVER.md measures it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solutions._base import INTERVAL_SLACK, AbstractSolution, check_inside, finite_times
from atlasnn.solutions._estimate import ErrorEstimate
from atlasnn.solutions._solution import check_outside_mode
from atlasnn.solutions._tableau import gauss_tableau, shifted_legendre
from atlasnn.systems import HamiltonianSystem

__all__ = ["PolynomialSolution", "edge_offsets", "CompanionEstimated"]


def edge_offsets(edges: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The offsets o_k of windows of these ``lengths`` laid end to end from edges[0] (exactly, as
    the march laid them) over the float64 ``edges`` t_k that stand for them: t_k + o_k = t_0 + the
    sum of the lengths before k. The differences of neighbouring edges are exact far from 0, so
    each term, and their sum, is a small number computed to its own precision."""
    edges, lengths = np.asarray(edges, np.float64), np.asarray(lengths, np.float64)
    return np.concatenate([[0.0], np.cumsum(lengths - np.diff(edges))])

#: the most nodes an error estimate keeps (three a window below it)
_MAX_NODES = 1_000_000
#: times evaluated at once (bounds the memory of the gathered polynomials)
_EVAL_CHUNK = 65_536
#: above this many bytes of gathered stage increments, times are evaluated window by window
_GATHER_BYTES = 16 << 20


def _at_least_roundoff(delta: np.ndarray, z: np.ndarray) -> np.ndarray:
    """δ, each entry at least eps·|ẑ| in size (its sign kept): ẑ is a float64 value, no nearer the
    true state than its own rounding, which the companion, rounded alike, does not see (H = p²/2 +
    (q − c)²/2 at c = 1e8: an error of an ulp of c, 1.5e-8, where the difference said 7e-9)."""
    floor = np.finfo(np.float64).eps * np.abs(z)
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(delta) < floor, np.where(delta < 0, -floor, floor), delta)


class CompanionEstimated:
    """The error estimate of a solution against its companion (the same method on steps or windows
    half as long, from ``estimator``, computed on first use and kept), for the solvers' solutions:
    ``companion()`` and ``error_estimate(t)``."""

    def companion(self):
        """The companion solution of the error estimate (computed on first use and kept)."""
        kept = self.__dict__.get("_companion")
        if kept is None:
            kept = self.__dict__["_companion"] = self.companion_from()
        return kept

    def companion_from(self, start: np.ndarray | None = None):
        """A companion solution from ``start`` in place of z0 (None: z0), not kept."""
        if self.estimator is None:
            raise ConfigError("this solution has no error estimator (it was built without its solver)")
        return self.estimator() if start is None else self.estimator(start)

    def error_estimate(self, t) -> np.ndarray:
        """The estimated error z(t) − ẑ(t) at times of the interval (the companion minus this
        solution, at exactly those times, at least an ulp of ẑ): shape t.shape + (2d,); NaN outside
        the interval."""
        arr = finite_times(t)
        check_inside(self, self.interval, arr.reshape(-1))
        companion = self.companion()
        with np.errstate(invalid="ignore"):
            mine = self(arr)
            out = _at_least_roundoff(companion(arr) - mine, mine)
        t0, T = self.interval
        slack = INTERVAL_SLACK * (T - t0)
        out[(arr < t0 - slack) | (arr > T + slack)] = np.nan
        return out


@dataclass(eq=False)
class PolynomialSolution(CompanionEstimated, AbstractSolution):
    """A Gauss collocation solution over [t0, T], callable at any times.

    Attributes:
        system: the Hamiltonian system.
        edges: the window edges t_0..t_n (float64, increasing).
        offsets: what each edge's float64 number leaves out of the edge (the edge is t_k + o_k: far
            from 0 the sum of the window lengths falls between float64 numbers, and an evaluation
            placed by t_k alone would be off by up to half their spacing); None: zeros.
        z: the window start states z_k (n, 2d); ``e``: their compensation (the part of z_k float64
            could not hold: z_k + e_k is the state).
        L: the stage increments (n, s, 2d), or None (solved again from the starts when needed).
        stages: s.
        check: every window's error check over its tolerance (≤ 1 for a window the solver
            accepted; None when not recorded).
        info: the solver's record (settings, tolerance, counts, times).
        estimator: ``estimator(start=None)``, the companion solution of the error estimate (from
            ``start`` in place of z0 where given).
        resolve: ``resolve(z, e, h) -> L`` for windows whose L is not kept.
        outside: what evaluating outside [t0, T] does (as for [`Solution`][atlasnn.solutions.Solution]).
    """

    interval_name: ClassVar[str] = "interval"

    system: HamiltonianSystem
    edges: np.ndarray
    z: np.ndarray
    e: np.ndarray
    L: np.ndarray | None
    stages: int
    check: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)
    estimator: Callable[..., "PolynomialSolution"] | None = field(default=None, repr=False)
    resolve: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = field(default=None, repr=False)
    outside: str = "warn"
    offsets: np.ndarray | None = None
    _warned: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        check_outside_mode(self.outside)
        self.edges = np.asarray(self.edges, np.float64)
        self.z = np.asarray(self.z, np.float64)
        self.e = np.asarray(self.e, np.float64)
        n, d = self.edges.size - 1, self.system.state_dim
        if n < 1 or not np.all(np.diff(self.edges) > 0):
            raise ConfigError(f"a polynomial solution needs increasing edges, at least two, got {self.edges.size}")
        self.offsets = np.zeros(n + 1) if self.offsets is None else np.asarray(self.offsets, np.float64)
        if self.offsets.shape != (n + 1,) or not np.all(np.isfinite(self.offsets)):
            raise ConfigError(f"a polynomial solution of {n} windows needs {n + 1} finite edge offsets, got "
                              f"shape {self.offsets.shape}")
        if self.z.shape != (n, d) or self.e.shape != (n, d):
            raise ConfigError(f"a polynomial solution of {n} windows needs z and e of shape ({n}, {d}), got "
                              f"{self.z.shape} and {self.e.shape}")
        if self.L is not None:
            self.L = np.asarray(self.L, np.float64)
            if self.L.shape != (n, self.stages, d):
                raise ConfigError(f"L must have shape ({n}, {self.stages}, {d}), got {self.L.shape}")
        elif self.resolve is None:
            raise ConfigError("a polynomial solution without its stage increments needs resolve()")
        self._tab = gauss_tableau(self.stages)

    # ------------------------------------------------------------------ evaluation
    def window_index(self, t) -> np.ndarray:
        """The window serving each time: k with t_k ≤ t < t_{k+1}, clipped to [0, n − 1]."""
        return np.searchsorted(self.edges[1:-1], np.asarray(t, np.float64), side="right").astype(np.int64)

    def window_increments(self, k: np.ndarray, component: int) -> np.ndarray:
        """The stage increments of one component in windows k: L[k, :, component], (len(k), s)."""
        return self._stage_rows(np.asarray(k, np.int64), slice(component, component + 1))[..., 0]

    def _stage_rows(self, k: np.ndarray, columns: slice = slice(None)) -> np.ndarray:
        """L of the windows k (len(k), s, 2d; only ``columns`` of the last axis), solved again where
        they are not kept."""
        if self.L is not None:
            return self.L[k, :, columns]
        unique, where = np.unique(k, return_inverse=True)
        rows = self.resolve(self.z[unique], self.e[unique], self.length_of(unique))
        return np.asarray(rows)[where][..., columns]

    def _evaluate(self, t) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        arr = finite_times(t)
        flat = arr.reshape(-1)
        check_inside(self, self.interval, flat)
        d = self.system.state_dim
        z, dz = np.empty((flat.size, d)), np.empty((flat.size, d))
        for a in range(0, flat.size, _EVAL_CHUNK):
            z[a:a + _EVAL_CHUNK], dz[a:a + _EVAL_CHUNK] = self._evaluate_flat(flat[a:a + _EVAL_CHUNK])
        return z.reshape(arr.shape + (d,)), dz.reshape(arr.shape + (d,)), arr.shape

    def _evaluate_flat(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.window_values(t, self.window_index(t))

    def window_values(self, t: np.ndarray, k: np.ndarray,
                      component: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(ẑ(t), dẑ/dt(t)) by window k's polynomial (times (m,) and windows (m,), no check that
        each time is inside its window), shape (m, 2d) each; with ``component``, that one only (m,)."""
        t, k = np.asarray(t, np.float64), np.asarray(k, np.int64)
        length = self.length_of(k)
        theta = ((t - self.edges[k]) - self.offsets[k]) / length
        basis = shifted_legendre(theta, self.stages)  # (m, s + 1)
        weights = np.stack([theta[:, None] * (basis[:, :-1] @ self._tab.value.T), basis @ self._tab.rate.T], axis=1)
        pick = slice(None) if component is None else slice(component, component + 1)
        z, e = self.z[k, pick], self.e[k, pick]
        both = self._weighted_rows(weights, k, pick)  # (m, 2, 2d): ẑ − z_k and h·dẑ/dt
        value, rate = z + (e + both[:, 0]), both[:, 1] / length[:, None]
        return (value, rate) if component is None else (value[:, 0], rate[:, 0])

    def _weighted_rows(self, weights: np.ndarray, k: np.ndarray, pick: slice) -> np.ndarray:
        """weights (m, 2, s) times the stage increments of windows k: (m, 2, columns). Where a
        copy of every time's rows would be large and the times are many per window, one product
        per window instead (NLS on 512 points at 2 000 times in 12 windows: 260 MB gathered, 0.8 s
        the first time)."""
        columns = len(range(*pick.indices(self.system.state_dim)))
        if k.size * self.stages * columns * 8 <= _GATHER_BYTES:
            return weights @ self._stage_rows(k, pick)
        unique, where = np.unique(k, return_inverse=True)
        if 4 * unique.size > k.size:
            return weights @ self._stage_rows(k, pick)
        rows = self._stage_rows(unique, pick)  # (u, s, columns)
        ordered = bool(np.all(np.diff(where) >= 0))  # times in order (the usual case): no sorting
        order = np.arange(k.size) if ordered else np.argsort(where, kind="stable")
        flat = weights[order].reshape(-1, self.stages)  # (2m, s), grouped by window
        bounds = 2 * np.searchsorted(where[order], np.arange(unique.size + 1))
        out = np.empty((2 * k.size, columns))
        for j in range(unique.size):
            np.matmul(flat[bounds[j]:bounds[j + 1]], rows[j], out=out[bounds[j]:bounds[j + 1]])
        out = out.reshape(k.size, 2, columns)
        return out if ordered else out[np.argsort(order)]

    def pieces(self) -> list[tuple[Any, float, float, float]]:
        raise NotImplementedError("a polynomial solution has no network pieces; its estimate() compares it "
                                  "with a companion solution")

    # ------------------------------------------------------------------ the error estimate
    def estimate(self, z0: Any = None) -> ErrorEstimate:
        """The a-posteriori error estimate against the companion solution (windows half as long):
        at every window start the difference itself, and for every half window the largest
        difference along it (per component, the two polynomials' difference sampled at 3(s + 1)
        Chebyshev points of the half), placed at the half's middle. ``z0`` is accepted for the
        common interface; the state at t0 is exact here."""
        cached = self.__dict__.get("_estimate")
        if cached is not None:
            return cached
        companion = self.companion()
        n, tab = self.n_windows, self._tab
        # the largest value of a degree-s polynomial is within 1/cos(π/6) ≈ 1.15 of its largest at
        # 3(s + 1) Chebyshev–Lobatto points
        points = 3 * (self.stages + 1)
        grid = shifted_legendre(0.5 * (1.0 - np.cos(np.pi * np.arange(points) / (points - 1))), self.stages)
        nodes_t, nodes_d = [], []
        block = max(1, -(-n // (_MAX_NODES // 3)))  # windows per kept node (1: every window kept)
        for a in range(0, n, _EVAL_CHUNK):
            k = np.arange(a, min(a + _EVAL_CHUNK, n))
            G = np.einsum("jc,kjn->kcn", tab.series, self._stage_rows(k))  # (m, s + 1, 2d) about z_k + e_k
            c = np.stack([2 * k, 2 * k + 1], axis=1)  # the companion's halves of window k
            Gc = np.einsum("jc,kjn->kcn", tab.series, companion._stage_rows(c.reshape(-1))).reshape(
                k.size, 2, self.stages + 1, -1)
            shift = (companion.z[c] - self.z[k][:, None]) + (companion.e[c] - self.e[k][:, None])  # (m, 2, 2d)
            D = Gc - np.einsum("hcd,kdn->khcn", tab.halves, G)
            D[:, :, 0] += shift
            bound = np.abs(np.einsum("gc,khcn->khgn", grid, D)).max(axis=2)  # (m, 2, 2d)
            start, length = self.edges[k], self.length_of(k)
            t = np.stack([start, start + 0.25 * length, start + 0.75 * length], axis=1)  # (m, 3)
            d = np.concatenate([shift[:, :1], bound], axis=1)  # (m, 3, 2d)
            if block > 1:  # of every block of windows, the one of the largest error
                worst = np.abs(d).max(axis=(1, 2))
                padded = np.pad(worst, (0, -worst.size % block), constant_values=-1.0).reshape(-1, block)
                pick = np.arange(0, worst.size, block) + np.argmax(padded, axis=1)
                t, d = t[pick], d[pick]
            nodes_t.append(t.reshape(-1))
            nodes_d.append(d.reshape(-1, d.shape[-1]))
        t_all = np.append(np.concatenate(nodes_t), self.edges[-1])
        end = companion(np.asarray([self.edges[-1]])) - self(np.asarray([self.edges[-1]]))
        z_all = self(t_all)
        est = ErrorEstimate(t_all, _at_least_roundoff(np.concatenate(nodes_d + [end]), z_all), z_all, steps=[3],
                            converged=True)
        self.__dict__["_estimate"] = est
        return est

    # ------------------------------------------------------------------ attributes
    @property
    def lengths(self) -> np.ndarray:
        """The windows' lengths (n,): the differences of the edges with their offsets."""
        return np.diff(self.edges) + np.diff(self.offsets)

    def length_of(self, k: np.ndarray) -> np.ndarray:
        """The lengths of windows k (as `lengths` has them, without the whole array)."""
        return (self.edges[k + 1] - self.edges[k]) + (self.offsets[k + 1] - self.offsets[k])

    @property
    def interval(self) -> tuple[float, float]:
        return float(self.edges[0]), float(self.edges[-1])

    @property
    def t0(self) -> float:
        return float(self.edges[0])

    @property
    def z0(self) -> np.ndarray:
        return self.z[0] + self.e[0]

    @property
    def n_windows(self) -> int:
        return int(self.edges.size - 1)

    @property
    def end_state(self) -> np.ndarray:
        """ẑ(T), the last window's end."""
        return self(np.asarray([self.edges[-1]]))[0]

"""The solution of a time-transformed Gauss march, in physical time.

The march solved the extended system (q, t; p, p_t) in a fictitious time τ
(:mod:`atlasnn.solver._gauss_time`): a :class:`PolynomialSolution` in τ whose component t(τ)
increases (dt/dτ = g > 0). A physical time t* is found on it by its window — the one whose ends'
times bracket t* — and in that window by Newton's method on t(τ) = t*, kept inside the bracket (a
step that leaves it bisects instead), vectorised over the times; the state there is the
physical part of the extended one, and dz/dt = (dz/dτ)/(dt/dτ).

Its error estimate is the extended solution's companion (windows half as long, in τ, and p_t moved
by the rounding of H(z0): ``energy_rounding``) read at the same physical times: the difference
carries the error of t(τ) and of the energy kept as well as that of the state.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import jax
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solutions._base import AbstractSolution, check_inside, finite_times
from atlasnn.solutions._estimate import ErrorEstimate
from atlasnn.solutions._polynomial import PolynomialSolution, _at_least_roundoff
from atlasnn.solutions._solution import check_outside_mode
from atlasnn.solutions._tableau import gauss_tableau, shifted_legendre
from atlasnn.systems import HamiltonianSystem

__all__ = ["TimeTransformedSolution"]

#: Newton (or bisection) steps at most per time: Newton converges in 3–6 where g is resolved by
#: the window; a bisection halves the bracket, and 60 of them reach round-off from any window
_MAX_STEPS = 60
#: times evaluated at once
_EVAL_CHUNK = 65_536
#: the most nodes an error estimate keeps (three a window below it)
_MAX_NODES = 1_000_000


@dataclass(eq=False)
class TimeTransformedSolution(AbstractSolution):
    """A solution over [t0, T] in physical time, from the extended solution in τ, callable at any times.

    Attributes:
        system: the (physical) Hamiltonian system, d degrees of freedom.
        extended: the solution in τ of the extended system, states (q, t, p, p_t) of 2d + 2
            components.
        end: T, the end of the interval (the extended march's last window ends past it).
        info: the solver's record (settings, counts, times; window lengths in τ).
        outside: what evaluating outside [t0, T] does (as for ``Solution``).
    """

    interval_name: ClassVar[str] = "interval"

    system: HamiltonianSystem
    extended: PolynomialSolution
    end: float
    info: dict[str, Any] = field(default_factory=dict)
    outside: str = "warn"
    _warned: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        check_outside_mode(self.outside)
        d = self.system.dim
        if self.extended.system.dim != d + 1:
            raise ConfigError(f"a time-transformed solution of {d} degrees of freedom needs an extended one of "
                              f"{d + 1}, got {self.extended.system.dim}")
        self.clock = d
        self._physical = np.r_[0:d, d + 1:2 * d + 1]
        last = self.extended.window_values(self.extended.edges[-1:], np.asarray([self.extended.n_windows - 1]), d)[0]
        self.times = np.append(self.extended.z[:, d] + self.extended.e[:, d], last)  # t at the window edges
        if not np.all(np.diff(self.times) > 0):
            raise ConfigError("a time-transformed solution needs its time to increase from window to window")
        self.end = float(min(self.end, self.times[-1]))

    # ------------------------------------------------------------------ evaluation
    def tau(self, t) -> tuple[np.ndarray, np.ndarray]:
        """τ at physical times t, and the window holding each: (τ, k), t's shape. In the window,
        Newton's method on t(θ) = t* for θ = (τ − τ_k)/h_k, from ``_start``, each step kept
        inside the bracket of the θs tried (bisecting where it would leave it), until t(θ) is t* to
        a few of its ulps (a further Newton step would be round-off divided by g: many ulps of θ
        where g is small), θ stops moving or the bracket closes."""
        t = np.asarray(t, np.float64)
        flat = t.reshape(-1)
        ext, eps = self.extended, np.finfo(np.float64).eps
        k = np.clip(np.searchsorted(self.times[1:-1], flat, side="right"), 0, ext.n_windows - 1)
        value, rate, nodes = self._coefficients(k)
        theta = self._start(flat, k, nodes)
        lo, hi = np.zeros_like(theta), np.ones_like(theta)
        roundoff = 4 * eps * np.maximum(np.abs(flat), np.abs(self.times[k + 1]))
        z, e = ext.z[k, self.clock], ext.e[k, self.clock]
        active = np.arange(flat.size)
        for _ in range(_MAX_STEPS):
            if active.size == 0:
                break
            th = theta[active]
            basis = shifted_legendre(th, ext.stages)
            miss = z[active] + (e[active] + th * np.einsum("ms,ms->m", basis[:, :-1], value[active])) - flat[active]
            slope = np.einsum("ms,ms->m", basis, rate[active])  # dt/dθ = h·g
            lo[active] = np.where(miss < 0, th, lo[active])
            hi[active] = np.where(miss > 0, th, hi[active])
            with np.errstate(divide="ignore", invalid="ignore"):
                new = th - miss / slope
            new = np.where(np.isfinite(new) & (new >= lo[active]) & (new <= hi[active]), new,
                           0.5 * (lo[active] + hi[active]))
            done = (np.abs(miss) <= roundoff[active]) | (np.abs(new - th) <= 2 * eps) \
                | (hi[active] - lo[active] <= 2 * eps)
            theta[active] = np.where(miss == 0, th, new)
            active = active[~done]
        tau = ext.edges[k] + theta * (ext.edges[k + 1] - ext.edges[k])
        return tau.reshape(t.shape), k.reshape(t.shape)

    def _start(self, flat: np.ndarray, k: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """θ where window k's t(θ) is each time, interpolated linearly between its values at the
        window's ends and at its s Gauss nodes (the stage values' t: no polynomial to evaluate;
        Newton's method then takes 2–3 steps where the window's ends alone took 5–6)."""
        c = np.concatenate([[0.0], gauss_tableau(self.extended.stages).c, [1.0]])
        values = np.concatenate([self.times[k, None], self.times[k, None] + nodes, self.times[k + 1, None]], axis=1)
        j = np.clip(np.sum(values <= flat[:, None], axis=1) - 1, 0, c.size - 2)
        below = np.take_along_axis(values, j[:, None], 1)[:, 0]
        above = np.take_along_axis(values, j[:, None] + 1, 1)[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.clip((flat - below) / (above - below), 0.0, 1.0)
        return c[j] + (c[j + 1] - c[j]) * np.where(np.isfinite(x), x, 0.5)

    def _coefficients(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What windows k's polynomial of t is made of: the Legendre coefficients of its value, Vᵀl
        (len(k), s), and of its rate, Wᵀl (len(k), s + 1), and its values at the Gauss nodes less
        the window's start, μl (len(k), s) (l: the window's increments of t); kept once computed
        where the increments are kept (a general product of every component per Newton step took
        4× as long)."""
        ext, tab = self.extended, gauss_tableau(self.extended.stages)
        if ext.L is None:
            increments = ext.window_increments(k, self.clock)
            return increments @ tab.value, increments @ tab.rate, increments @ tab.mu.T
        if "_clock_coefficients" not in self.__dict__:
            increments = ext.L[:, :, self.clock]
            self.__dict__["_clock_coefficients"] = (increments @ tab.value, increments @ tab.rate,
                                                    increments @ tab.mu.T)
        return tuple(part[k] for part in self.__dict__["_clock_coefficients"])

    def _evaluate(self, t) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        arr = finite_times(t)
        flat = arr.reshape(-1)
        check_inside(self, self.interval, flat)
        n = self.system.state_dim
        z, dz = np.empty((flat.size, n)), np.empty((flat.size, n))
        for a in range(0, flat.size, _EVAL_CHUNK):
            tau, k = self.tau(flat[a:a + _EVAL_CHUNK])
            Z, dZ = self.extended.window_values(tau, k)
            z[a:a + _EVAL_CHUNK] = Z[:, self._physical]
            dz[a:a + _EVAL_CHUNK] = dZ[:, self._physical] / dZ[:, self.clock:self.clock + 1]
        return z.reshape(arr.shape + (n,)), dz.reshape(arr.shape + (n,)), arr.shape

    def pieces(self) -> list[tuple[Any, float, float, float]]:
        raise NotImplementedError("a time-transformed solution has no network pieces; its estimate() compares it "
                                  "with a companion solution")

    # ------------------------------------------------------------------ the error estimate
    def companion(self) -> "TimeTransformedSolution":
        """The extended solution's companion (windows half as long in τ) in physical time."""
        kept = self.__dict__.get("_companion")
        if kept is None:
            start = np.array(self.extended.z0, np.float64)
            start[-1] -= self.energy_rounding()
            kept = self.__dict__["_companion"] = TimeTransformedSolution(
                self.system, self.extended.companion_from(start), self.end, {"companion_of": self.info.get("solver")},
                outside="allow")
        return kept

    def energy_rounding(self) -> float:
        """How far H(z0) in float64 may be from H at z0: eps·(|H(z0)| + Σ|z0_i ∂H/∂z_i|), what one
        rounding of each component moves H by. The march in τ keeps H at −p_t = H(z0) as float64
        gave it, so this rounding is an error of the energy it keeps all along; the companion starts
        with p_t moved by it. (Kepler's problem at e = 0.99 from pericentre: H = 99.5 − 100 lost
        41 ulps of −0.5, and the period that energy gives put the pericentre two periods on 3.5e-9
        off, where a companion from the same p_t agreed to 3e-11.)"""
        z0 = self.z0[None]
        with jax.enable_x64(True):
            grad = np.asarray(self.system.grad(z0))[0]
        H = float(self.system.energy64(z0)[0])
        return float(np.finfo(np.float64).eps * (abs(H) + np.abs(z0[0] * grad).sum()))

    def error_estimate(self, t) -> np.ndarray:
        """The estimated error z(t) − ẑ(t) at times of the interval (the companion minus this solution
        at those times, at least an ulp of ẑ): shape t.shape + (2d,); NaN outside the interval."""
        arr = np.asarray(t, np.float64)
        check_inside(self, self.interval, arr.reshape(-1))
        t0, T = self.interval
        inside = np.clip(arr, t0, T)
        mine = self(inside)
        out = _at_least_roundoff(self.companion()(inside) - mine, mine)
        out[(arr < t0) | (arr > T)] = np.nan
        return out

    def estimate(self, z0: Any = None) -> ErrorEstimate:
        """The error estimate: the companion minus this solution at 3(s + 1) Chebyshev points in τ of
        each half window (fewer where the windows are many: at most ``_MAX_NODES`` points), for
        each half its largest difference per component placed at its worst point, and at T.
        Three points a window missed the largest error inside it and said "accurate" of answers
        3–6x over (Kepler e = 0.97 from apocentre at rtol 1e-8). ``z0`` is accepted for the
        common interface; the state at t0 is exact here."""
        cached = self.__dict__.get("_estimate")
        if cached is not None:
            return cached
        ext, companion = self.extended, self.companion()
        n = ext.n_windows
        points = int(np.clip(_MAX_NODES // (2 * n), 2, 3 * (ext.stages + 1)))
        grid = 0.5 * (1.0 - np.cos(np.pi * np.arange(points) / (points - 1)))  # on [0, 1]
        theta = 0.5 * (np.arange(2)[None, :, None] + grid[None, None, :])  # the halves' points, (1, 2, points)
        step = max(1, -(-2 * n * points // _MAX_NODES))  # every step-th window where even 2 points are too many
        windows = np.arange(0, n, step)
        ts, ds, zs = [], [], []
        block = max(1, _EVAL_CHUNK // (2 * points))
        for a in range(0, windows.size, block):
            k = windows[a:a + block]
            start, length = ext.edges[k], ext.length_of(k)
            tau = (start[:, None, None] + length[:, None, None] * theta).reshape(-1)
            Z = ext.window_values(tau, np.repeat(k, 2 * points))[0]
            t, z = Z[:, self.clock], Z[:, self._physical]
            inside = t <= self.end
            d = np.where(inside[:, None], companion(np.minimum(t, self.end)) - z, 0.0)
            d, t, z = (x.reshape(k.size * 2, points, -1) for x in (d, t[:, None], z))
            halves = np.arange(k.size * 2)
            worst = np.argmax(np.abs(d).max(axis=2), axis=1)  # each half's worst point
            keep = inside.reshape(k.size * 2, points).any(axis=1)
            ts.append(t[halves, worst, 0][keep])
            ds.append(np.abs(d).max(axis=1)[keep])
            zs.append(z[halves, worst][keep])
        end = np.asarray([self.end])
        z_end = self(end)
        t = np.concatenate(ts + [end])
        z = np.concatenate(zs + [z_end])
        d = np.concatenate(ds + [companion(end) - z_end])
        cached = self.__dict__["_estimate"] = ErrorEstimate(t, _at_least_roundoff(d, z), z, steps=[3],
                                                            converged=True)
        return cached

    # ------------------------------------------------------------------ attributes
    @property
    def interval(self) -> tuple[float, float]:
        return float(self.times[0]), self.end

    @property
    def t0(self) -> float:
        return float(self.times[0])

    @property
    def edges(self) -> np.ndarray:
        """The windows' edges in physical time (the last one at T; the extended march's last window
        ends past it)."""
        inside = self.times[self.times < self.end]
        return np.append(inside, self.end)

    @property
    def z0(self) -> np.ndarray:
        return self.extended.z0[self._physical]

    @property
    def n_windows(self) -> int:
        return self.extended.n_windows

    @property
    def stages(self) -> int:
        return self.extended.stages

    @property
    def check(self) -> np.ndarray | None:
        return self.extended.check

    @property
    def end_state(self) -> np.ndarray:
        """ẑ(T)."""
        return self(np.asarray([self.end]))[0]

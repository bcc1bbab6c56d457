"""The solution of a time-transformed Gauss march, in physical time.

The march solved the extended system (q, t; p, p_t) in a fictitious time τ
(:mod:`atlasnn.solver._gauss_time`): a :class:`PolynomialSolution` in τ whose component t(τ)
increases (dt/dτ = g > 0). A physical time t* is found on it by its window — the one whose ends'
times bracket t* — and in that window by Newton's method on t(τ) = t*, kept inside the bracket (a
step that leaves it bisects instead), vectorised over the times; the state there is the
physical part of the extended one, and dz/dt = (dz/dτ)/(dt/dτ).

Its error estimate is the extended solution's companion (windows half as long, in τ) read at the
same physical times: the difference carries the error of t(τ) as well as that of the state.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solutions._base import AbstractSolution, check_inside, finite_times
from atlasnn.solutions._estimate import ErrorEstimate
from atlasnn.solutions._polynomial import PolynomialSolution, _at_least_roundoff
from atlasnn.solutions._solution import check_outside_mode
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
        outside: what evaluating outside [t0, T] does (as for :class:`Solution`).
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
    def tau(self, t) -> np.ndarray:
        """τ at physical times t (t's shape), and the window holding it: (τ, k)."""
        t = np.asarray(t, np.float64)
        flat = t.reshape(-1)
        ext = self.extended
        k = np.clip(np.searchsorted(self.times[1:-1], flat, side="right"), 0, ext.n_windows - 1)
        lo, hi = ext.edges[k].copy(), ext.edges[k + 1].copy()
        t_lo, t_hi = self.times[k], self.times[k + 1]
        tau = lo + (hi - lo) * np.clip((flat - t_lo) / (t_hi - t_lo), 0.0, 1.0)
        active = np.arange(flat.size)
        for _ in range(_MAX_STEPS):
            if active.size == 0:
                break
            value, rate = ext.window_values(tau[active], k[active], self.clock)
            miss = value - flat[active]
            lo[active] = np.where(miss < 0, tau[active], lo[active])
            hi[active] = np.where(miss > 0, tau[active], hi[active])
            with np.errstate(divide="ignore", invalid="ignore"):
                new = tau[active] - miss / rate
            inside = np.isfinite(new) & (new >= lo[active]) & (new <= hi[active])
            new = np.where(inside, new, 0.5 * (lo[active] + hi[active]))
            done = (miss == 0) | (np.abs(new - tau[active]) <= 2 * np.finfo(np.float64).eps * np.abs(tau[active])) \
                | (hi[active] - lo[active] <= 2 * np.finfo(np.float64).eps * np.abs(tau[active]))
            tau[active] = np.where(miss == 0, tau[active], new)
            active = active[~done]
        return tau.reshape(t.shape), k.reshape(t.shape)

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
            kept = self.__dict__["_companion"] = TimeTransformedSolution(
                self.system, self.extended.companion(), self.end, {"companion_of": self.info.get("solver")},
                outside="allow")
        return kept

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
        """The error estimate at three times per window (its start and the middles of its halves in
        τ, read as physical times) and at T: the companion minus this solution there. ``z0`` is
        accepted for the common interface; the state at t0 is exact here."""
        cached = self.__dict__.get("_estimate")
        if cached is None:
            ext = self.extended
            starts, lengths = ext.edges[:-1], np.diff(ext.edges)
            tau = np.stack([starts, starts + 0.25 * lengths, starts + 0.75 * lengths], axis=1).reshape(-1)
            step = max(1, -(-tau.size // _MAX_NODES))
            tau = tau[::step]
            k = np.repeat(np.arange(ext.n_windows), 3)[::step]
            t = ext.window_values(tau, k, self.clock)[0]
            t = np.append(t[t < self.end], self.end)
            z = self(t)
            cached = self.__dict__["_estimate"] = ErrorEstimate(
                t, _at_least_roundoff(self.companion()(t) - z, z), z, steps=[3], converged=True)
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

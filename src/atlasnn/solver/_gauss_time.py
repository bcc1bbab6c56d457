"""The time transformation of the Gauss collocation (``GaussCollocation(time_scale=...)``): windows
short where bodies are close and long elsewhere, the method still symplectic.

A march of constant windows in t takes the length the closest approach needs for the whole
interval (one near-collision of three bodies: millions of windows); adaptive lengths are not
symplectic. Instead the time is changed: with a scale g(q, p) > 0 and a fictitious time τ,

    dt/dτ = g(q, p),

small where the motion is fast. Poincaré's transformation makes this Hamiltonian in the extended
phase space (q, t; p, p_t) of d + 1 degrees of freedom (Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, VIII.2):

    K(q, t, p, p_t) = g(q, p) · (H(q, p) + p_t),     p_t(0) = −H(z0),

so that K = 0 on the solution, p_t is constant (H does not depend on t; the Gauss method keeps
that linear invariant exactly), and Hamilton's equations of K are those of H with the time scaled
by g. The extended system is marched in τ by the same Gauss method on windows of one τ-length
(found over the warm-up, only ever shortened): a symplectic map of the extended space, whatever g
does, until the physical time — a component of the extended state — reaches T
(:mod:`._gauss_march`, ``until``). Its energy error is K/g: bounded, as the error of a symplectic
method's invariant is, but multiplied by 1/g during an encounter (docs/howto/CLOSE_ENCOUNTERS.md).

``time_scale="potential"``: g = (−V(q))^(−3/2), V(q) = H(q, 0) the potential of a separable H
(H = T(p) + V(q), T(0) = 0) that is negative everywhere and vanishes far away — gravitational
N-body problems, Kepler's: r^(3/2) there, the free-fall time at that distance, and for N bodies
1/(Σ m_i m_j/r_ij)^(3/2). Measured against g = 1/(−V) (r for Kepler): 65 and 87 windows for ten
periods of Kepler e = 0.9 and 0.99 against 197 and 622, 48 and 362 against 371 and 9 432 for the
Pythagorean three-body problem to t = 10 and 60 (benchmarks/time_transform.py). Any other scale
is a function g(q, p) of the user's (JAX-traceable, > 0 and finite along the orbit).
"""

from __future__ import annotations

import functools
import weakref
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import program_cache
from atlasnn.errors import ConfigError
from atlasnn.solutions import PolynomialSolution, TimeTransformedSolution
from atlasnn.solver._gauss_stops import states_ahead
from atlasnn.systems import HamiltonianSystem

__all__ = ["AUTO", "SCALE_VARIATION", "ScaleVaries", "ScaleWatch", "TIME_SCALES", "TimeTransform", "WATCH_FIRST",
           "check_time_scale", "describe_time_scale", "march_advice", "poincare_system", "potential_applies",
           "potential_scale_values"]

#: the scales chosen by name (any other is a function g(q, p))
TIME_SCALES = ("potential",)
#: the default: march in t, and in τ with "potential" once a march in t shows it needs it (:class:`ScaleWatch`)
AUTO = "auto"
#: how many-fold g = (−V)^(−3/2) varies over a march's windows in t before the default marches in τ
#: instead (and before a march in t given ``time_scale=None`` advises it): Kepler e = 0.6 (8-fold)
#: stays in t, where the two cost the same; e = 0.9 (80-fold) takes 2 403 windows in t, 65 in τ
#: (benchmarks/time_transform.py)
SCALE_VARIATION = 20.0
#: the windows of a watched march's first call, each later call's twice the last's (up to the
#: chunk): what a switch to τ throws away is at most about twice what the march in t needed to show
#: it, beyond these (the Pythagorean problem: g varies 1 900-fold over its first 128 windows in t).
#: Each call and look costs about 1–2 ms: on Kepler e = 0.6 (273 windows in t, two calls) 15.1
#: against 12.4 ms for the call with its values (benchmarks/time_transform.py)
WATCH_FIRST = 128


class ScaleVaries(Exception):
    """Raised between calls of a default march in t that :class:`ScaleWatch` found to need τ; its
    text says why (recorded in the solution's ``info["time_scale_chosen"]``)."""


class ScaleWatch:
    """The default's watch on a march of constant lengths in t of a system ``"potential"`` suits:
    the range of g = (−V)^(−3/2) over each member's window starts so far (:meth:`see` after each
    call of the march's program), and the reason to march in τ instead once it spans ``SCALE_VARIATION``-fold for a
    member (:meth:`reason`; None while it does not). A g that is not finite and positive (V ≥ 0
    on the way) turns the watch off for that member: the scale does not apply there."""

    def __init__(self, system: HamiltonianSystem, members: int):
        self.system = system
        self.low, self.high = np.full(members, np.inf), np.zeros(members)
        self.off = np.zeros(members, bool)
        self.windows = np.zeros(members, int)

    def see(self, m: int, z: np.ndarray) -> None:
        if self.off[m] or len(z) == 0:
            return
        g = potential_scale_values(self.system, z)
        if not np.all(np.isfinite(g) & (g > 0)):
            self.off[m] = True
            return
        self.low[m], self.high[m] = min(self.low[m], g.min()), max(self.high[m], g.max())
        self.windows[m] += len(z)

    def reason(self) -> str | None:
        fold = np.where(self.off, 0.0, scale_fold(self.low, self.high))
        m = int(np.argmax(fold))
        if fold[m] < SCALE_VARIATION:
            return None
        return (f"the time scale (−V)^(−3/2) varied {fold[m]:.0f}-fold over the first {self.windows[m]} windows "
                "of constant length in t")


def check_time_scale(value: Any) -> None:
    """Refuse, in one line, a ``time_scale`` that is none of None, "auto", a name of
    :data:`TIME_SCALES`, a function."""
    if value is None or callable(value) or (isinstance(value, str) and value in (AUTO,) + TIME_SCALES):
        return
    raise ConfigError(f"GaussCollocation time_scale must be None, {AUTO!r}, one of {list(TIME_SCALES)} or a function "
                      f"g(q, p) > 0, got {value!r}")


def describe_time_scale(value: Any) -> str | None:
    """The scale as a record keeps it: its name, or the function's."""
    if value is None or isinstance(value, str):
        return value
    return f"g = {getattr(value, '__qualname__', type(value).__name__)}"


def _potential_scale(system: HamiltonianSystem) -> Callable:
    if not system.separable:
        raise ConfigError(f"GaussCollocation time_scale 'potential' needs a separable H = T(p) + V(q); system "
                          f"{system.name!r} is not declared separable (give g(q, p) as time_scale instead)")

    def g(q, p):
        return (-system.hamiltonian(q, jnp.zeros_like(p))) ** -1.5

    return g


def potential_applies(system: HamiltonianSystem, z0: Any) -> bool:
    """Whether ``time_scale="potential"`` suits ``system`` by the look of it at the first z0 it is
    asked about (kept per system): H declared separable, and V(q) = H(q, 0) negative at q0 and
    homogeneous of degree −1 there (V(λq0) = V(q0)/λ for λ = 1/2, 2, 10 to 1e-9), as a sum of
    −m_i m_j/r_ij is — gravitational N bodies and Kepler's problem. It decides whether the default
    (``"auto"``) watches g along a march in t (:class:`ScaleWatch`), and the advice a stopped or
    slow march gives."""
    if not system.separable:
        return False
    known = _SUITS.get(system)
    if known is None:
        lams = np.array([1.0, 0.5, 2.0, 10.0])
        try:
            v = _potential(system, lams[:, None] * np.asarray(z0, np.float64)[: system.dim])
        except Exception:  # noqa: BLE001 - H not evaluable there: no advice, the march's own line stands
            v = np.full(lams.size, np.nan)
        known = _SUITS[system] = bool(np.isfinite(v[0]) and v[0] < 0 and np.all(np.abs(v[1:] * lams[1:] / v[0] - 1)
                                                                                 <= 1e-9))
    return known


def march_advice(system: HamiltonianSystem, length: np.ndarray, z: np.ndarray, warmup: int) -> str | None:
    """A line for a march of constant lengths in t through time scales that differ along the orbit
    (``length``: its windows' lengths, ``z``: their starts): for a system ``time_scale="potential"``
    suits, when the scale g varies ``SCALE_VARIATION``-fold or more over the windows (an eccentric
    orbit, a close approach: the constant length is the shortest time scale's throughout);
    otherwise when the length had to shrink 8-fold or more after the warm-up, adaptive lengths."""
    if len(z) < 2:
        return None
    if potential_applies(system, z[0]):
        g = potential_scale_values(system, z)
        fold = float(scale_fold(g.min(), g.max()))
        if fold >= SCALE_VARIATION:
            return (f"the time scale (−V)^(−3/2) varies {fold:.0f}-fold over the windows: "
                    "time_scale='potential' would take fewer windows, symplectic "
                    "(docs/howto/CLOSE_ENCOUNTERS.md)")
        return None
    kept = length[warmup:-1]
    if kept.size < 2 or kept.max() <= 8 * kept.min():
        return None
    return (f"the window length shrank {kept.max() / kept.min():.0f}-fold after the warm-up (time scales that "
            "differ along the orbit): steps='adaptive' would take fewer windows (not symplectic: "
            "docs/SOLVER.md, 'Window lengths')")


def scale_fold(low, high) -> np.ndarray:
    """How many-fold g varies from ``low`` to ``high`` (0 where ``low`` is not positive: no range)."""
    low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
    return np.where(low > 0, high / np.where(low > 0, low, 1.0), 0.0)


def potential_scale_values(system: HamiltonianSystem, z: np.ndarray) -> np.ndarray:
    """g = (−V(q))^(−3/2) of ``time_scale="potential"`` at host states z (m, 2d), in float64."""
    return (-_potential(system, np.asarray(z, np.float64)[:, : system.dim])) ** -1.5


#: positions per evaluation of V (padded to it): one program, and one call, for every count the
#: watch sees (128, 256, 512, 1 024 windows a call), where each count compiled its own (0.13 s
#: each for the outer solar system's expression)
_POTENTIAL_ROWS = 1024


def _potential(system: HamiltonianSystem, q: np.ndarray) -> np.ndarray:
    """V(q) = H(q, 0) at host positions q (m, d), in float64."""
    z = np.concatenate([q, np.zeros_like(q)], axis=1)
    out = []
    for a in range(0, len(z), _POTENTIAL_ROWS):
        block = z[a:a + _POTENTIAL_ROWS]
        padded = np.concatenate([block, np.repeat(block[-1:], _POTENTIAL_ROWS - len(block), axis=0)])
        out.append(system.energy64(padded)[:len(block)])
    return np.concatenate(out) if out else np.zeros(0)


#: systems asked about by ``potential_applies``, and its answer
_SUITS: "weakref.WeakKeyDictionary[HamiltonianSystem, bool]" = weakref.WeakKeyDictionary()


@program_cache
@functools.lru_cache(maxsize=32)
def poincare_system(system: HamiltonianSystem, time_scale: Any) -> HamiltonianSystem:
    """The extended system K(q, t, p, p_t) = g(q, p)·(H(q, p) + p_t) of d + 1 degrees of freedom,
    its coordinates (q, t) and momenta (p, p_t) (module docstring); one object per system and scale
    (it keys the compiled programs)."""
    d, H = system.dim, system.hamiltonian
    g = _potential_scale(system) if time_scale == "potential" else time_scale

    def poincare(qt, pp):
        q, p = qt[:d], pp[:d]
        return jnp.asarray(g(q, p)).reshape(()) * (jnp.asarray(H(q, p)).reshape(()) + pp[d])

    taken = set(system.state_names)
    t_name = next(n for n in ("t", "time", "t_") if n not in taken)
    pt_name = next(n for n in ("p_t", "p_time", "p_t_") if n not in taken)
    return HamiltonianSystem(poincare, d + 1, name=f"{system.name}-poincare", q_names=system.q_names + (t_name,),
                             p_names=system.p_names + (pt_name,))


@program_cache
@functools.lru_cache(maxsize=32)
def _compiled_rate(extended: HamiltonianSystem, clock: int) -> Callable:
    """dt/dτ = g at extended states (m, 2d + 2), compiled (once per system)."""
    return jax.jit(lambda Z: extended.vector_field(Z)[..., clock])


class TimeTransform:
    """One system's time transformation: the extended system, the lift of initial states into it,
    and the solution in physical time from the extended one."""

    def __init__(self, system: HamiltonianSystem, time_scale: Any):
        self.system = system
        self.extended = poincare_system(system, time_scale)
        self.clock = system.dim  # the index of t in the extended state
        self.label = describe_time_scale(time_scale)

    def lift(self, z0s: np.ndarray, t0: float) -> np.ndarray:
        """(q, t0, p, −H(z0)) per row of z0s (m, 2d), after checking g there: positive and finite
        (refused in one line otherwise)."""
        z0s = np.atleast_2d(np.asarray(z0s, np.float64))
        d = self.system.dim
        rows = np.concatenate([z0s[:, :d], np.full((len(z0s), 1), float(t0)), z0s[:, d:],
                               -self.system.energy64(z0s)[:, None]], axis=1)
        g = self.rate(rows)
        bad = np.flatnonzero(~(np.isfinite(g) & (g > 0)))
        if bad.size:
            raise ConfigError(self._line(float(g[bad[0]]), f"z0 = {z0s[bad[0]].tolist()}"))
        return rows

    def rate(self, Z: np.ndarray) -> np.ndarray:
        """g at extended states Z (m, 2d + 2)."""
        if self.label == "potential":  # V's program, which the watch compiled: none of its own
            return potential_scale_values(self.system, np.asarray(Z, np.float64)[:, :self.system.dim])
        with jax.enable_x64(True):
            return np.asarray(_compiled_rate(self.extended, self.clock)(np.asarray(Z, np.float64)))

    def _line(self, g: float, where: str) -> str:
        hint = ": V(q) = H(q, 0) must be < 0 there" if self.label == "potential" else ""
        return (f"GaussCollocation time_scale ({self.label}) must be finite and > 0 along the orbit, got g = {g!r} "
                f"at {where}{hint}; give a scale that stays positive and finite wherever the orbit goes")

    def stop_line(self, parts: list[PolynomialSolution | None]) -> str | None:
        """Where a march in τ stopped (``parts``: the extended solutions up to the stop) because g
        is not finite or not positive at the state reached or a little way along the flow from it
        (a potential V ≥ 0 ahead, say): the line naming the time scale, not H; else None."""
        for ext in parts:
            if ext is None or ext.n_windows == 0:
                continue
            Z = np.asarray(ext(ext.edges[-1]), np.float64).reshape(1, -1)
            with jax.enable_x64(True):
                rate = np.asarray(self.extended.vector_field(Z))
            g = self.rate(np.concatenate([Z, states_ahead(Z[0], rate[0])]))
            bad = np.flatnonzero(~(np.isfinite(g) & (g > 0)))
            if bad.size:
                return self._line(float(g[bad[0]]), f"t = {float(Z[0, self.clock]):.6g}" +
                                  ("" if bad[0] == 0 else ", just ahead along the flow"))
        return None

    def solutions(self, parts: list[PolynomialSolution | None], T: float
                  ) -> tuple[list[TimeTransformedSolution | None], str | None]:
        """The solutions in physical time on [t0, min(T, the time reached)] from the extended ones
        (None stays None), and the line saying where the first march's time stopped increasing
        (g ≤ 0 or not finite on the way; None: none did), its solution then cut before that window."""
        out, problem = [], None
        for part in parts:
            sol, line = self._physical(part, T)
            out.append(sol)
            problem = problem or line
        return out, problem

    def _physical(self, ext: PolynomialSolution | None, T: float) -> tuple[TimeTransformedSolution | None, str | None]:
        if ext is None:
            return None, None
        t = ext.z[:, self.clock] + ext.e[:, self.clock]
        stalled = np.flatnonzero(np.diff(t) <= 0)
        line = None
        if stalled.size:
            k = int(stalled[0]) + 1  # window k starts no later than window k - 1 did: keep windows before k - 1
            line = self._line(float(self.rate((ext.z + ext.e)[k:k + 1])[0]), f"t = {t[k]:.6g} (window {k})")
            if k < 2:
                return None, line
            keep = slice(0, k - 1)
            ext = PolynomialSolution(ext.system, ext.edges[:k], ext.z[keep], ext.e[keep],
                                     None if ext.L is None else ext.L[keep], ext.stages,
                                     None if ext.check is None else ext.check[keep], ext.info, resolve=ext.resolve,
                                     offsets=ext.offsets[:k])
        info = {**ext.info, "time_scale": self.label, "tau_interval": list(ext.interval)}
        return TimeTransformedSolution(self.system, ext, float(T), info), line

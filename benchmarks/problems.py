"""The problems the solver instruments share: the hard suite's and the long experiments' names,
Kepler's problem with its exact orbit, the Pythagorean three-body problem, and the reference where
no exact solution is known."""

from __future__ import annotations

import math
import statistics
import time

import numpy as np

from atlasnn import solve
from atlasnn.evaluation import reference_solution
from atlasnn.experiments.config import builtin_config_path, load_config
from atlasnn.solver import GaussCollocation
from atlasnn.systems import expression_system

HARD = ["figure-eight", "fpu-stiff", "henon-heiles-chaotic", "kepler-e06", "kepler-e09", "pendulum-separatrix",
        "toda-3"]
LONG = ["oscillator-long", "henon-heiles-long"]


def builtin_problem(name: str):
    """(system, z0, interval) of a built-in experiment's evaluation stage."""
    cfg = load_config(builtin_config_path(name))
    system = cfg.system.build()
    return system, np.asarray(system.z0), (float(cfg.eval_stage.t0), float(cfg.eval_stage.T))


def kepler_system(e: float, name: str | None = None):
    """Kepler's problem (a = 1, period 2π) started at pericentre with eccentricity ``e``."""
    return expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                             z0=[1 - e, 0.0, 0.0, math.sqrt((1 + e) / (1 - e))], separable=True, name=name or f"kepler-{e}")


#: the Pythagorean three-body problem (Burrau 1913; Szebehely & Peters 1967): masses 3, 4, 5 at rest
#: at the vertices of a 3-4-5 right triangle, each opposite the side of its length, G = 1
PYTHAGOREAN_MASSES = (3.0, 4.0, 5.0)
PYTHAGOREAN_Z0 = (1.0, 3.0, -2.0, -1.0, 1.0, -1.0) + (0.0,) * 6


def pythagorean_system():
    """The Pythagorean three-body problem in the plane (q = x1, y1, x2, y2, x3, y3): near-collisions
    (the closest, at t ≈ 15.83, brings two bodies within ~4e-4), then a binary and an escape after
    t ≈ 60. Energy −769/60."""
    m = PYTHAGOREAN_MASSES
    kinetic = " + ".join(f"(px{i + 1}**2 + py{i + 1}**2)/{2 * m[i]:g}" for i in range(3))
    pairs = " - ".join(f"{m[i] * m[j]:g}/sqrt((x{i + 1} - x{j + 1})**2 + (y{i + 1} - y{j + 1})**2)"
                       for i, j in ((0, 1), (0, 2), (1, 2)))
    q = [f"{c}{i + 1}" for i in range(3) for c in "xy"]
    return expression_system(f"{kinetic} - {pairs}", q, ["p" + n for n in q], z0=list(PYTHAGOREAN_Z0),
                             separable=True, name="pythagorean")


def kepler_exact(t, e: float, z0=None) -> np.ndarray:
    """The exact orbit from the float64 start ``z0`` at pericentre (default: kepler_system(e)'s),
    whose elements differ from the nominal a = 1 and ``e`` by the start's rounding — at e = 0.95
    that alone moves the velocity at pericentre by ~3e-11 of its range after 10 periods. The
    elements are computed from z0 at 40 digits (mpmath), Kepler's equation E − e sin E = M by
    Newton's method in float64."""
    import mpmath

    z0 = np.asarray(kepler_system(e).z0 if z0 is None else z0, np.float64)
    with mpmath.workdps(40):
        x0, py0 = mpmath.mpf(float(z0[0])), mpmath.mpf(float(z0[3]))
        a = -1 / (2 * (py0 ** 2 / 2 - 1 / x0))
        ecc = 1 - x0 / a
        a, ecc, n, w = float(a), float(ecc), float(a ** mpmath.mpf(-1.5)), float(mpmath.sqrt(1 - ecc ** 2))
    M = np.mod(n * np.asarray(t, np.float64), 2 * np.pi)
    E = np.where(ecc < 0.8, M + ecc * np.sin(M), np.pi * np.ones_like(M))
    for _ in range(60):
        E = E - (E - ecc * np.sin(E) - M) / (1 - ecc * np.cos(E))
    c, s = np.cos(E), np.sin(E)
    rate = n / (1 - ecc * c)  # dE/dt
    return np.stack([a * (c - ecc), a * w * s, -a * s * rate, a * w * c * rate], axis=-1)


def kepler_eccentricity(system, z0) -> float | None:
    """The eccentricity of a Kepler problem started at pericentre (a = 1), else None."""
    if not system.name.startswith("kepler") or z0[1] != 0.0 or z0[2] != 0.0:
        return None
    e = 1.0 - float(z0[0])
    return e if math.isclose(float(z0[3]), math.sqrt((1 + e) / (1 - e)), rel_tol=1e-12) else None


def gauss_reference(system, z0, interval, t):
    """(reference at t, its description, its gap to DOP853 at rtol 2.3e-14 relative to the range):
    the Gauss collocation with s = 16 on windows a quarter of the default's shortest."""
    default = solve(system, z0, interval, solver=GaussCollocation())
    h = float(np.diff(default.edges).min()) / 4
    ref = solve(system, z0, interval, solver=GaussCollocation(stages=16, h=h))(t)
    dop = reference_solution(system, z0, t, rtol=2.3e-14, atol=1e-16)
    gap = float(np.abs(ref - dop).max() / np.ptp(ref, axis=0).max())
    return ref, f"Gauss s = 16, h = {h:.3g}", gap


def timed(fn, repeats=3):
    """(the last result, the fastest time, the median time) of ``repeats`` calls of ``fn``."""
    times, out = [], None
    for _ in range(repeats):
        tic = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - tic)
    return out, min(times), statistics.median(times)

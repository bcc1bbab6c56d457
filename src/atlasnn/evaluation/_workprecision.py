"""Work–precision: the accuracy each method buys per second of computing.

For one problem (system, initial state, interval) and its evaluation grid t_1..t_E with the
reference solution on it, every method becomes points (wall time, error):

- the symplectic integrators (symplectic Euler, Störmer–Verlet, Yoshida-4) with N = m·(E − 1)
  steps for several m, so that every evaluation time is a step time (no interpolation);
- DOP853 (SciPy ``solve_ivp``) at several tolerances rtol = atol, reporting at t_1..t_E, its
  right-hand side NumPy code where the system has it written (the built-ins: a call costs a few µs)
  and the compiled JAX field elsewhere (about 16 µs a call: DOP853 is then slower than at its best,
  which ``WorkPoint.rhs`` records);
- network methods, given by the caller: the training wall time per seed (and, separately, the
  time to evaluate the trained solution at 10⁴ times, :func:`evaluation_seconds`).

The errors are the maximum |z − z_ref| over all components and times, the release-form L2 of the
first coordinate, sqrt(Σ_i err(t_i)²) on the evaluation grid (the paper's tables' number), and the
energy drift (:func:`~atlasnn.evaluation.energy_drift`). Times exclude JAX compilation (recorded
apart); each is the median of repeats that together last at least ``min_seconds``. Each point
records its right-hand-side (DOP853) or gradient (symplectic: steps × stages) evaluations, so a
time can be read against the work it bought. The figure is
drawn by :func:`atlasnn.report.plot_work_precision`.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import asdict, dataclass
from typing import Any, Callable, Sequence

import numpy as np

from atlasnn.evaluation._integrators import dop853, integrate
from atlasnn.evaluation._metrics import energy_drift
from atlasnn.systems import HamiltonianSystem, numpy_field

SYMPLECTIC = {"symplectic_euler": "symplectic Euler", "stormer_verlet": "Störmer–Verlet", "yoshida4": "Yoshida-4"}
#: gradient evaluations (∇V and ∇T each once) per step of each symplectic method
STAGES = {"symplectic_euler": 1, "stormer_verlet": 1, "yoshida4": 3}
STEP_MULTIPLES = (1, 2, 4, 8, 16, 32)
TOLERANCES = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)


@dataclass(frozen=True)
class WorkPoint:
    """One method at one setting: its cost and its errors on the evaluation grid."""

    method: str  # "symplectic_euler" | "stormer_verlet" | "yoshida4" | "dop853" | a network label
    setting: str  # "N=999", "tol=1e-06", "seed 3"
    seconds: float
    max_error: float
    l2_first: float
    energy_drift: float
    kind: str = "classical"  # "classical" | "network"
    compile_seconds: float = 0.0
    evaluations: int = 0  # right-hand-side (DOP853) or gradient (symplectic) evaluations; 0 for networks
    rhs: str = ""  # DOP853's right-hand side: "numpy" (written out) or "jax" (the compiled field)


def _timed(fn: Callable[[], Any], min_seconds: float, max_repeats: int = 50) -> tuple[Any, float]:
    """(last result, median seconds per call) over repeats lasting at least ``min_seconds``."""
    times: list[float] = []
    out = None
    while len(times) < 3 or (sum(times) < min_seconds and len(times) < max_repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return out, statistics.median(times)


def errors(system: HamiltonianSystem, z: np.ndarray, z_ref: np.ndarray, e0: float) -> dict[str, float]:
    """max |err|, release-form L2 of the first coordinate, energy drift (:func:`energy_drift`)."""
    err = np.asarray(z, np.float64) - np.asarray(z_ref, np.float64)
    drift = energy_drift(system.energy64(z), e0)
    return {"max_error": float(np.max(np.abs(err))), "l2_first": float(np.sqrt(np.sum(err[:, 0] ** 2))),
            "energy_drift": drift}


def symplectic_points(system: HamiltonianSystem, z0: np.ndarray, t_eval: np.ndarray, z_ref: np.ndarray,
                      *, multiples: Sequence[int] = STEP_MULTIPLES, min_seconds: float = 0.2) -> list[WorkPoint]:
    """The three symplectic integrators at N = m·(E − 1) steps for each m in ``multiples``."""
    e0 = float(system.energy64(z0))
    t0, T, gaps = float(t_eval[0]), float(t_eval[-1]), len(t_eval) - 1
    points = []
    for method in SYMPLECTIC:
        for m in multiples:
            n = m * gaps
            start = time.perf_counter()
            integrate(method, system, z0, t0, T, n)  # compiles
            first = time.perf_counter() - start
            (_, z), seconds = _timed(lambda: integrate(method, system, z0, t0, T, n), min_seconds)
            points.append(WorkPoint(method, f"N={n}", seconds, **errors(system, z[::m], z_ref, e0),
                                    compile_seconds=max(first - seconds, 0.0), evaluations=n * STAGES[method]))
    return points


def dop853_points(system: HamiltonianSystem, z0: np.ndarray, t_eval: np.ndarray, z_ref: np.ndarray,
                  *, tolerances: Sequence[float] = TOLERANCES, min_seconds: float = 0.2) -> list[WorkPoint]:
    """DOP853 at rtol = atol = each tolerance (dense output at the evaluation times), its
    right-hand side NumPy code where the system has one written (:func:`atlasnn.systems.numpy_field`),
    else compiled ahead of time (:func:`~atlasnn.evaluation.reference_rhs`)."""
    e0 = float(system.energy64(z0))
    z_init = np.asarray(z0, np.float64)
    t = np.asarray(t_eval, np.float64)
    rhs = numpy_field(system)
    points = []
    for tol in tolerances:
        (z, nfev), seconds = _timed(lambda: dop853(system, z_init, t, tol, tol, rhs), min_seconds)
        points.append(WorkPoint("dop853", f"tol={tol:g}", seconds, **errors(system, z, z_ref, e0), evaluations=nfev,
                                rhs="jax" if rhs is None else "numpy"))
    return points


def network_point(label: str, setting: str, seconds: float, system: HamiltonianSystem, z: np.ndarray,
                  z_ref: np.ndarray, e0: float) -> WorkPoint:
    """A trained network as a point: its training wall time and its errors on the grid."""
    return WorkPoint(label, setting, float(seconds), **errors(system, z, z_ref, e0), kind="network")


def evaluation_seconds(solution, t0: float, T: float, n: int = 10_000, min_seconds: float = 0.2) -> float:
    """Median seconds to evaluate a trained solution at ``n`` times in [t0, T] (compiled)."""
    t = np.linspace(t0, T, n)
    solution(t)  # compiles for this shape
    return _timed(lambda: solution(t), min_seconds)[1]


def cheapest_match(points: Sequence[WorkPoint], target: WorkPoint, error: str = "max_error") -> WorkPoint | None:
    """The fastest classical point at least as accurate as ``target`` (by ``error``), or None."""
    good = [p for p in points if p.kind == "classical" and getattr(p, error) <= getattr(target, error)]
    return min(good, key=lambda p: p.seconds) if good else None


def verdicts(points: Sequence[WorkPoint], error: str = "max_error") -> list[str]:
    """One line per network point: which classical method reaches its accuracy, at what cost."""
    lines = []
    for p in (q for q in points if q.kind == "network"):
        match = cheapest_match(points, p, error)
        if match is None:
            lines.append(f"{p.method} ({p.setting}): {error} {getattr(p, error):.3g} after {p.seconds:.3g} s of "
                         "training; no classical setting measured is that accurate")
            continue
        ratio = p.seconds / match.seconds if match.seconds > 0 else math.inf
        lines.append(f"{p.method} ({p.setting}): {error} {getattr(p, error):.3g} after {p.seconds:.3g} s of training; "
                     f"{SYMPLECTIC.get(match.method, 'DOP853' if match.method == 'dop853' else match.method)} "
                     f"({match.setting}) reaches {getattr(match, error):.3g} in {match.seconds:.3g} s "
                     f"({ratio:.3g}x cheaper)")
    return lines


def to_json(points: Sequence[WorkPoint]) -> list[dict]:
    return [asdict(p) for p in points]

"""Work–precision: the accuracy each method buys per second of computing.

For one problem (system, initial state, interval) and its evaluation grid t_1..t_E with the
reference solution on it, every method becomes points (wall time, error):

- the symplectic integrators (symplectic Euler, Störmer–Verlet, Yoshida-4) with N = m·(E − 1)
  steps for several m, so that every evaluation time is a step time (no interpolation);
- DOP853 (SciPy ``solve_ivp``) at several tolerances rtol = atol, reporting at t_1..t_E;
- network methods, given by the caller: the training wall time per seed (and, separately, the
  time to evaluate the trained solution at 10⁴ times, :func:`evaluation_seconds`).

The errors are the maximum |z − z_ref| over all components and times, the release-form L2 of the
first coordinate, sqrt(Σ_i err(t_i)²) on the evaluation grid (the paper's tables' number), and the
relative energy drift max_i |H(z_i) − E0| / |E0|. Times exclude JAX compilation (recorded apart);
each is the median of repeats that together last at least ``min_seconds``.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from atlasnn.systems._hamiltonian import HamiltonianSystem

SYMPLECTIC = {"symplectic_euler": "symplectic Euler", "stormer_verlet": "Störmer–Verlet", "yoshida4": "Yoshida-4"}
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
    """max |err|, release-form L2 of the first coordinate, relative energy drift."""
    from atlasnn.experiments._measure import energies

    err = np.asarray(z, np.float64) - np.asarray(z_ref, np.float64)
    drift = float(np.max(np.abs(energies(system, z) - e0)) / max(abs(e0), 1e-300))
    return {"max_error": float(np.max(np.abs(err))), "l2_first": float(np.sqrt(np.sum(err[:, 0] ** 2))),
            "energy_drift": drift}


def symplectic_points(system: HamiltonianSystem, z0: np.ndarray, t_eval: np.ndarray, z_ref: np.ndarray,
                      *, multiples: Sequence[int] = STEP_MULTIPLES, min_seconds: float = 0.2) -> list[WorkPoint]:
    """The three symplectic integrators at N = m·(E − 1) steps for each m in ``multiples``."""
    from atlasnn.experiments._measure import energy0
    from atlasnn.evaluation._integrators import integrate

    e0 = energy0(system, z0)
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
                                    compile_seconds=max(first - seconds, 0.0)))
    return points


def dop853_points(system: HamiltonianSystem, z0: np.ndarray, t_eval: np.ndarray, z_ref: np.ndarray,
                  *, tolerances: Sequence[float] = TOLERANCES, min_seconds: float = 0.2) -> list[WorkPoint]:
    """DOP853 at rtol = atol = each tolerance (dense output at the evaluation times)."""
    from atlasnn.experiments._measure import energy0
    from atlasnn.evaluation._integrators import reference_solution

    e0 = energy0(system, z0)
    points = []
    for tol in tolerances:
        z, seconds = _timed(lambda: reference_solution(system, z0, t_eval, rtol=tol, atol=tol), min_seconds)
        points.append(WorkPoint("dop853", f"tol={tol:g}", seconds, **errors(system, z, z_ref, e0)))
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


def plot_work_precision(stem: str | Path, points: Sequence[WorkPoint], *, title: str = "",
                        first_name: str = "x") -> list[Path]:
    """Two log–log panels, max error and L2(first coordinate) against seconds: a line per
    classical method (its settings joined), markers for the network points (one per seed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    classical = [m for m in [*SYMPLECTIC, "dop853"] if any(p.method == m for p in points)]
    networks = list(dict.fromkeys(p.method for p in points if p.kind == "network"))
    markers = "os^Dv<>"
    for ax, field, name in ((axes[0], "max_error", "max |error| (all components)"),
                            (axes[1], "l2_first", f"L2({first_name}), release form")):
        for m in classical:
            pts = sorted((p for p in points if p.method == m), key=lambda p: p.seconds)
            ax.plot([p.seconds for p in pts], [getattr(p, field) for p in pts], "-o", ms=3,
                    label=SYMPLECTIC.get(m, "DOP853 (rtol = atol)"))
        for i, label in enumerate(networks):
            pts = [p for p in points if p.method == label]
            ax.scatter([p.seconds for p in pts], [getattr(p, field) for p in pts], marker=markers[i % len(markers)],
                       s=40, zorder=3, edgecolors="black", linewidths=0.6, label=f"{label} (training, per seed)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time [s] (classical: one solve; networks: training)")
        ax.set_ylabel(name)
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=7, loc="best")
    if title:
        fig.suptitle(title)
    paths = []
    for ext in ("png", "pdf"):
        path = Path(f"{stem}.{ext}")
        fig.savefig(path, dpi=150)
        paths.append(path)
    plt.close(fig)
    return paths

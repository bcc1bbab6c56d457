"""``atlasnn.solve``: one door for a trajectory, whichever solver object computes it."""

from __future__ import annotations

import math

import numpy as np
from typing import Any, Callable

from atlasnn.errors import ConfigError
from atlasnn.solutions import PiecewiseSolution
from atlasnn.solver._base import AbstractSolver
from atlasnn.solver._collocation import Collocation
from atlasnn.systems import HamiltonianSystem

__all__ = ["solve", "solve_batch", "DEFAULT_RTOL", "DEFAULT_ATOL", "TIGHTEST_TOLERANCE"]

#: the default tolerances of a window's local error: atol + rtol·|z| per component
DEFAULT_RTOL = 1e-12
DEFAULT_ATOL = 1e-14
#: tolerances below this are beyond float64's reach for a window's error (round-off ~1e-16 per
#: operation, amplified by the collocation's conditioning)
TIGHTEST_TOLERANCE = 1e-15


def _tolerance(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{name} must be a finite number > 0, got {value!r}")
    if value < TIGHTEST_TOLERANCE:
        raise ConfigError(f"{name} = {value:g} is below what float64 can reach ({TIGHTEST_TOLERANCE:g}); raise it")
    return float(value)


def _problem(system: Any, interval: Any, rtol: Any, atol: Any) -> tuple[float, float, float, float]:
    if not isinstance(system, HamiltonianSystem):
        raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    try:
        t0, T = (float(x) for x in interval)
    except (TypeError, ValueError):
        raise ConfigError(f"interval must be (t0, T), got {interval!r}") from None
    if not (math.isfinite(t0) and math.isfinite(T) and t0 < T):
        raise ConfigError(f"interval must be finite with t0 < T, got ({t0!r}, {T!r})")
    return t0, T, _tolerance("rtol", rtol), _tolerance("atol", atol)


def solve(system: HamiltonianSystem, z0: Any = None, interval: tuple[float, float] | None = None, *,
          solver: AbstractSolver | None = None, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
          progress: Callable[[float], None] | None = None) -> PiecewiseSolution:
    """Solve Hamilton's equations dz/dt = J∇H(z) on [t0, T] from z0 with a trial solution per window.

    Args:
        system: the Hamiltonian system.
        z0: the initial state (q then p); default the system's own.
        interval: (t0, T) with t0 < T.
        solver: a solver object: :class:`~atlasnn.solver.Collocation` (default: float64
            Gauss–Newton over random features, windows chosen by their error) or
            :class:`~atlasnn.solver.AdamMarch` (the paper's networks trained by Adam, window by window).
        rtol, atol: each window's local error must meet atol + rtol·|z| per component.
        progress: called with the fraction of the interval done as the march advances.

    Returns the :class:`~atlasnn.solutions.PiecewiseSolution`: evaluate ẑ and dẑ/dt at any times,
    its residual, its a-posteriori ``error_estimate(t)``, save it with ``save_piecewise``.
    """
    t0, T, rtol, atol = _problem(system, interval, rtol, atol)
    z = system.initial_state(z0)
    solver = Collocation() if solver is None else solver
    if not isinstance(solver, AbstractSolver):
        raise ConfigError(f"solver must be a solver object such as Collocation(), got {type(solver).__name__}")
    return solver.solve(system, z, t0, T, rtol=rtol, atol=atol, progress=progress)


def solve_batch(system: HamiltonianSystem, z0s: Any, interval: tuple[float, float], *,
                solver: Collocation | None = None, seeds: Any = None, rtol: float = DEFAULT_RTOL,
                atol: float = DEFAULT_ATOL, progress: Callable[[float], None] | None = None) -> list[PiecewiseSolution]:
    """Many trajectories at once: one solution per initial state in ``z0s`` (shape (B, 2d)), all
    marched by one compiled program, each with windows of its own; ``seeds`` (one per member)
    draws each member's features (default: the solver's seed for all). Otherwise as :func:`solve`."""
    t0, T, rtol, atol = _problem(system, interval, rtol, atol)
    try:
        rows = [system.check_state(z, f"z0s[{i}]") for i, z in enumerate(list(z0s))]
    except TypeError:
        raise ConfigError(f"z0s must be a list of initial states, got {type(z0s).__name__}") from None
    if not rows:
        raise ConfigError("z0s must hold at least one initial state")
    solver = Collocation() if solver is None else solver
    if not isinstance(solver, Collocation):
        raise ConfigError(f"solve_batch needs a Collocation solver, got {type(solver).__name__}")
    return solver.solve_batch(system, np.stack(rows), t0, T, rtol=rtol, atol=atol, seeds=seeds, progress=progress)

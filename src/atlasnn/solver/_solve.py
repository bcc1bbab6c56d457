"""``atlasnn.solve``: one door for a trajectory, whichever solver object computes it."""

from __future__ import annotations

import math
from numbers import Integral
from typing import Any, Callable

import jax
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solutions import AbstractSolution
from atlasnn.solver._base import AbstractSolver
from atlasnn.solver._collocation import Collocation
from atlasnn.solver._gauss import GaussCollocation
from atlasnn.solver._gauss_time import potential_applies
from atlasnn.solver._splitting import SplittingComposition
from atlasnn.systems import HamiltonianSystem

__all__ = ["solve", "solve_batch", "default_solver", "SPLITTING_AUTO_SIZE"]


def _interval(system: Any, interval: Any) -> tuple[float, float]:
    if not isinstance(system, HamiltonianSystem):
        raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    try:
        t0, T = (float(x) for x in interval)
    except (TypeError, ValueError):
        raise ConfigError(f"interval must be (t0, T), got {interval!r}") from None
    if not (math.isfinite(t0) and math.isfinite(T) and t0 < T):
        raise ConfigError(f"interval must be finite with t0 < T, got ({t0!r}, {T!r})")
    if T - t0 <= 64 * np.spacing(max(abs(t0), abs(T))):
        raise ConfigError(f"interval ({t0!r}, {T!r}) is shorter than the round-off of its times; "
                          "shift it nearer 0 or lengthen it")
    return t0, T


#: the smallest state (2d components) of a separable H that the default solves by a splitting
#: method: below it the Gauss solver's fewer, longer windows cost less than the splitting's
#: pilot, check and steps (benchmarks/splitting_workprecision.py: Hénon–Heiles, 4 components,
#: 0.83–1.2 ms by Gauss against 0.81–1.7 ms by the fastest scheme, ahead only at 1e-5 of the
#: range, by 3 %; FPUT-β with 64 particles, 128 components, the default's splitting in 0.50–0.83
#: of the Gauss solver's time at 1e-5 … 1e-11 of the range)
SPLITTING_AUTO_SIZE = 64


def default_solver(system: HamiltonianSystem, z0: Any = None) -> AbstractSolver:
    """The solver ``solve`` takes when none is given, from what is known before marching:

    * H declared separable, no linear part, not gravitational, and at least
      ``SPLITTING_AUTO_SIZE`` components:
      [`SplittingComposition`][atlasnn.solver.SplittingComposition] (explicit, symplectic; the
      scheme from the tolerance);
    * otherwise [`GaussCollocation`][atlasnn.solver.GaussCollocation] (any H; a declared linear
      part solved exactly in its stage equations; close encounters and eccentric orbits of
      gravitational systems by its time transformation, which a constant explicit step cannot
      follow). A PDE with a declared linear part stays there too, its flows declared or not: on
      the NLS soliton the Gauss solver's long windows beat the split-step compositions from rtol
      1e-7 on, by 1.2–6× (benchmarks/splitting_nls.py; at 1e-6 the splitting, its pilot's march the
      solution over that short interval, took 0.71 of the Gauss solver's time: one tolerance of one
      interval, too little to choose by).

    The rule and its measurement: docs/CHOOSING.md (benchmarks/splitting_workprecision.py)."""
    if system.traced:
        return GaussCollocation()
    if system.separable and system.linear_part is None and system.state_dim >= SPLITTING_AUTO_SIZE:
        gravitational = z0 is not None and potential_applies(system, z0)
        if not gravitational:
            return SplittingComposition()
    return GaussCollocation()


def _solver(solver: Any, rtol: Any, atol: Any, system: Any = None, z0: Any = None) -> AbstractSolver:
    if solver is None:
        solver = default_solver(system, z0) if isinstance(system, HamiltonianSystem) else GaussCollocation()
    if not isinstance(solver, AbstractSolver):
        raise ConfigError(f"solver must be a solver object such as GaussCollocation(), got {type(solver).__name__}")
    return solver.with_tolerance(rtol, atol)


def _traced(system: HamiltonianSystem, *values: Any) -> bool:
    """Whether a solve runs inside a JAX transformation: its inputs, or what H closes over, traced."""
    return system.traced or any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(values))


def _solve_traced(system: HamiltonianSystem, z0: Any, interval: Any, solver: AbstractSolver):
    if not isinstance(solver, (GaussCollocation, SplittingComposition)):
        raise ConfigError("inside jit/grad/vmap solve needs a GaussCollocation or SplittingComposition(steps=N) "
                          f"solver, got {type(solver).__name__}")
    try:
        t0, T = interval
    except (TypeError, ValueError):
        raise ConfigError(f"interval must be (t0, T), got {interval!r}") from None
    z0 = system.initial_state(None) if z0 is None else z0
    return solver.solve_traced(system, z0, t0, T)


def solve(system: HamiltonianSystem, z0: Any = None, interval: tuple[float, float] | None = None, *,
          solver: AbstractSolver | None = None, rtol: float | None = None, atol: float | None = None,
          progress: Callable[[float], None] | None = None) -> AbstractSolution:
    """Solve Hamilton's equations dz/dt = J∇H(z) on [t0, T] from z0 with a trial solution per window.

    Args:
        system: the Hamiltonian system.
        z0: the initial state (q then p); default the system's own.
        interval: (t0, T) with t0 < T.
        solver: a solver object, holding its settings and tolerances:
            [`GaussCollocation`][atlasnn.solver.GaussCollocation] (the trial solution collocated at
            Gauss–Legendre nodes; symplectic, order 2s; any H),
            [`SplittingComposition`][atlasnn.solver.SplittingComposition] (explicit symplectic
            splitting methods for a separable H), [`Collocation`][atlasnn.solver.Collocation]
            (random tanh features, Gauss–Newton) or [`AdamMarch`][atlasnn.solver.AdamMarch] (the
            paper's networks trained by Adam, window by window). None: chosen from the system
            ([`default_solver`][atlasnn.solver.default_solver]: a splitting method for a separable,
            non-gravitational H without a linear part, else the Gauss solver); ``sol.info["solver"]``
            says which ran.
        rtol: replaces the solver's own relative tolerance (each solver says what it means).
        atol: replaces the solver's own absolute tolerance.
        progress: called with the fraction of the interval done as the march advances.

    Returns the solution: evaluate ẑ and dẑ/dt at any times (``sol(t)``, ``sol.derivative(t)``),
    its energy, residual and a-posteriori ``error_estimate(t)``; save it with
    [`atlasnn.save`][atlasnn.checkpoint.save].

    Inside ``jax.jit``, ``jax.grad``, ``jax.vmap`` or ``jax.jvp`` (z0, the interval or what H
    closes over traced) it runs the Gauss solver's traceable core and returns a
    [`TracedSolution`][atlasnn.solutions.TracedSolution]: the same windows and numbers, as JAX
    values (``sol(t)``, ``sol.derivative(t)``, ``sol.energy(t)``), differentiable with respect to
    z0, the interval and H's parameters (docs/JAX.md).
    """
    if isinstance(system, HamiltonianSystem) and _traced(system, z0, interval):
        solver = GaussCollocation() if solver is None else solver  # a step count must be static for a splitting
        return _solve_traced(system, z0, interval, _solver(solver, rtol, atol))
    t0, T = _interval(system, interval)
    z = system.initial_state(z0)
    return _solver(solver, rtol, atol, system, z).solve(system, z, t0, T, progress=progress)


def _seeds(seeds: Any, count: int) -> list[int] | None:
    if seeds is None:
        return None
    try:
        out = list(seeds)
    except TypeError:
        raise ConfigError(f"seeds must be a list of integers, got {type(seeds).__name__}") from None
    for s in out:
        if isinstance(s, bool) or not isinstance(s, Integral) or not 0 <= s < 2 ** 32:
            raise ConfigError(f"seeds must be integers in [0, 2**32), got {s!r}")
    if len(out) != count:
        raise ConfigError(f"seeds must give one seed per initial state: {len(out)} seeds for {count} states")
    return [int(s) for s in out]


def solve_batch(system: HamiltonianSystem, z0s: Any, interval: tuple[float, float], *,
                solver: GaussCollocation | Collocation | None = None, seeds: Any = None, rtol: float | None = None,
                atol: float | None = None, progress: Callable[[float], None] | None = None) -> list[AbstractSolution]:
    """Many trajectories at once: one solution per initial state in ``z0s``, all marched by one
    compiled program, each with windows of its own. Otherwise as [`solve`][atlasnn.solver.solve].

    Args:
        system: the Hamiltonian system.
        z0s: the initial states, one per row (shape (B, 2d), q then p); at least one.
        interval: (t0, T) with t0 < T, the same for every member.
        solver: [`GaussCollocation`][atlasnn.solver.GaussCollocation] (default) or
            [`Collocation`][atlasnn.solver.Collocation]; the trained solvers have no batch.
        seeds: one integer in [0, 2**32) per member, drawing each member's random features of a
            ``Collocation`` solver; None for ``GaussCollocation``, which has none.
        rtol: replaces the solver's own relative tolerance.
        atol: replaces the solver's own absolute tolerance.
        progress: called with the fraction of the interval done as the march advances.

    Returns a list of B solutions, in the order of ``z0s``, each the same kind as ``solve`` returns.
    """
    if isinstance(system, HamiltonianSystem) and _traced(system, z0s, interval):
        raise ConfigError("solve_batch runs on numbers, not inside jit/grad/vmap (its inputs, or what H closes over, "
                          "are traced there): use jax.vmap or jax.lax.map of atlasnn.solve instead")
    t0, T = _interval(system, interval)
    try:
        rows = [system.check_state(z, f"z0s[{i}]") for i, z in enumerate(list(z0s))]
    except TypeError:
        raise ConfigError(f"z0s must be a list of initial states, got {type(z0s).__name__}") from None
    if not rows:
        raise ConfigError("z0s must hold at least one initial state")
    solver = _solver(solver, rtol, atol, system, rows[0])
    seeds = _seeds(seeds, len(rows))
    if isinstance(solver, Collocation):
        return solver.solve_batch(system, np.stack(rows), t0, T, seeds=seeds, progress=progress)
    if not isinstance(solver, (GaussCollocation, SplittingComposition)):
        raise ConfigError("solve_batch needs a GaussCollocation, SplittingComposition or Collocation solver, got "
                          f"{type(solver).__name__}")
    if seeds is not None:
        raise ConfigError(f"seeds draw the random features of a Collocation solver; {type(solver).__name__} has none")
    return solver.solve_batch(system, np.stack(rows), t0, T, progress=progress)

"""The orbit solvers the inverse fits go through: ``"gauss"`` (default), the compiled Gauss
collocation with the variational equations beside the state (:class:`atlasnn.solver.ParametricGauss`:
shooting fits 6–11× faster than with DOP853, the same estimates; ``benchmarks/shooting_solver.py``),
and ``"dop853"``, SciPy's (:func:`atlasnn.evaluation.solve_parametric`)."""

from __future__ import annotations

from atlasnn.errors import ConfigError
from atlasnn.evaluation import solve_parametric
from atlasnn.solver import ParametricGauss
from atlasnn.systems import HamiltonianSystem

__all__ = ["parametric_solver", "PARAMETRIC_SOLVERS"]

#: the solvers :func:`parametric_solver` offers
PARAMETRIC_SOLVERS = ("gauss", "dop853")


def parametric_solver(system: HamiltonianSystem, rtol: float, atol: float, solver: str = "gauss"):
    """``solve(z_init, theta, t0, times, S_init=None, dtheta=None) -> (Z, S, evaluations)`` for one
    fit: :func:`solve_parametric`'s tail, by ``solver`` (:data:`PARAMETRIC_SOLVERS`). The Gauss
    solve keeps its window length from call to call (:class:`atlasnn.solver.ParametricGauss`), so
    one ``solve`` serves one fit; ``evaluations`` counts the right-hand side's evaluations (DOP853:
    of the augmented system; Gauss: of the field, the sensitivities' derivatives beside each)."""
    if solver not in PARAMETRIC_SOLVERS:
        raise ConfigError(f"solver must be one of {list(PARAMETRIC_SOLVERS)}, got {solver!r}")
    if solver == "dop853":
        def solve(z_init, theta, t0, times, S_init=None, dtheta=None):
            return solve_parametric(system, z_init, theta, t0, times, rtol, atol, S_init, dtheta)

        return solve
    gauss = ParametricGauss(system, rtol=rtol, atol=atol)

    def solve(z_init, theta, t0, times, S_init=None, dtheta=None):
        before = gauss.evaluations
        Z, S = gauss(z_init, theta, t0, times, S_init, dtheta)
        return Z, S, gauss.evaluations - before

    return solve

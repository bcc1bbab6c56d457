"""Solving Hamilton's equations for one trajectory: :func:`solve`, and the solver objects it takes.

:class:`GaussCollocation` (the default) solves ATLAS-NN's trial solution with a polynomial network
collocated at the Gauss–Legendre nodes of every window — the Gauss–Legendre Runge–Kutta method,
symplectic and of order 2s — as one compiled program. :class:`Collocation` solves it over random
tanh features by Gauss–Newton; :class:`AdamMarch` is the paper's network trained by Adam window by
window. A new solver is one :class:`AbstractSolver` subclass and one :func:`register_solver` entry.

:class:`ParametricGauss` solves one orbit at given times for parameters θ passed as arguments, with
its forward sensitivities ∂z/∂(θ, z0) (the model of least-squares shooting).

:func:`solve_bundle` solves a whole bundle (every initial state and parameter of a box) with a method
object: one float64 flow map (:class:`FlowMap`, the default) or a trained network
(:class:`NetworkBundle`).
"""

from atlasnn.solver._base import SOLVERS, AbstractSolver, check_tolerance, register_solver, solver_from_name
from atlasnn.solver._collocation import Collocation, require_float64
from atlasnn.solver._bundle import NetworkBundle, solve_bundle
from atlasnn.solver._flowmap import FlowMap, FlowMapProblem, flowmap_bundle, flowmap_problem
from atlasnn.solver._gauss import GaussCollocation
from atlasnn.solver._gauss_time import poincare_system
from atlasnn.solver._parametric import ParametricGauss, ParametricSolveFailed
from atlasnn.solver._features import WINDOW_SCALINGS, RandomFeatures, collocation_nodes
from atlasnn.solver._solve import SPLITTING_AUTO_SIZE, default_solver, solve, solve_batch
from atlasnn.solver._splitting import SCHEME_BY_TOLERANCE, SplittingComposition, scheme_for
from atlasnn.solver._trained import AdamMarch, Transfer

__all__ = [
    "solve",
    "default_solver",
    "SPLITTING_AUTO_SIZE",
    "solve_bundle",
    "FlowMap",
    "NetworkBundle",
    "flowmap_bundle",
    "FlowMapProblem",
    "flowmap_problem",
    "solve_batch",
    "AbstractSolver",
    "GaussCollocation",
    "poincare_system",
    "SplittingComposition",
    "SCHEME_BY_TOLERANCE",
    "scheme_for",
    "ParametricGauss",
    "ParametricSolveFailed",
    "Collocation",
    "AdamMarch",
    "Transfer",
    "SOLVERS",
    "register_solver",
    "solver_from_name",
    "require_float64",
    "RandomFeatures",
    "collocation_nodes",
    "WINDOW_SCALINGS",
    "check_tolerance",
]

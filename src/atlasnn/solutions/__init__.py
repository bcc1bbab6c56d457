"""Trained networks as solutions of Hamilton's equations: callable at any time, differentiable,
with their residual; one trial solution (:class:`Solution`) or a time-marching chain of windows
(:class:`PiecewiseSolution`); and their a-posteriori error estimate, with no reference needed. The
Gauss collocation's: :class:`PolynomialSolution`, and :class:`TimeTransformedSolution` for its
time-transformed march; an explicit splitting method's: :class:`SplittingSolution`."""

from atlasnn.solutions._base import AbstractSolution
from atlasnn.solutions._bundle import MEMBER_CHUNK, BundleSolution, bundle_start
from atlasnn.solutions._flowmap import ChebyshevBasis, FlowMapBundle, chebyshev
from atlasnn.solutions._bounds import log_norm, residual_bound
from atlasnn.solutions._evaluate import bucket_size
from atlasnn.solutions._estimate import TRUST_FRACTION, ErrorEstimate, estimate_error, state_range
from atlasnn.solutions._linearised import propagate, residual_and_jacobian
from atlasnn.solutions._polynomial import PolynomialSolution, edge_offsets
from atlasnn.solutions._transformed import TimeTransformedSolution
from atlasnn.solutions._traced import TracedSolution
from atlasnn.solutions._splitting_tables import SCHEMES as SPLITTING_SCHEMES, SplittingScheme, splitting_scheme
from atlasnn.solutions._splitting import SplittingSolution
from atlasnn.solutions._splitting_traced import TracedSplittingSolution
from atlasnn.solutions._splitting_step import SplitState, lax_steps, linear_splitting, split_step, stability_limit, start_state
from atlasnn.solutions._piecewise import PiecewiseSolution, WindowRecord, stack_models, unstack_models, window_edges
from atlasnn.solutions._base import INTERVAL_SLACK, ExtrapolationError, ExtrapolationWarning
from atlasnn.solutions._solution import OUTSIDE_MODES, Solution
from atlasnn.solutions._tableau import (MAX_STAGES, GaussTableau, gauss_tableau, legendre_integral, shifted_legendre,
                                        window_value)

__all__ = [
    "ChebyshevBasis",
    "FlowMapBundle",
    "chebyshev",
    "AbstractSolution",
    "ErrorEstimate",
    "estimate_error",
    "state_range",
    "TRUST_FRACTION",
    "residual_and_jacobian",
    "propagate",
    "residual_bound",
    "log_norm",
    "Solution",
    "PiecewiseSolution",
    "PolynomialSolution",
    "edge_offsets",
    "TimeTransformedSolution",
    "TracedSolution",
    "SPLITTING_SCHEMES",
    "SplittingScheme",
    "splitting_scheme",
    "SplittingSolution",
    "TracedSplittingSolution",
    "linear_splitting",
    "stability_limit",
    "SplitState",
    "split_step",
    "start_state",
    "lax_steps",
    "BundleSolution",
    "MEMBER_CHUNK",
    "bundle_start",
    "WindowRecord",
    "window_edges",
    "stack_models",
    "unstack_models",
    "ExtrapolationWarning",
    "ExtrapolationError",
    "OUTSIDE_MODES",
    "INTERVAL_SLACK",
    "GaussTableau",
    "gauss_tableau",
    "shifted_legendre",
    "legendre_integral",
    "window_value",
    "MAX_STAGES",
    "bucket_size",
]

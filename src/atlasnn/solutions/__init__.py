"""Trained networks as solutions of Hamilton's equations: callable at any time, differentiable,
with their residual; one trial solution (:class:`Solution`) or a time-marching chain of windows
(:class:`PiecewiseSolution`)."""

from atlasnn.solutions._piecewise import PiecewiseSolution, WindowRecord, stack_models, unstack_models, window_edges
from atlasnn.solutions._solution import (
    INTERVAL_SLACK,
    OUTSIDE_MODES,
    ExtrapolationError,
    ExtrapolationWarning,
    Solution,
)

__all__ = [
    "Solution",
    "PiecewiseSolution",
    "WindowRecord",
    "window_edges",
    "stack_models",
    "unstack_models",
    "ExtrapolationWarning",
    "ExtrapolationError",
    "OUTSIDE_MODES",
    "INTERVAL_SLACK",
]

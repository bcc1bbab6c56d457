"""The Adam-trained time-marching ATLAS-NN (the paper's networks, trained window by window) as a
solver object, so that :func:`atlasnn.solve` reaches it through the same door."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, ClassVar

import numpy as np

from atlasnn.nn import make_model
from atlasnn.solutions import PiecewiseSolution
from atlasnn.solver._base import AbstractSolver, register_solver
from atlasnn.systems import HamiltonianSystem
from atlasnn.training import DEFAULT_NETWORK, MarchConfig, march

__all__ = ["AdamMarch"]


@register_solver
@dataclass(frozen=True)
class AdamMarch(AbstractSolver):
    """Time-marching with windows trained by Adam (float32) then Levenberg–Marquardt, windows
    chosen by the a-posteriori error estimate (:func:`atlasnn.training.march`). It is what the
    paper's reproductions use; for a trajectory alone the collocation solver is faster and more
    accurate (docs/SOLVER.md). ``network``: the arguments of :func:`atlasnn.make_model`;
    ``config``: the march's settings (its rtol/atol are replaced by :func:`atlasnn.solve`'s).
    """

    name: ClassVar[str] = "adam-march"

    network: dict[str, Any] = field(default_factory=lambda: dict(DEFAULT_NETWORK))
    config: MarchConfig = field(default_factory=MarchConfig)
    seed: int = 0

    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *, rtol: float, atol: float,
              progress: Callable[[float], None] | None = None) -> PiecewiseSolution:
        model = make_model(z0, t0=t0, seed=self.seed, **self.network)
        config = replace(self.config, rtol=rtol, atol=atol)
        hook = None if progress is None else (lambda rec: progress(min(1.0, (rec.end - t0) / (T - t0))))
        return march(model, system, T, config, on_window=hook)

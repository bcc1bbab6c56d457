"""The Adam-trained time-marching ATLAS-NN (the paper's networks, trained window by window) as a
solver object, so that :func:`atlasnn.solve` reaches it through the same door."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, ClassVar

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import make_model
from atlasnn.solutions import PiecewiseSolution
from atlasnn.solver._base import AbstractSolver, register_solver
from atlasnn.systems import HamiltonianSystem
from atlasnn.training import DEFAULT_NETWORK, DEFAULT_RTOL, MarchConfig, march

__all__ = ["AdamMarch"]


@register_solver
@dataclass(frozen=True)
class AdamMarch(AbstractSolver):
    """Time-marching with windows trained by Adam (float32) then Levenberg–Marquardt, windows
    chosen by the a-posteriori error estimate (:func:`atlasnn.training.march`). It is what the
    paper's reproductions use; for a trajectory alone the Gauss collocation is faster and more
    accurate by orders of magnitude (docs/SOLVER.md).

    Attributes:
        rtol, atol: every window's estimated local error must be within atol + rtol × the state's
            range (the trained windows are float32: rtol below 1e-7 is out of reach and refused).
        network: the arguments of :func:`atlasnn.make_model`.
        config: the march's other settings (its own rtol/atol are replaced by these).
        seed: the networks' initialisation.
    """

    name: ClassVar[str] = "adam-march"
    #: float32 networks: their round-off is ~1e-7 of the state
    tightest: ClassVar[float] = 1e-7

    rtol: float = DEFAULT_RTOL
    atol: float = 0.0
    network: dict[str, Any] = field(default_factory=lambda: dict(DEFAULT_NETWORK))
    config: MarchConfig = field(default_factory=MarchConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        self.check_tolerances()
        if not isinstance(self.config, MarchConfig):
            raise ConfigError(f"AdamMarch config must be a MarchConfig, got {type(self.config).__name__}")
        if not isinstance(self.network, dict):
            raise ConfigError(f"AdamMarch network must be a dict of make_model's arguments, got "
                              f"{type(self.network).__name__}")

    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *,
              progress: Callable[[float], None] | None = None) -> PiecewiseSolution:
        model = make_model(z0, t0=t0, seed=self.seed, **self.network)
        config = replace(self.config, rtol=self.rtol, atol=self.atol)
        hook = None if progress is None else (lambda rec: progress(min(1.0, (rec.end - t0) / (T - t0))))
        return march(model, system, T, config, on_window=hook)

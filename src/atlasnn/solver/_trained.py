"""The paper's trained networks as solver objects, so that :func:`atlasnn.solve` reaches them through
the same door: :class:`AdamMarch` (time-marching ATLAS-NN, window by window) and :class:`Transfer`
(the paper's transfer: trained on a short source interval, γ frozen, then on the whole one)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, ClassVar

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import make_model
from atlasnn.solutions import PiecewiseSolution, Solution
from atlasnn.solver._base import AbstractSolver, register_solver
from atlasnn.systems import HamiltonianSystem
from atlasnn.training import DEFAULT_NETWORK, DEFAULT_RTOL, MarchConfig, TrainConfig, march, train, transfer

__all__ = ["AdamMarch", "Transfer"]


@register_solver
@dataclass(frozen=True)
class AdamMarch(AbstractSolver):
    """Time-marching with windows trained by Adam (float32) then Levenberg–Marquardt, windows
    chosen by the a-posteriori error estimate ([`atlasnn.training.march`][atlasnn.training.march]). It is what the
    paper's reproductions use; for a trajectory alone the Gauss collocation is faster and more
    accurate by orders of magnitude (docs/SOLVER.md).

    Attributes:
        rtol: relative tolerance: every window's estimated local error must be within atol + rtol ×
            the state's range (the trained windows are float32: rtol below 1e-7 is out of reach and
            refused).
        atol: absolute tolerance (see rtol).
        network: the arguments of [`atlasnn.nn.make_model`][atlasnn.nn.make_model].
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


@register_solver
@dataclass(frozen=True)
class Transfer(AbstractSolver):
    """The paper's transfer (SPEC, docs/METHOD.md): one network trained by Adam on the source
    interval [t0, t0 + source] (γ learned), then, γ frozen, on the whole interval [t0, T] from the
    source's weights. No tolerance: it trains for its epoch budgets (its error is what the
    a-posteriori estimate says; docs/REPRODUCTION.md measures it against the Gauss collocation).

    Attributes:
        source: the source interval's length (default 4π, the paper's oscillator source).
        network: the arguments of [`atlasnn.nn.make_model`][atlasnn.nn.make_model] (default: the paper's
            ATLAS-NN exp model, 80 wide, 2 deep).
        source_train: the source training's settings ([`atlasnn.training.TrainConfig`][atlasnn.training.TrainConfig]).
        target_train: the target training's settings.
        thaw: keep γ trainable on the target (the paper freezes it).
        seed: the network's initialisation.
    """

    name: ClassVar[str] = "transfer"
    tightest: ClassVar[float] = 0.0

    rtol: None = None
    atol: None = None
    source: float = 4 * np.pi
    network: dict[str, Any] = field(default_factory=lambda: {"scaling": "rational_exp", "width": 80, "depth": 2})
    source_train: TrainConfig = field(default_factory=lambda: TrainConfig(epochs=10_000, lr=8e-3, n_points=200))
    target_train: TrainConfig = field(default_factory=lambda: TrainConfig(epochs=10_000, lr=5e-3, n_points=500))
    thaw: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        if self.rtol is not None or self.atol is not None:
            raise ConfigError("Transfer has no tolerance (it trains for its epoch budgets); drop rtol/atol, or use "
                              "AdamMarch or GaussCollocation for a solution to a tolerance")
        if isinstance(self.source, bool) or not isinstance(self.source, (int, float)) or not self.source > 0:
            raise ConfigError(f"Transfer source must be a length > 0, got {self.source!r}")
        for name in ("source_train", "target_train"):
            if not isinstance(getattr(self, name), TrainConfig):
                raise ConfigError(f"Transfer {name} must be a TrainConfig, got {type(getattr(self, name)).__name__}")

    def with_tolerance(self, rtol: Any = None, atol: Any = None) -> "Transfer":
        if rtol is not None or atol is not None:
            raise ConfigError("Transfer has no tolerance (it trains for its epoch budgets); solve(..., rtol=...) "
                              "needs AdamMarch or GaussCollocation")
        return self

    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *,
              progress: Callable[[float], None] | None = None) -> Solution:
        source_T = min(T, t0 + float(self.source))
        model = make_model(z0, t0=t0, seed=self.seed, **self.network)
        first = train(model, system, source_T, self.source_train.replace(seed=self.seed), desc="source")
        if progress is not None:
            progress((source_T - t0) / (T - t0))
        if source_T >= T:
            return Solution(first.model, system, (t0, T), {"solver": self.name, "source": _summary(first)})
        second = transfer(first, system, T, self.target_train.replace(seed=self.seed), thaw=self.thaw)
        if progress is not None:
            progress(1.0)
        return Solution(second.model, system, (t0, T), {"solver": self.name, "source": _summary(first),
                                                         "target": _summary(second)})


def _summary(result) -> dict[str, Any]:
    """A training's record in a solution's info (JSON-able)."""
    return {"interval": list(result.interval), "epochs": int(result.epochs_run), "stop_reason": result.stop_reason,
            "best_loss": result.best_loss, "wall_time": result.wall_time, "compile_time": result.compile_time,
            "gamma": {k: float(v) for k, v in result.model.scaling.gamma().items()}}

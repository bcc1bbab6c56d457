"""The second phase after Adam, one entry point: Levenberg–Marquardt or L-BFGS by its config's type."""

from __future__ import annotations

from atlasnn.nn import TrialSolution
from atlasnn.systems import HamiltonianSystem
from atlasnn.training._lm import LMConfig, LMResult, levenberg_marquardt
from atlasnn.training._polish import PolishConfig, PolishResult, polish

__all__ = ["refine", "RefineConfig"]

RefineConfig = LMConfig | PolishConfig


def refine(model: TrialSolution, system: HamiltonianSystem, T: float, config: RefineConfig, *,
           energy0: float | None = None) -> LMResult | PolishResult:
    """Run the phase ``config`` names on [model.t0, T]: an :class:`LMConfig` runs
    Levenberg–Marquardt, a :class:`PolishConfig` L-BFGS. Both results carry ``model``, ``steps``,
    ``stop_reason``, ``initial_loss``, ``final_loss``, ``loss`` and ``compile_time``."""
    if isinstance(config, LMConfig):
        return levenberg_marquardt(model, system, T, config, energy0=energy0)
    return polish(model, system, T, config, energy0=energy0)

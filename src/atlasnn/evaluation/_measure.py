"""A trained solution's errors against a reference on one grid, as results.json records them.

Everything runs in float64: the energies of predicted states are H evaluated in float64
(:meth:`~atlasnn.systems.HamiltonianSystem.energy64`), the metrics are NumPy.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from atlasnn.evaluation._metrics import energy_drift, error_table, state_metric_names
from atlasnn.solutions import state_range

__all__ = ["error_metrics", "measure_solution"]


def error_metrics(t: np.ndarray, z: np.ndarray, z_ref: np.ndarray, names: Sequence[str], energy: np.ndarray,
                  e0: float) -> dict[str, Any]:
    """Per-state metrics (``metric → {state: value}``), whole-state metrics and the energy drift."""
    table = error_table(t, z, z_ref, names)
    per: dict[str, Any] = {m: {n: table["components"][n][m] for n in names} for m in state_metric_names()}
    per["whole"] = table["whole"]
    per["energy_drift"] = energy_drift(energy, e0)
    scale = state_range(z_ref)
    per["relative_max"] = per["whole"]["max_abs"] / scale if scale > 0 else float("inf")
    return per


def measure_solution(solution, t: np.ndarray, z_ref: np.ndarray, names: Sequence[str], e0: float):
    """(metrics, ẑ on t, H(ẑ) on t) of a trained solution against the reference on grid t."""
    z = np.asarray(solution(t), dtype=np.float64)
    energy = solution.energy(t)
    return error_metrics(t, z, z_ref, names, energy, e0), z, energy

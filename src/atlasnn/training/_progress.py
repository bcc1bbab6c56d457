"""Where a time-marching run stands after its last finished window: enough to continue it exactly.

A march hands a :class:`MarchProgress` to its ``on_progress`` callback after every finished
window, and accepts one back as ``resume``: the windows already trained are kept and the march
goes on from the next one, bit-identical to a run that was never stopped. Nothing is recomputed
that a stop could change: the next window's starting model is rebuilt from the last trained one
(:func:`next_window_model` and :func:`end_state` are deterministic), the carried Adam state is
stored, and the adaptive controller's state (next trial length, the running extent of the
solution that sets the tolerance's scale, every attempt so far) is stored too.
:mod:`atlasnn.checkpoint` saves and loads it (``save_march_progress``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.solutions import WindowRecord
from atlasnn.training._records import TrainConfig

__all__ = ["MarchProgress"]


@dataclass
class MarchProgress:
    """A march after ``len(trained)`` finished windows.

    Attributes:
        edges: t_0..t_k, the finished windows' edges (k + 1 values).
        trained: the finished windows' models (local time), in order.
        records: their :class:`~atlasnn.solutions.WindowRecord`.
        opt_state: the Adam state the last window ended with (carried into the next one), or None.
        opt_config: the TrainConfig the last window was trained with (rebuilds ``opt_state``'s
            structure when it is loaded).
        next_length: adaptive windows: the next window's trial length (0 for fixed windows).
        lo, hi: adaptive windows: the componentwise min and max of the solution so far (the
            tolerance's scale is the largest hi − lo).
        attempts: adaptive windows: every attempt so far (accepted, cut, rejected, forced).
        info: free-form JSON-able notes saved and loaded with it (e.g. the run it belongs to).
    """

    edges: list[float]
    trained: list[TrialSolution]
    records: list[WindowRecord]
    opt_state: Any = None
    opt_config: TrainConfig | None = None
    next_length: float = 0.0
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    attempts: list[dict[str, Any]] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.trained)
        if n < 1 or len(self.records) != n or len(self.edges) != n + 1:
            raise ConfigError(f"a march's progress needs n >= 1 windows with n records and n + 1 edges, got "
                              f"{n} windows, {len(self.records)} records, {len(self.edges)} edges")
        self.edges = [float(e) for e in self.edges]

    @property
    def windows(self) -> int:
        """Finished windows."""
        return len(self.trained)

    @property
    def t(self) -> float:
        """The end of the last finished window."""
        return self.edges[-1]

    @property
    def last_length(self) -> float:
        return self.edges[-1] - self.edges[-2]

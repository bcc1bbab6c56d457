"""A trained model as a solution of Hamilton's equations, callable at any times.

``Solution(model, system, interval)`` evaluates ẑ(t), dẑ/dt(t) and H(ẑ(t)) at any array of
times. Results are NumPy arrays.

Outside its training interval [t0, T] a network is an extrapolation, and usually a poor one (the
issue that introduced this check measured a max error of 6.3e-4 inside [0, 8π] and of 0.79 on
[0, 12π], 2.1 on [0, 30π]). When the interval is known, ``outside`` says what evaluating beyond
it does: ``"warn"`` (default: one :class:`ExtrapolationWarning` per Solution, naming the
interval and the times asked for), ``"raise"`` (an :class:`ExtrapolationError`) or
``"allow"`` (silently). Times within ``INTERVAL_SLACK`` (relative to T − t0) of the ends count
as inside, so float rounding of a grid's end points does not trigger it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.solutions._base import AbstractSolution, check_inside, finite_times
from atlasnn.solutions._evaluate import value_and_rate_padded
from atlasnn.systems import HamiltonianSystem

OUTSIDE_MODES = ("warn", "raise", "allow")


def check_outside_mode(outside: str) -> None:
    """Refuse an ``outside=`` option that is not one of :data:`OUTSIDE_MODES`."""
    if outside not in OUTSIDE_MODES:
        raise ValueError(f"outside must be one of {list(OUTSIDE_MODES)}, got {outside!r}")


def check_state_size(model: TrialSolution, system: HamiltonianSystem, what: str = "the model") -> None:
    """Refuse a network whose output size is not the system's state size (2d), both named."""
    size = int(np.shape(model.z0)[-1])
    if size != system.state_dim:
        raise ConfigError(f"{what} has {size} state components but the system {system.name!r} has "
                          f"{system.state_dim} (2d, d = {system.dim}); train a model for this system")


@dataclass(eq=False)
class Solution(AbstractSolution):
    """A trained trial solution for one system.

    Attributes:
        model: the trained ``TrialSolution``.
        system: its Hamiltonian system.
        interval: the (t0, T) it was trained on, if known.
        info: free-form record (model name, training summary).
        outside: what evaluating outside ``interval`` does: ``"warn"`` (once per Solution),
            ``"raise"`` or ``"allow"`` (see the module docstring).
    """

    model: TrialSolution
    system: HamiltonianSystem
    interval: tuple[float, float] | None = None
    info: dict[str, Any] = field(default_factory=dict)
    outside: str = "warn"
    _warned: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        check_outside_mode(self.outside)
        check_state_size(self.model, self.system)
        if self.interval is not None:
            try:
                t0, T = (float(x) for x in self.interval)
            except (TypeError, ValueError):
                raise ValueError(f"interval must be (t0, T), got {self.interval!r}") from None
            if not (math.isfinite(t0) and math.isfinite(T) and t0 < T):
                raise ValueError(f"interval must be finite with t0 < T, got {self.interval!r}")
            self.interval = (t0, T)

    def _check_inside(self, arr: np.ndarray) -> None:
        check_inside(self, self.interval, arr)

    def _times(self, t) -> tuple[np.ndarray, tuple[int, ...]]:
        arr = finite_times(t)
        self._check_inside(arr)
        return arr.reshape(-1), arr.shape

    def _evaluate(self, t) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        """(ẑ, dẑ/dt, shape of t): the times padded to a bucket size so that a new number of
        times rarely compiles again (:func:`bucket_size`)."""
        flat, shape = self._times(t)
        z, dz = value_and_rate_padded(self.model, flat, self.model.z0.dtype)
        d = self.system.state_dim
        return z.reshape(shape + (d,)), dz.reshape(shape + (d,)), shape

    def pieces(self) -> list[tuple[TrialSolution, float, float, float]]:
        if self.interval is None:
            raise ValueError("a Solution without an interval has no error estimate; give interval=(t0, T)")
        t0, T = self.interval
        return [(self.model, t0, T - t0, t0)]

    @property
    def scaling_name(self) -> str:
        return self.model.scaling.name

    @property
    def gamma(self) -> dict[str, float]:
        """The learned (or fixed) time-scaling parameters γ."""
        return {k: float(v) for k, v in self.model.scaling.gamma().items()}

    @property
    def z0(self) -> np.ndarray:
        return np.asarray(self.model.z0, dtype=np.float64)

    @property
    def t0(self) -> float:
        return float(self.model.t0)

"""The interface every inverse fit method implements (:class:`AbstractFitMethod`)."""

from __future__ import annotations

import abc
from typing import Any, ClassVar, Sequence

from atlasnn.inverse._fit_result import FitResult
from atlasnn.observations import Observations, Unknown
from atlasnn.systems import HamiltonianSystem

__all__ = ["AbstractFitMethod"]


class AbstractFitMethod(abc.ABC):
    """A way of fitting unknowns to observations: a frozen dataclass of settings, a ``name`` (the
    word of a config's ``[fit] methods``) and :meth:`fit`."""

    name: ClassVar[str]

    @abc.abstractmethod
    def fit(self, system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown], *,
            z0: Any = None, t0: float = 0.0, seed: int = 0) -> FitResult:
        """The fit (``seed``: the draw of whatever the method draws: starts, features, networks)."""

    @abc.abstractmethod
    def describe(self, unknowns: Sequence[Unknown]) -> str:
        """A few words for the line printed before the fit."""

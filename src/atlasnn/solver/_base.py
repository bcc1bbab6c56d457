"""What every trajectory solver is: one small interface and one registry.

A solver object holds its own settings (frozen, checked when it is built) and turns a problem —
a system, an initial state, an interval and a tolerance — into a
:class:`~atlasnn.solutions.PiecewiseSolution`. :func:`atlasnn.solve` takes any of them; configs
and the CLI name them through :data:`SOLVERS` (a new solver is one class and one
:func:`register_solver` entry).
"""

from __future__ import annotations

import abc
from typing import Any, Callable, ClassVar

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solutions import PiecewiseSolution
from atlasnn.systems import HamiltonianSystem

__all__ = ["AbstractSolver", "SOLVERS", "register_solver", "solver_from_name"]


class AbstractSolver(abc.ABC):
    """A way of solving Hamilton's equations on an interval with a trial solution per window."""

    #: the name configs and ``--solver`` use
    name: ClassVar[str]

    @abc.abstractmethod
    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *, rtol: float, atol: float,
              progress: Callable[[float], None] | None = None) -> PiecewiseSolution:
        """The solution on [t0, T] from z0 (already checked). ``progress(fraction)`` is called as
        the march advances."""


#: solver name -> class
SOLVERS: dict[str, type[AbstractSolver]] = {}


def register_solver(cls: type[AbstractSolver]) -> type[AbstractSolver]:
    """Add a solver class under its ``name`` (which must be new); returns it (a decorator)."""
    if cls.name in SOLVERS:
        raise ConfigError(f"solver name {cls.name!r} is taken already")
    SOLVERS[cls.name] = cls
    return cls


def solver_from_name(name: str, **settings: Any) -> AbstractSolver:
    """A solver by name with settings (one line naming the choices when the name is unknown)."""
    cls = SOLVERS.get(str(name))
    if cls is None:
        raise ConfigError(f"unknown solver {name!r}; choose one of {sorted(SOLVERS)}")
    try:
        return cls(**settings)
    except TypeError as exc:
        raise ConfigError(f"solver {name!r}: {exc}") from None

"""What every trajectory solver is: one small interface and one registry.

A solver object holds its own settings — its tolerances and what they mean among them — frozen and
checked when it is built, and turns a problem (a system, an initial state, an interval) into a
solution (:class:`~atlasnn.solutions.PolynomialSolution` or
:class:`~atlasnn.solutions.PiecewiseSolution`). :func:`atlasnn.solve` takes any of them; configs
and the CLI name them through :data:`SOLVERS` (a new solver is one class and one
:func:`register_solver` entry).
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import math
from numbers import Real
from typing import Any, Callable, ClassVar

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.solutions import AbstractSolution
from atlasnn.systems import HamiltonianSystem

__all__ = ["AbstractSolver", "SOLVERS", "register_solver", "solver_from_name", "check_tolerance",
           "refuse_unknown_settings", "solve_one", "monotone_progress"]


def check_tolerance(owner: str, name: str, value: Any, tightest: float, *, zero: bool = False) -> float:
    """``value`` as a float if it is a finite real number > 0 (≥ 0 with ``zero``) and not below
    ``tightest`` (what the solver can reach), else one line naming the value and the remedy."""
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(float(value)) \
            or float(value) < 0 or (float(value) == 0 and not zero):
        raise ConfigError(f"{owner} {name} must be a finite number {'>=' if zero else '>'} 0, got {value!r}")
    value = float(value)
    if 0 < value < tightest:
        raise ConfigError(f"{owner} {name} = {value:g} is below what it can reach ({tightest:g}); raise it to "
                          f"at least {tightest:g}")
    return value


class AbstractSolver(abc.ABC):
    """A way of solving Hamilton's equations on an interval with a trial solution per window.

    A subclass is a frozen dataclass with fields ``rtol`` and ``atol`` (its tolerances, in its own
    meaning), a ``name`` and ``tightest`` (the smallest rtol it can reach), and :meth:`solve`."""

    #: the name configs and ``--solver`` use
    name: ClassVar[str]
    #: the smallest tolerance the solver can reach (smaller ones are refused when it is built)
    tightest: ClassVar[float]

    @abc.abstractmethod
    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *,
              progress: Callable[[float], None] | None = None) -> AbstractSolution:
        """The solution on [t0, T] from z0 (already checked). ``progress(fraction)`` is called as
        the march advances."""

    def check_tolerances(self) -> None:
        """Refuse tolerances that are not numbers, below :attr:`tightest`, or an rtol above 1 (call
        from __post_init__)."""
        owner = type(self).__name__
        rtol = check_tolerance(owner, "rtol", self.rtol, self.tightest)
        if rtol > 1.0:
            raise ConfigError(f"{owner} rtol = {rtol:g} allows errors larger than the solution itself; "
                              "give a relative tolerance of at most 1")
        object.__setattr__(self, "rtol", rtol)
        object.__setattr__(self, "atol", check_tolerance(owner, "atol", self.atol, 0.0, zero=True))

    def with_tolerance(self, rtol: Any = None, atol: Any = None) -> "AbstractSolver":
        """A copy with other tolerances (None keeps the solver's own), checked as at construction."""
        changes = {k: v for k, v in (("rtol", rtol), ("atol", atol)) if v is not None}
        return dataclasses.replace(self, **changes) if changes else self


#: solver name -> class
SOLVERS: dict[str, type[AbstractSolver]] = {}


def solve_one(solve_batch: Callable, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float,
              progress: Callable[[float], None] | None) -> AbstractSolution:
    """One trajectory by a solver's ``solve_batch`` of one member; a stop's ``.partial`` (the list
    of the batch) becomes that member's part up to the stop, or None."""
    try:
        return solve_batch(system, np.asarray(z0)[None], t0, T, progress=progress)[0]
    except ConfigError as exc:
        if isinstance(getattr(exc, "partial", None), list):
            exc.partial = exc.partial[0]
        raise


def monotone_progress(progress: Callable[[float], None]) -> Callable[[float], None]:
    """``progress`` never called with less than before (a march that starts again does not move
    the bar back: it holds until the new march passes the old one's point)."""
    most = [0.0]

    def report(fraction: float) -> None:
        most[0] = max(most[0], fraction)
        progress(most[0])

    return report


def refuse_unknown_settings(cls: type) -> type:
    """A settings dataclass whose constructor refuses a keyword that is none of its fields in one
    line naming it and the fields (rather than Python's TypeError); returns it (a decorator, after
    ``@dataclass``). :func:`register_solver` applies it to every solver."""
    init = cls.__init__
    names = tuple(f.name for f in dataclasses.fields(cls) if f.init)

    @functools.wraps(init)
    def __init__(self, *args: Any, **settings: Any) -> None:
        unknown = [k for k in settings if k not in names]
        if unknown:
            raise ConfigError(f"{type(self).__name__} has no setting {unknown[0]!r}; its settings are "
                              f"{', '.join(names)}")
        init(self, *args, **settings)

    cls.__init__ = __init__
    return cls


def register_solver(cls: type[AbstractSolver]) -> type[AbstractSolver]:
    """Add a solver class under its ``name`` (which must be new); returns it (a decorator, after
    ``@dataclass``; an unknown setting is refused in one line: :func:`refuse_unknown_settings`)."""
    if cls.name in SOLVERS:
        raise ConfigError(f"solver name {cls.name!r} is taken already")
    SOLVERS[cls.name] = refuse_unknown_settings(cls)
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

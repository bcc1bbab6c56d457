"""What every solution offers on top of ẑ(t) and dẑ/dt(t): H(ẑ(t)), the residual, and the
a-posteriori error estimate (computed once per solution and kept)."""

from __future__ import annotations

import abc
import warnings
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.solutions._estimate import ErrorEstimate, estimate_error

__all__ = ["AbstractSolution", "INTERVAL_SLACK", "ExtrapolationWarning", "ExtrapolationError", "check_inside",
           "finite_times"]


#: Relative slack at the interval's ends (times within it count as inside).
INTERVAL_SLACK = 1e-9


class ExtrapolationWarning(UserWarning):
    """A Solution was evaluated outside the interval it was trained on."""


class ExtrapolationError(AtlasError, ValueError):
    """A Solution with ``outside="raise"`` was evaluated outside its training interval."""


def check_inside(owner: Any, interval: tuple[float, float] | None, arr: np.ndarray) -> None:
    """The extrapolation rule (module docstring) for the times ``arr`` (finite) of a solution
    ``owner`` with attributes ``outside`` and ``_warned`` (a Solution or a PiecewiseSolution)."""
    if interval is None or owner.outside == "allow" or arr.size == 0:
        return
    t0, T = interval
    slack = INTERVAL_SLACK * (T - t0)
    lo, hi = float(arr.min()), float(arr.max())
    if lo >= t0 - slack and hi <= T + slack:
        return
    kind = type(owner).__name__
    msg = (f"evaluating the solution at times in [{lo:.6g}, {hi:.6g}], outside its "
           f"{getattr(owner, 'interval_name', 'training interval')} "
           f"[{t0:.6g}, {T:.6g}]: values there are an extrapolation")
    if owner.outside == "raise":
        raise ExtrapolationError(msg + f" ({kind}(..., outside='allow') permits it)")
    if not owner._warned:
        owner._warned = True
        warnings.warn(msg + f" (warned once per {kind})", ExtrapolationWarning, stacklevel=5)


def finite_times(t) -> np.ndarray:
    """``t`` as float64 times, or a one-line refusal of what is not a finite number."""
    try:
        arr = np.asarray(t, np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"times must be finite numbers, got {t!r}") from None
    if not np.all(np.isfinite(arr)):
        bad = float(arr[~np.isfinite(arr)].reshape(-1)[0])
        raise ConfigError(f"times must be finite numbers, got {bad!r} among them")
    return arr


class AbstractSolution(abc.ABC):
    """A solution of Hamilton's equations made of trained trial solutions (one, or one per window).

    A subclass provides ``system``, ``interval``, ``_evaluate(t) -> (ẑ, dẑ/dt, shape)`` and
    ``pieces()``; the rest is shared.
    """

    system: Any
    #: what its interval is called in the warning outside it (a solved solution was not trained)
    interval_name: ClassVar[str] = "training interval"

    @abc.abstractmethod
    def _evaluate(self, t) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        """(ẑ(t), dẑ/dt(t), t's shape)."""

    @abc.abstractmethod
    def pieces(self) -> list[tuple[Any, float, float, float]]:
        """(model, start, length, the model's own time at the start) per window, in order."""

    def __call__(self, t) -> np.ndarray:
        """ẑ(t): shape t.shape + (2d,)."""
        return self._evaluate(t)[0]

    def derivative(self, t) -> np.ndarray:
        """dẑ/dt(t): shape t.shape + (2d,)."""
        return self._evaluate(t)[1]

    def energy(self, t) -> np.ndarray:
        """H(ẑ(t)), evaluated in float64: shape t.shape."""
        return self.system.energy64(self(t))

    def residual(self, t) -> np.ndarray:
        """dẑ/dt − J∇H(ẑ) at t: how far the network is from Hamilton's equations there (J∇H in
        the solution's own precision: a float64 solution's field is not rounded to float32)."""
        z, dz, _ = self._evaluate(t)
        with jax.enable_x64(np.asarray(z).dtype == np.float64):
            return dz - np.asarray(self.system.vector_field(jnp.asarray(z)))

    def estimate(self, z0: Any = None) -> ErrorEstimate:
        """The a-posteriori error estimate over the whole interval (no reference needed; see
        :mod:`atlasnn.solutions._estimate`), computed on first use. ``z0``: the exact initial
        state when it is known (the network holds it rounded to float32); default: the system's
        z0 if the model's is its rounding, else δ(t0) = 0."""
        cache = self.__dict__.setdefault("_estimates", {})
        key = None if z0 is None else tuple(np.asarray(z0, np.float64).reshape(-1))
        if key not in cache:
            cache[key] = estimate_error(self.system, self.pieces(), z0=self._exact_z0(z0))
        return cache[key]

    def error_estimate(self, t) -> np.ndarray:
        """The estimated error z(t) − ẑ(t) at times of the interval: shape t.shape + (2d,). There is
        no estimate outside the interval: those rows are NaN, and the solution's ``outside`` rule
        warns (once) or raises, as evaluating there does."""
        pieces = self.pieces()
        t0, T = pieces[0][1], pieces[-1][1] + pieces[-1][2]
        arr = np.asarray(t, dtype=np.float64)
        check_inside(self, (t0, T), arr.reshape(-1))
        out = self.estimate().at(arr)
        slack = INTERVAL_SLACK * (T - t0)
        out[(arr < t0 - slack) | (arr > T + slack)] = np.nan
        return out

    def _exact_z0(self, z0: Any) -> np.ndarray | None:
        if z0 is not None:
            return np.asarray(z0, dtype=np.float64).reshape(-1)
        model = self.pieces()[0][0]
        own = np.asarray(model.z0)
        given = getattr(self.system, "z0", None)
        if given is not None and np.array_equal(np.asarray(given, dtype=own.dtype), own):
            return np.asarray(given, dtype=np.float64)
        return None

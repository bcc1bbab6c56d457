"""What every inverse fit returns (:class:`FitResult`), its Gauss–Newton covariance and the
rules that say when a fit is not to be trusted (:func:`flag_misfit`; the multistart and the
cross-checks of :mod:`atlasnn.inverse` add theirs)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.observations import Observations

__all__ = ["FitResult", "gauss_newton_covariance", "COND_LIMIT", "flag_misfit", "MISFIT_LIMIT", "distrust"]

#: above this condition number of the (column-scaled) Gauss–Newton matrix an unknown is unidentifiable
COND_LIMIT = 1e12


@dataclasses.dataclass
class FitResult:
    """The outcome of a fit ([`atlasnn.fit`][atlasnn.inverse.fit], by any method).

    ``std`` are Gauss–Newton standard errors at the optimum: sqrt of the diagonal of
    s²(JᵀJ)⁻¹ with s² = RSS/(n_data − n_unknowns) (``noise_estimate`` is s). An unknown that the
    data cannot determine (it lies in a direction where the column-scaled JᵀJ has condition
    number above ``COND_LIMIT``) gets std = inf, ``identifiable`` is False and ``notes``
    names it. ``trusted`` is False when a rule found a reason not to believe the estimate or its
    σ (a misfit, a bound, a second minimum, another method's better fit); ``notes`` says which and
    what to do.

    Attributes:
        names: the unknowns' names, in the order of ``estimate``.
        estimate: the fitted values.
        std: their standard errors (inf for an unknown the data cannot determine).
        covariance: the Gauss–Newton covariance of the estimates.
        noise_estimate: s, the noise level the residuals imply.
        residual_rms: the root mean square of the data misfits at the optimum.
        wall_time: seconds the fit took.
        n_rhs: evaluations of the vector field.
        n_solves: orbits integrated.
        method: the method, in words.
        success: whether the minimisation ended normally.
        message: its last message.
        identifiable: False when some unknown is not determined by the data.
        notes: the reasons behind ``trusted`` and ``identifiable``, each with what to do.
        t0: the time the orbits start from.
        n_data: the number of observed values.
        segments: the shooting segments (1: single shooting).
        cond: the condition number of the column-scaled JᵀJ.
        trusted: False when a rule found a reason not to believe the estimate or its σ.
        search: what a multistart tried (starts, failed starts, the minima found).
    """

    names: tuple[str, ...]
    estimate: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    noise_estimate: float
    residual_rms: float
    wall_time: float
    n_rhs: int
    n_solves: int
    method: str
    success: bool
    message: str
    identifiable: bool
    notes: list[str] = dataclasses.field(default_factory=list)
    t0: float = 0.0
    n_data: int = 0
    segments: int = 1
    cond: float = 1.0
    trusted: bool = True
    search: dict[str, Any] = dataclasses.field(default_factory=dict)

    def value(self, name: str) -> float:
        """The estimate of the unknown ``name``."""
        if name not in self.names:
            raise ConfigError(f"the fit has no unknown {name!r}; its unknowns are {list(self.names)}")
        return float(self.estimate[self.names.index(name)])

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "FitResult":
        """The record ``as_dict`` wrote, read back (keys that are not fields are ignored)."""
        arrays = {"estimate", "std", "covariance"}
        kw = {f.name: (np.asarray(d[f.name], float) if f.name in arrays else
                       tuple(d[f.name]) if f.name == "names" else d[f.name])
              for f in dataclasses.fields(cls) if f.name in d}
        return cls(**kw)

    def as_dict(self) -> dict[str, Any]:
        """A JSON-able summary of every field (non-finite numbers stay floats: ``inf``/``nan``)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = v.tolist() if isinstance(v, np.ndarray) else list(v) if isinstance(v, (tuple, list)) else v
        return out


def gauss_newton_covariance(J: np.ndarray, rss: float, dof: int):
    """(covariance, cond, indices of unidentifiable columns) from Gauss–Newton at the optimum."""
    s2 = rss / dof
    norms = np.linalg.norm(J, axis=0)
    dead = norms <= 1e-14 * max(float(norms.max()), np.finfo(float).tiny)  # no effect on any residual
    scale = np.where(dead, 1.0, norms)
    A = (J / scale).T @ (J / scale)
    lam, V = np.linalg.eigh(A)
    top = max(float(lam[-1]), np.finfo(float).tiny)
    cond = float(top / lam[0]) if lam[0] > 0 else math.inf
    weak = set(np.flatnonzero(dead).tolist())
    if cond > COND_LIMIT:
        for k in np.flatnonzero(lam < top / COND_LIMIT):
            weak |= set(np.flatnonzero(np.abs(V[:, k]) > 0.1).tolist())
    inv = np.linalg.pinv(A, rcond=1.0 / COND_LIMIT, hermitian=True)
    cov = s2 * inv / np.outer(scale, scale)
    for j in weak:
        cov[j, :] = cov[:, j] = np.nan
        cov[j, j] = np.inf
    return cov, cond, sorted(weak)


#: a fit whose residual RMS exceeds this fraction of the data's RMS does not explain the data
MISFIT_LIMIT = 0.1


def flag_misfit(fit: FitResult, observations: Observations) -> FitResult:
    """Mark a fit untrusted whose σ says nothing (:func:`_flag_no_sigma`), or whose residual RMS
    exceeds MISFIT_LIMIT × the data's RMS (``success`` False, untrusted, a note): its σ are then the curvature of a wrong valley (a Toda pair's c from a
    guess of 0.5: 0.336 ± 0.014, truth 0.8, residual 75 % of the data's RMS; from 0.7: 0.8004,
    residual 1 %). The advice skips what the fit already did (a multistart tried other guesses)."""
    scale = float(np.sqrt(np.mean(observations.values ** 2)))
    _flag_no_sigma(fit, scale)
    ratio = fit.residual_rms / scale if scale > 0 else 0.0
    if ratio > MISFIT_LIMIT:
        fit.success = False
        remedy = ("the model may be wrong, or the record too long for single shooting: raise segments or fit a "
                  "shorter record" if fit.search else
                  "try other guesses (a multistart), segments > 1 (multiple shooting) or a shorter record")
        distrust(fit, f"the fit does not explain the data: residual RMS {fit.residual_rms:.3g} is {ratio:.0%} of "
                      f"the data's RMS (a local minimum, or the wrong model): {remedy}")
    return fit


def _flag_no_sigma(fit: FitResult, scale: float) -> None:
    """A fit whose σ says nothing is not trusted: an unknown the data cannot determine (σ = inf
    already), or residuals at round-off (the fit passes through the data: s² = 0 and σ = 0 would
    claim an exact estimate; it is set to inf)."""
    if not fit.identifiable:
        distrust(fit, "an unknown is not identifiable from these data (its σ is inf): fix it, or add "
                      "observations that depend on it")
    if not math.isfinite(fit.noise_estimate) or fit.noise_estimate <= np.finfo(np.float64).eps * scale:
        fit.std = np.full_like(np.asarray(fit.std, np.float64), np.inf)
        fit.covariance = np.full_like(np.asarray(fit.covariance, np.float64), np.nan)
        np.fill_diagonal(fit.covariance, np.inf)
        distrust(fit, f"no σ: the residuals are at round-off (noise estimate {fit.noise_estimate:.3g}), so the "
                      "fit passes through the data and nothing is left to measure the noise; add observations")


def distrust(fit: FitResult, reason: str) -> FitResult:
    """Mark ``fit`` untrusted for ``reason`` (kept in its notes, said once)."""
    fit.trusted = False
    if reason not in fit.notes:
        fit.notes.append(reason)
    return fit

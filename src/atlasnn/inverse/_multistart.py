"""Fits that survive a bad first guess, and say when they are not to be trusted.

:func:`fit_multistart` runs least-squares shooting (:func:`fit_shooting`) from
the user's guess and from a scrambled Halton set of starts spread over the unknowns' bounds, and
keeps the fit of lowest misfit. A start whose orbit cannot be integrated (it escapes before the
last observation) is skipped and counted, never fatal; only when every start fails is the fit
refused. The distinct minima it met are kept in ``search``.

:func:`judge_fit` applies the rules under which a fit is marked untrusted (``trusted`` False and a
note naming the remedy):

- an estimate at a bound of its unknown (the minimum may lie beyond it: widen the bounds);
- a second minimum, at least 4σ away, whose misfit is not significantly worse
  (Δχ² = ΔRSS/s² below the 99 % quantile of χ² with as many degrees of freedom as unknowns): the
  data cannot choose between them, and the σ of either understates the uncertainty;
- another fit of the same data (the multistart's best) with a significantly lower misfit: this
  fit sits in a local minimum (the cross-check a family run applies to every fit).

The misfit rule itself (a residual far above the data's scale) is
:func:`flag_misfit`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Sequence

import numpy as np

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.inverse._fit_result import FitResult, distrust
from atlasnn.inverse._shooting import fit_shooting, shooting_misfit
from atlasnn.observations import Observations, Unknown, check_unknowns
from atlasnn.systems import HamiltonianSystem

__all__ = ["fit_multistart", "judge_fit", "auto_starts", "SIGNIFICANCE", "DISTINCT_SIGMAS", "BOUND_FRACTION"]

#: a misfit difference below the χ² quantile at this level is not significant
SIGNIFICANCE = 0.99
#: two minima closer than this many σ (of the better fit) count as one
DISTINCT_SIGMAS = 4.0
#: an estimate within this fraction of its bounds' width of a bound sits at the bound
BOUND_FRACTION = 1e-4


def auto_starts(n_unknowns: int) -> int:
    """Starts of ``starts="auto"``: the guess and 12 more per unknown (a 20-start grid over one
    unknown's bounds found the Hénon–Heiles coupling from every guess: docs/FAMILIES.md, "From bad first guesses")."""
    return 1 + 12 * n_unknowns


def _start_points(unknowns: tuple[Unknown, ...], count: int, seed: int) -> np.ndarray:
    """The guess, then ``count − 1`` scrambled Halton points scaled to the bounds."""
    lo = np.array([u.low for u in unknowns])
    hi = np.array([u.high for u in unknowns])
    guess = np.array([[u.guess for u in unknowns]])
    if count <= 1:
        return guess
    from scipy.stats import qmc  # scipy.stats costs 0.35 s to import: only where a fit needs it

    pts = qmc.Halton(len(unknowns), scramble=True, seed=seed).random(count - 1)
    return np.concatenate([guess, lo + pts * (hi - lo)])


def _minima(fits: list[FitResult]) -> list[dict[str, Any]]:
    """Distinct minima, best first: fits within DISTINCT_SIGMAS σ of a better one are merged."""
    out: list[dict[str, Any]] = []
    for f in sorted(fits, key=lambda f: f.noise_estimate):
        sigma = np.where(np.isfinite(f.std) & (f.std > 0), f.std, np.abs(f.estimate) * 1e-6 + 1e-12)
        for m in out:
            if np.all(np.abs(np.asarray(m["estimate"]) - f.estimate) <= DISTINCT_SIGMAS * np.asarray(m["sigma"])):
                m["starts"] += 1
                break
        else:
            rss = f.noise_estimate ** 2 * (f.n_data - len(f.names))
            out.append({"estimate": f.estimate.tolist(), "sigma": sigma.tolist(), "rss": rss, "starts": 1})
    return out


def fit_multistart(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown],
                   z0: Any = None, *, t0: float = 0.0, segments: int = 1, starts: int | str = "auto", seed: int = 0,
                   **shooting: Any) -> FitResult:
    """Shooting from the guess and from ``starts − 1`` more points over the bounds; the fit of
    lowest misfit, judged (:func:`judge_fit`), with the search in ``search``."""
    tic = time.perf_counter()
    unknowns = check_unknowns(unknowns, system.state_names, system.param_names, observations.n_values,
                              observations=observations, t0=t0)
    count = auto_starts(len(unknowns)) if starts == "auto" else starts
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ConfigError(f"starts must be a positive integer or \"auto\", got {starts!r}")
    fits, failed = [], []
    for point in _start_points(unknowns, int(count), seed):
        trial = tuple(dataclasses.replace(u, guess=float(g)) for u, g in zip(unknowns, point))
        try:
            fits.append(fit_shooting(system, observations, trial, z0, t0=t0, segments=segments, **shooting))
        except ConfigError:
            raise  # bad input is bad from every start
        except AtlasError as exc:  # an orbit that escapes from this start: the next one
            failed.append({"start": point.tolist(), "reason": str(exc)})
    if not fits:
        raise AtlasError(f"shooting could not integrate system {system.name!r} from any of {count} starts over the "
                         f"bounds (first: {failed[0]['reason']}); narrow the bounds to where the orbit stays bounded")
    best = min(fits, key=lambda f: f.noise_estimate)
    best.search = {"starts": int(count), "failed_starts": len(failed), "minima": _minima(fits),
                   "failed": failed[:5], "seed": seed}
    best.wall_time = time.perf_counter() - tic
    best.n_rhs, best.n_solves = sum(f.n_rhs for f in fits), sum(f.n_solves for f in fits)
    best.method = f"{best.method} ({count} starts)"
    return judge_fit(best, unknowns)


def _chi2_quantile(dof: int) -> float:
    """χ²_dof(SIGNIFICANCE) (scipy.stats imported here: 0.35 s that a run without fits skips)."""
    from scipy.stats import chi2

    return float(chi2.ppf(SIGNIFICANCE, dof))


def _threshold(fit: FitResult) -> float:
    """The smallest significant RSS difference for ``fit``: s² × χ²_p(SIGNIFICANCE)."""
    return fit.noise_estimate ** 2 * _chi2_quantile(len(fit.names))


def judge_fit(fit: FitResult, unknowns: Sequence[Unknown], *, system: HamiltonianSystem | None = None,
              observations: Observations | None = None, z0: Any = None, better: FitResult | None = None) -> FitResult:
    """Mark ``fit`` untrusted where a rule of the module docstring applies; ``better``: another
    fit of the same data (the multistart's) to check this one against (needs ``system`` and
    ``observations``: this fit's misfit is measured as shooting sees it)."""
    for u, value in zip(unknowns, fit.estimate):
        edge = BOUND_FRACTION * (u.high - u.low)
        for bound, side in ((u.low, "low"), (u.high, "high")):
            if abs(value - bound) <= edge:
                distrust(fit, f"{u.name} = {value:.6g} sits at its bound {side} = {bound:g}: the best fit may lie "
                              f"beyond it; widen [{u.low:g}, {u.high:g}]")
    minima = (fit.search or {}).get("minima") or []
    if len(minima) > 1 and math.isfinite(fit.noise_estimate):
        for m in minima[1:]:
            delta = (m["rss"] - minima[0]["rss"]) / max(fit.noise_estimate ** 2, 1e-300)
            if delta < _chi2_quantile(len(fit.names)):
                where = ", ".join(f"{n} = {v:.6g}" for n, v in zip(fit.names, m["estimate"]))
                distrust(fit, f"a second minimum ({where}) fits the data about as well (Δχ² = {delta:.2g}): the data "
                              "cannot choose between them; add observations or lengthen the record")
    if better is not None and better is not fit and system is not None and observations is not None:
        # both misfits as single shooting sees them (a multiple-shooting fit's own RSS also holds
        # its continuity gaps, and its segments follow the data where one orbit from t0 may not)
        mine = shooting_misfit(system, observations, unknowns, fit.estimate, z0, t0=fit.t0)
        theirs = shooting_misfit(system, observations, unknowns, better.estimate, z0, t0=better.t0)
        if math.isfinite(theirs) and mine - theirs > _threshold(better):
            where = ", ".join(f"{n} = {v:.6g}" for n, v in zip(better.names, better.estimate))
            excess = "an orbit that cannot be integrated" if math.isinf(mine) else f"Δχ² = {(mine - theirs) / better.noise_estimate ** 2:.3g}"
            distrust(fit, f"a local minimum: {better.method} found {where}, which fits the data far better "
                          f"(this estimate: {excess}); prefer that one, or start this method near it")
    return fit

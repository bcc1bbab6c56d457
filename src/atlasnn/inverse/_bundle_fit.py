"""Parameter identification with a trained bundle: the network as a fast, differentiable model.

A bundle ẑ(t; z0, λ) trained on Hamilton's equations alone (no data) over a box that covers the
unknowns' bounds answers any candidate (z0, λ) without training again. Fitting is then ordinary
least squares over the unknowns (SciPy's ``least_squares``, trust-region reflective within the
bounds), with the exact Jacobian ∂ẑ/∂(z0, λ) by forward-mode autodiff of the bundle, and the
Gauss–Newton covariance at the optimum. One bundle serves every data set of its box: the fit
itself costs milliseconds, the training is paid once.
"""

from __future__ import annotations

import math
import time
from typing import Any, Sequence

import numpy as np
from scipy.optimize import least_squares

from atlasnn.errors import ConfigError
from atlasnn.inverse._fit_result import FitResult, flag_misfit, gauss_newton_covariance
from atlasnn.observations import Observations, Unknown, check_unknowns, fixed_values
from atlasnn.solutions import BundleSolution
from atlasnn.systems import BundleBox

__all__ = ["fit_with_bundle", "bundle_box_for"]


def bundle_box_for(system, unknowns: Sequence[Unknown], z0: Any, T: float, t0: float = 0.0):
    """The :class:`~atlasnn.systems.BundleBox` a bundle needs to fit these unknowns: the unknown
    parameters over their bounds, the unknown z0 components over theirs, the rest fixed."""
    z0 = np.array(system.initial_state(z0), np.float64)
    low, high = z0.copy(), z0.copy()
    params = {}
    for u in unknowns:
        if u.is_initial_state:
            i = system.state_names.index(u.component)
            low[i], high[i] = u.low, u.high
        else:
            params[u.name] = (u.low, u.high)
    return BundleBox(tuple(low), tuple(high), T, params, t0)


def _check_cover(bundle: BundleSolution, system, unknowns: tuple[Unknown, ...]) -> None:
    box = bundle.box
    for u in unknowns:
        if u.is_initial_state:
            i = system.state_names.index(u.component)
            lo, hi = box.z0_low[i], box.z0_high[i]
        elif u.name in box.params:
            lo, hi = box.params[u.name]
        else:
            raise ConfigError(f"unknown {u.name!r} is not an input of the bundle (it varies "
                              f"{list(box.param_names)} and z0 within its box)")
        if u.low < lo or u.high > hi:
            raise ConfigError(f"unknown {u.name!r}: bounds [{u.low}, {u.high}] leave the bundle's range [{lo}, {hi}]")


def fit_with_bundle(bundle: BundleSolution, observations: Observations, unknowns: Sequence[Unknown],
                    z0: Any = None, *, max_nfev: int = 100) -> FitResult:
    """Fit the unknowns with a trained bundle (its box must cover their bounds); returns a
    :class:`~atlasnn.evaluation.FitResult` (method "network (bundle)"; ``wall_time`` is the fit's,
    not the bundle's training)."""
    start = time.perf_counter()
    system = bundle.system
    if system is None:
        raise ConfigError("the bundle has no system attached; load it with its system")
    observations.check_interval(bundle.t0, bundle.T)
    unknowns = check_unknowns(unknowns, system.state_names, system.param_names, observations.n_values,
                              observations=observations, t0=bundle.t0)
    _check_cover(bundle, system, unknowns)
    cols = observations.indices(system.state_names)
    z_base = np.array(system.initial_state(z0), np.float64)
    lam_base = np.asarray([system.params[n] for n in bundle.box.param_names], np.float64)
    z_idx = [(j, system.state_names.index(u.component)) for j, u in enumerate(unknowns) if u.is_initial_state]
    l_idx = [(j, bundle.box.param_names.index(u.name)) for j, u in enumerate(unknowns) if not u.is_initial_state]

    def members(phi):
        z, lam = z_base.copy(), lam_base.copy()
        for j, i in z_idx:
            z[i] = phi[j]
        for j, i in l_idx:
            lam[i] = phi[j]
        return z, lam

    def residual(phi):
        z, lam = members(phi)
        return (bundle(observations.t, z, lam)[0][:, cols] - observations.values).reshape(-1).astype(np.float64)

    def jacobian(phi):
        z, lam = members(phi)
        dz, dl = bundle.sensitivities(observations.t, z, lam)
        out = np.zeros((observations.n_values, len(unknowns)))
        for j, i in z_idx:
            out[:, j] = dz[0][:, cols, i].reshape(-1)
        for j, i in l_idx:
            out[:, j] = dl[0][:, cols, i].reshape(-1)
        return out

    guess = np.asarray([u.guess for u in unknowns])
    bounds = (np.asarray([u.low for u in unknowns]), np.asarray([u.high for u in unknowns]))
    res = least_squares(residual, guess, jac=jacobian, bounds=bounds, method="trf", x_scale="jac",
                        max_nfev=max_nfev)
    r = res.fun
    informs = ~fixed_values(observations, unknowns, bundle.t0).reshape(-1)  # a bundle starts at z0 too
    m, n, rss = int(informs.sum()), len(unknowns), float(r[informs] @ r[informs])
    cov, cond, weak = gauss_newton_covariance(res.jac, rss, m - n)
    names = tuple(u.name for u in unknowns)
    return flag_misfit(FitResult(names=names, estimate=np.asarray(res.x, np.float64), std=np.sqrt(np.abs(np.diag(cov))),
                     covariance=cov, noise_estimate=math.sqrt(rss / (m - n)),
                     residual_rms=float(np.sqrt(np.mean(r**2))), wall_time=time.perf_counter() - start,
                     n_rhs=0, n_solves=int(res.nfev), method="network (bundle)", success=bool(res.success),
                     message=" ".join(str(res.message).split()), identifiable=not weak,
                     notes=[f"{names[j]} is not identifiable from these data (condition number {cond:.3g})"
                            for j in weak], t0=bundle.t0, n_data=m, cond=cond), observations)

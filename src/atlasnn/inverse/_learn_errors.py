"""The standard errors of a learned H's parameters, for models of few parameters.

A model of at most ``MAX_PARAMETERS`` values (a known form with unknown coefficients) trained
through the solver is a nonlinear least-squares fit: at the result, the Jacobian J of the weighted
residuals with respect to θ and the fitted start values gives the covariance s²·(JᵀJ)⁻¹, s² the
residuals' variance. The start values are nuisance parameters: θ's block of the inverse profiles
them out. Residuals that share observations (overlapping segments) are not independent; the
covariance is scaled by how many times each observation enters them. The noise of the observed
start values is not a parameter of the fit: with noisy data the standard errors are a lower
estimate (measured: errors of about two standard errors occur, docs/LEARNED_H_MEASURED.md). A
parameter whose standard error is more than ``VAGUE`` of its size is not determined by the data; a
Gauss–Newton step from the result that moves a parameter by more than its standard error (and
``SHORT`` of its size) says the training stopped short of the minimum; where the minimum through
steps half as long lies more than a standard error away, the step biases the parameters.
"""

from __future__ import annotations

from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

__all__ = ["standard_errors", "MAX_PARAMETERS", "SHORT", "VAGUE", "BIAS"]

#: models with more values than this (networks) get no standard errors
MAX_PARAMETERS = 32
#: a standard error above this part of its value: the data do not determine the parameter
VAGUE = 0.1
#: a Gauss–Newton step from the result larger than its standard error and this part of the value:
#: the training stopped short of the minimum
SHORT = 5e-3
#: the minimum through steps half as long moving a parameter by more than its standard error and this
#: part of its value: the step biases it
BIAS = 1e-3


def standard_errors(residuals: tuple[Callable, float] | None, model, unknown,
                    refined: tuple[Callable, float] | None = None) -> tuple[np.ndarray | None, list[str]]:
    """(θ's standard errors or None, the reasons not to trust them: a parameter the data do not
    determine, a training that stopped short of the loss's minimum, or — with ``refined``, the
    residuals through steps half as long — a step whose error moves θ by more than its standard
    error: the modified Hamiltonian's parameters, not the true one's)."""
    fit = _linearised(residuals, model, unknown)
    if fit is None:
        return None, []
    values, std, step = fit
    reasons = []
    vague = [i for i in range(values.size) if not np.isfinite(std[i]) or std[i] > VAGUE * abs(values[i])]
    if vague:
        listed = ", ".join(f"θ[{i}] = {values[i]:.4g} ± {std[i]:.2g}" for i in vague[:4])
        reasons.append(f"the data do not determine every parameter: {listed} (a standard error over {VAGUE:.0%} of "
                       "the value); longer or more trajectories, end-to-end segments (stride=ahead), or fewer unknowns")
    # a Gauss–Newton step from the result: where it moves θ by more than its standard error, the
    # training stopped short of the least-squares minimum and θ is off by more than the data say
    short = [i for i in range(values.size) if np.isfinite(std[i]) and abs(step[i]) > max(std[i], SHORT * abs(values[i]))]
    if short and np.all(np.isfinite(step)):
        listed = ", ".join(f"θ[{i}] = {values[i]:.4g} → {values[i] + step[i]:.4g}" for i in short[:4])
        reasons.append(f"the training stopped short of the loss's minimum: a Gauss–Newton step moves {listed}, more "
                       f"than its standard error and {SHORT:.1%} of the value; more steps or a larger rate")
    finer = None if refined is None else _linearised(refined, model, unknown)
    if finer is not None and np.all(np.isfinite(finer[2])):
        # the minimum through steps half as long, less the minimum through these: what the step moves θ by
        moved = finer[2] - step
        biased = [i for i in range(values.size)
                  if np.isfinite(std[i]) and abs(moved[i]) > max(std[i], BIAS * abs(values[i]))]
        if biased:
            listed = ", ".join(f"θ[{i}] = {values[i]:.4g} → {values[i] + moved[i]:.4g}" for i in biased[:4])
            reasons.append(f"the step biases θ: through steps half as long the least-squares minimum moves {listed}, "
                           f"more than its standard error and {BIAS:.1%} of the value (θ is the modified Hamiltonian's); "
                           "train with more steps "
                           "(SplittingComposition(steps=…)) until it no longer moves")
    return std, reasons


def _linearised(residuals: tuple[Callable, float] | None, model, unknown) -> tuple | None:
    """θ's values, standard errors and the Gauss–Newton step from the result, from the residuals'
    Jacobian at it; None for a large model or where it cannot be formed."""
    if residuals is None:
        return None
    residual, overlap = residuals
    params, static = eqx.partition(model, eqx.is_inexact_array)
    flat, unravel = ravel_pytree(params)
    if flat.size > MAX_PARAMETERS:
        return None
    unknown = jnp.asarray(unknown)
    with jax.enable_x64(True):
        x = jnp.concatenate([flat, unknown.ravel()])
        split = lambda x: (eqx.combine(unravel(x[:flat.size]), static), x[flat.size:].reshape(unknown.shape))  # noqa: E731
        function = lambda x: residual(*split(x))  # noqa: E731
        try:
            r, jac = (np.asarray(a) for a in _with_jacobian(function, x))
        except (jax.errors.JaxRuntimeError, eqx.EquinoxRuntimeError):  # a solve that fails there: the
            return None  # trained result is kept without standard errors
    if not (np.all(np.isfinite(jac)) and np.all(np.isfinite(r))):
        return None
    used = np.any(jac != 0, axis=1) | (r != 0)  # the residuals of observed values (the others are 0)
    count, size = int(used.sum()), x.size
    if count <= size:
        return None
    # residual i is √w (prediction − observation), w = 1/count: s² of the unweighted ones is Σr²·count/(count − p)
    variance = float(np.sum(r ** 2)) * count / (count - size)
    normal = jac[used].T @ jac[used] * count  # JᵀJ of the unweighted residuals
    try:
        inverse = np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        inverse = np.full((size, size), np.inf)
    std = np.sqrt(np.clip(np.diag(inverse)[:flat.size] * variance * overlap, 0.0, np.inf))
    step = -(inverse @ (jac[used].T @ r[used]) * count)[:flat.size]
    return np.asarray(flat), std, step


def _with_jacobian(function: Callable, x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(function(x), its Jacobian) from one compiled program: forward mode (a pass per parameter)
    where the solve has a forward rule, else reverse mode (the Gauss core's custom rule is reverse
    only: a pass per residual). One compiled program rather than primitive by primitive: through the
    Gauss solver the dispatch of each primitive cost more than the compile."""
    try:
        return jax.jit(lambda x: (function(x), jax.jacfwd(function)(x)))(x)
    except TypeError:  # no forward rule: refused while tracing, before anything is compiled
        return jax.jit(lambda x: (function(x), jax.jacrev(function)(x)))(x)

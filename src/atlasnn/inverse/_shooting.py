"""Classical least-squares shooting: the baseline for identifying parameters of H from data.

Given observations of some state components at times t_i, :func:`fit_shooting` finds the unknown
parameters θ of H (and, if asked, unknown components of the initial state z0) that minimise

    Σ_i ‖ z(t_i; θ, z0)[observed] − obs_i ‖²,

where z(t; θ, z0) solves dz/dt = J∇H(z; θ) from t0. The minimiser is SciPy's ``least_squares``
(trust-region reflective, bounds from the unknowns, ``x_scale="jac"``).

The Jacobian of the residuals comes from **forward sensitivities** ∂z(t_i)/∂(θ, z0), one column
per unknown. The solve (:func:`atlasnn.inverse.parametric_solver`, θ an argument: trying a new
θ compiles nothing) is ``solver="gauss"`` by default: the compiled Gauss collocation on windows of
one length for the whole fit, its sensitivities the forward-mode derivatives of that same program
(:class:`atlasnn.solver.ParametricGauss`); ``solver="dop853"``: SciPy's DOP853 with the
variational equations dS/dt = A(z, θ) S + ∂f/∂θ · D, A = ∂f/∂z, integrated beside z.

``segments > 1`` gives **multiple shooting**: the observation times are split into consecutive
segments, every segment after the first starts from its own unknown state, and the residuals are
the data misfit of every segment plus the continuity gaps (end of segment k − start of segment
k+1) multiplied by a weight, 1 at first and ``continuity_weight`` in a second pass. Only the
user's unknowns are reported, with standard errors from the full Gauss–Newton covariance. The
segments' start states begin at the data (observed components) and where the guess's orbit from
the previous start arrives (the others), so an orbit that escapes from the guess over the whole
record does not stop the fit. ``segments="auto"``: about three per 1/‖A‖ of the record
(:func:`auto_segments`).
"""

from __future__ import annotations

import math
import time
from typing import Any, Sequence

import numpy as np
from scipy.optimize import least_squares

from atlasnn.errors import AtlasError, ConfigError, ParametricSolveFailed
from atlasnn.inverse._field import field_scale
from atlasnn.inverse._fit_result import FitResult, flag_misfit, gauss_newton_covariance
from atlasnn.inverse._orbits import PARAMETRIC_SOLVERS, parametric_solver
from atlasnn.inverse._synthetic import finite_number
from atlasnn.observations import Observations, Unknown, check_unknowns, fixed_values
from atlasnn.systems import HamiltonianSystem

__all__ = ["fit_shooting", "predict_fit", "shooting_misfit", "check_shooting_inputs", "auto_segments"]


# -------------------------------------------------------------------------------- problem
class _Problem:
    """Residuals and their Jacobian for single (one segment) or multiple shooting."""

    def __init__(self, system, obs, unknowns, z0, t0, segments, rtol, atol, weight, solver="gauss"):
        self.system, self.obs, self.w = system, obs, weight
        self.solve = parametric_solver(system, rtol, atol, solver)
        self.idx = obs.indices(system.state_names)
        self.theta0, self.z0 = system.param_vector(), z0
        pn, sn = list(system.param_names), list(system.state_names)
        self.p_cols = [(i, pn.index(u.name)) for i, u in enumerate(unknowns) if not u.is_initial_state]
        self.z_cols = [(i, sn.index(u.component)) for i, u in enumerate(unknowns) if u.is_initial_state]
        self.n_user, self.n = len(unknowns), system.state_dim
        M, C = obs.values.shape
        bounds = np.array_split(np.arange(M), segments)
        self.rows = [(int(b[0]), int(b[-1]) + 1) for b in bounds]
        self.starts = [float(t0)] + [float(obs.t[a]) for a, _ in self.rows[1:]]
        self.n_x = self.n_user + self.n * (segments - 1)
        self.n_res = M * C + self.n * (segments - 1)
        self.n_rhs = self.n_solves = 0
        self.memo: tuple[bytes, np.ndarray, np.ndarray] | None = None

    def theta_z0(self, x):
        theta, z = self.theta0.copy(), self.z0.copy()
        for i, j in self.p_cols:
            theta[j] = x[i]
        for i, j in self.z_cols:
            z[j] = x[i]
        return theta, z

    def system_solve(self, theta, z, start, end):
        """The state at ``end`` from ``z`` at ``start`` (one solve)."""
        Z, _, nfev = self.solve(z, theta, start, np.array([end]))
        self.n_rhs, self.n_solves = self.n_rhs + nfev, self.n_solves + 1
        return Z[-1].copy()

    def trajectory(self, x, times):
        theta, z = self.theta_z0(x)
        Z, _, nfev = self.solve(z, theta, self.starts[0], times)
        self.n_rhs, self.n_solves = self.n_rhs + nfev, self.n_solves + 1
        return Z

    def _segment(self, k, x, theta):
        """(model at the segment's rows and its end, sensitivities, Jacobian columns of x)."""
        n, P = self.n, self.theta0.size
        a, b = self.rows[k]
        end = [self.starts[k + 1]] if k + 1 < len(self.rows) else []
        times = np.concatenate([self.obs.t[a:b], end])
        if k == 0:
            _, z = self.theta_z0(x)
            cols = list(range(self.n_user))
            S0, D = np.zeros((n, len(cols))), np.zeros((P, len(cols)))
            for i, j in self.p_cols:
                D[j, i] = 1.0
            for i, j in self.z_cols:
                S0[j, i] = 1.0
        else:
            off = self.n_user + n * (k - 1)
            z = x[off:off + n]
            cols = [i for i, _ in self.p_cols] + list(range(off, off + n))
            S0, D = np.zeros((n, len(cols))), np.zeros((P, len(cols)))
            for c, (_, j) in enumerate(self.p_cols):
                D[j, c] = 1.0
            S0[:, len(self.p_cols):] = np.eye(n)
        Z, S, nfev = self.solve(z, theta, self.starts[k], times, S0, D)
        self.n_rhs, self.n_solves = self.n_rhs + nfev, self.n_solves + 1
        return Z, S, cols

    def evaluate(self, x):
        key = np.asarray(x, np.float64).tobytes()
        if self.memo is not None and self.memo[0] == key:
            return self.memo[1], self.memo[2]
        theta, _ = self.theta_z0(x)
        C, n = self.idx.size, self.n
        r, J = np.zeros(self.n_res), np.zeros((self.n_res, self.n_x))
        data_end = self.obs.values.size
        for k, (a, b) in enumerate(self.rows):
            Z, S, cols = self._segment(k, x, theta)
            m = b - a
            r[a * C:b * C] = (Z[:m, self.idx] - self.obs.values[a:b]).reshape(-1)
            J[a * C:b * C, cols] = S[:m][:, self.idx, :].reshape(m * C, len(cols))
            if k + 1 < len(self.rows):
                off = self.n_user + n * k
                c0 = data_end + n * k
                r[c0:c0 + n] = self.w * (Z[m] - x[off:off + n])
                J[c0:c0 + n, cols] = self.w * S[m]
                J[c0:c0 + n, off:off + n] -= self.w * np.eye(n)
        self.memo = (key, r, J)
        return r, J


# ------------------------------------------------------------------------------------ fit
def fit_shooting(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown],
                 z0: Any = None, *, t0: float = 0.0, segments: int | str = 1, rtol: float = 1e-10,
                 atol: float = 1e-10, max_nfev: int = 200, continuity_weight: float = 1e3,
                 solver: str = "gauss") -> FitResult:
    """Fit unknown parameters of H (and initial-state components) to observations by shooting.

    Minimises Σ (model(t_i) − obs_i)² over the unknowns with ``least_squares`` (method "trf",
    bounds from the unknowns, ``x_scale="jac"``); the model is the orbit from ``t0`` (``solver``:
    ``"gauss"``, the compiled Gauss collocation, or ``"dop853"``; ``rtol``, ``atol``) with the
    system's parameters and ``z0`` (default ``system.z0``) replaced where an unknown names them.
    The Jacobian comes from forward sensitivities (module docstring), not finite differences.

    ``segments > 1``: multiple shooting. The observation rows are split into that many
    consecutive groups; segment k ≥ 1 starts at its first observation time from its own unknown
    state (initialised from one solve at the guess); the residuals are the data misfits plus the
    continuity gaps times a weight (1/noise-scale: a gap counts as a data misfit that many times
    larger). The weight is 1 for a first minimisation (the iterates may leave the continuous
    trajectories, which lets them pass the many local minima that single shooting meets on a long
    interval) and ``continuity_weight`` for a second one started from the first one's optimum (the
    segments then join to about 1/continuity_weight of the noise). Only the user's unknowns are
    reported; their std come from the full Gauss–Newton covariance at the end.

    Raises:
        SystemError_: the system has no ``parametric`` H or no parameters.
        ConfigError: bad observations, unknowns, times outside [t0, last time], bad options, or
            more unknowns than the data can determine.
        AtlasError: the model cannot be integrated at the initial guess (or during the fit).
    """
    start = time.perf_counter()
    auto = isinstance(segments, str) and segments == "auto"
    _check_options(system, observations, t0, rtol, atol, continuity_weight, 1 if auto else segments, max_nfev)
    _check_solver(solver)
    t0 = float(t0)
    unknowns = check_shooting_inputs(system, observations, unknowns, t0=t0, segments=segments)
    if auto:
        segments = auto_segments(system, observations, unknowns, z0, t0=t0)
        _check_segments(observations, segments, t0)
    prob = _Problem(system, observations, unknowns, system.initial_state(z0).copy(), t0, int(segments),
                    float(rtol), float(atol), float(continuity_weight), solver)
    try:
        res, r, J = _minimise(prob, *_start(prob, unknowns), int(max_nfev))
    except ParametricSolveFailed as exc:
        raise AtlasError(f"shooting cannot integrate system {system.name!r} {exc}") from None
    # the values no unknown can change (at t0, of known components) count neither in s² nor in its dof
    fixed = fixed_values(observations, unknowns, t0).reshape(-1)
    informs = np.concatenate([~fixed, np.ones(r.size - fixed.size, bool)])
    n_data, n_user, rss = int(observations.n_values - fixed.sum()), len(unknowns), float(r[informs] @ r[informs])
    cov, cond, weak = gauss_newton_covariance(J, rss, n_data - n_user)
    notes = [f"{unknowns[j].name} is not identifiable from these data (condition number {cond:.3g})"
             for j in weak if j < n_user]
    if any(j >= n_user for j in weak):
        notes.append(f"some segment start states are not identifiable (condition number {cond:.3g})")
    return flag_misfit(FitResult(
        names=tuple(u.name for u in unknowns), estimate=np.asarray(res.x[:n_user], np.float64),
        std=np.sqrt(np.diag(cov)[:n_user]), covariance=cov[:n_user, :n_user],
        noise_estimate=float(math.sqrt(rss / (n_data - n_user))),
        residual_rms=float(np.sqrt(np.mean(r[:observations.n_values] ** 2))), wall_time=time.perf_counter() - start,
        n_rhs=prob.n_rhs, n_solves=prob.n_solves,
        method=("shooting" if segments == 1 else f"multiple shooting ({segments} segments)") + (" (auto)" if auto else ""),
        success=bool(res.success), message=" ".join(str(res.message).split()), identifiable=not weak,
        notes=notes, t0=t0, n_data=n_data, segments=int(segments), cond=cond,
    ), observations)


def check_shooting_inputs(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown], *,
                          t0: float = 0.0, segments: int | str = 1) -> tuple[Unknown, ...]:
    """Refuse, as one line, what no shooting fit of these inputs could run with: observed names or
    unknowns the system lacks, observations before t0, more unknowns than data that depend on them
    (:func:`~atlasnn.observations.fixed_values`), more segments than
    the observation times allow. Returns the unknowns as a tuple."""
    observations.indices(system.state_names)
    observations.check_interval(float(t0), float(observations.t[-1]))
    unknowns = check_unknowns(unknowns, system.state_names, system.param_names, observations.n_values,
                              observations=observations, t0=float(t0))
    if not (isinstance(segments, str) and segments == "auto"):
        _check_segments(observations, int(segments), float(t0))
    return unknowns


def shooting_misfit(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown],
                    values: Any, z0: Any = None, *, t0: float = 0.0, rtol: float = 1e-10, atol: float = 1e-10,
                    solver: str = "gauss") -> float:
    """Σ (model(t_i) − obs_i)² with the unknowns set to ``values`` (one solve from t0, as single
    shooting sees it); inf when the orbit cannot be integrated to the last observation."""
    unknowns = check_unknowns(unknowns, system.state_names, system.param_names, observations.n_values)
    _check_solver(solver)
    prob = _Problem(system, observations, unknowns, system.initial_state(z0).copy(), float(t0), 1, rtol, atol, 1.0,
                    solver)
    try:
        Z = prob.trajectory(np.asarray(values, np.float64), observations.t)
    except ParametricSolveFailed:
        return math.inf
    r = Z[:, prob.idx] - observations.values
    return float(r.ravel() @ r.ravel()) if np.all(np.isfinite(r)) else math.inf


def _check_options(system, observations, t0, rtol, atol, continuity_weight, segments, max_nfev) -> None:
    if not isinstance(system, HamiltonianSystem):
        raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    system.require_parametric("parameter identification")
    if not isinstance(observations, Observations):
        raise ConfigError(f"observations must be an Observations, got {type(observations).__name__}")
    finite_number(t0, "t0")
    for name, val in (("rtol", rtol), ("atol", atol), ("continuity_weight", continuity_weight)):
        if finite_number(val, name) <= 0:
            raise ConfigError(f"{name} must be a positive number, got {val!r}")
    for name, val in (("segments", segments), ("max_nfev", max_nfev)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
            raise ConfigError(f"{name} must be a positive integer, got {val!r}")


def _check_solver(solver) -> None:
    if not isinstance(solver, str) or solver not in PARAMETRIC_SOLVERS:
        raise ConfigError(f"solver must be one of {list(PARAMETRIC_SOLVERS)}, got {solver!r}")


def _minimise(prob: _Problem, x0, lo, hi, max_nfev: int):
    """(least_squares result, residuals, Jacobian at its optimum)."""
    def fun(x):
        try:
            return prob.evaluate(x)[0]
        except ParametricSolveFailed:
            return np.full(prob.n_res, np.nan)  # least_squares shrinks its step on a non-finite residual

    try:
        r0 = prob.evaluate(x0)[0]
    except ParametricSolveFailed as exc:
        raise ParametricSolveFailed(f"at the initial guess: {exc}") from None
    if not np.all(np.isfinite(r0)):
        raise ParametricSolveFailed("at the initial guess: the residuals are not finite")
    # multiple shooting: first with gaps weighted as data (the path may leave the continuous
    # trajectories and so pass the local minima of single shooting), then with the full weight
    ladder = [1.0, prob.w] if len(prob.rows) > 1 and prob.w > 1.0 else [prob.w]
    for w in ladder:
        prob.w, prob.memo = w, None
        res = least_squares(fun, x0, jac=lambda x: prob.evaluate(x)[1], bounds=(lo, hi), method="trf",
                            x_scale="jac", max_nfev=max_nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10)
        x0 = np.clip(res.x, lo, hi)
    try:
        r, J = prob.evaluate(res.x)
    except ParametricSolveFailed as exc:
        raise ParametricSolveFailed(f"at the optimum: {exc}") from None
    return res, r, J


def _check_segments(obs: Observations, segments: int, t0: float) -> None:
    if obs.count < 2 * segments:
        raise ConfigError(f"segments={segments} needs at least {2 * segments} observation times, got {obs.count}")
    starts = [t0] + [float(b[0]) for b in np.array_split(obs.t, segments)[1:]]
    if segments > 1 and not np.all(np.diff(starts) > 0):
        raise ConfigError(f"segments={segments}: segment start times {starts} are not strictly increasing "
                          "(repeated observation times at a boundary)")


def _start(prob: _Problem, unknowns: tuple[Unknown, ...]):
    """x0 and bounds: the guesses, then (multiple shooting) the segments' start states."""
    x0 = np.array([u.guess for u in unknowns], np.float64)
    lo = np.array([u.low for u in unknowns], np.float64)
    hi = np.array([u.high for u in unknowns], np.float64)
    if len(prob.rows) > 1:
        Z = _segment_starts(prob, x0)
        x0 = np.concatenate([x0, Z.reshape(-1)])
        lo = np.concatenate([lo, np.full(Z.size, -np.inf)])
        hi = np.concatenate([hi, np.full(Z.size, np.inf)])
    return x0, lo, hi


def _segment_starts(prob: _Problem, x0: np.ndarray) -> np.ndarray:
    """The segments' start states at the guess, reset to the data as they go: segment k starts at
    its first observation, so its observed components start at that observation and the others
    where the guess's orbit from the previous start (itself so reset) arrives. An orbit that
    escapes from the guess over the whole record stays near the data this way; a piece that cannot
    be integrated keeps the previous start's unobserved components."""
    theta, z = prob.theta_z0(x0)
    out = []
    for k in range(1, len(prob.rows)):
        try:
            z = prob.system_solve(theta, z, prob.starts[k - 1], prob.starts[k])
        except ParametricSolveFailed:
            z = z.copy()
        z[prob.idx] = prob.obs.values[prob.rows[k][0]]
        out.append(z)
    return np.asarray(out)


def auto_segments(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown], z0: Any = None,
                  *, t0: float = 0.0) -> int:
    """Segments of ``segments="auto"``: about three per 1/‖A‖ of the record (A the field's
    Jacobian at z0, its largest norm over the unknowns' guesses and bounds), at most one per
    three observations."""
    norm = field_scale(system, unknowns, system.initial_state(z0))
    span = float(observations.t[-1]) - float(t0)
    wanted = math.ceil(span * norm / 3.0) if math.isfinite(norm) and norm > 0 else 1
    return int(max(1, min(wanted, observations.count // 3)))


# -------------------------------------------------------------------------------- predict
def predict_fit(system: HamiltonianSystem, fit: FitResult, z0: Any, t: Any, *, solver: str = "gauss") -> np.ndarray:
    """The fitted trajectory at the times ``t`` (sorted, ≥ ``fit.t0``): ``solver`` (``"gauss"``
    or ``"dop853"``) at rtol = atol = 1e-12 from ``z0`` (``None``: the system's) with the fitted
    unknowns put in; shape (len(t), 2d)."""
    if not isinstance(fit, FitResult):
        raise ConfigError(f"fit must be a FitResult, got {type(fit).__name__}")
    system.require_parametric("predict_fit")
    _check_solver(solver)
    try:
        times = np.asarray(t, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError("t must be a 1-D array of numbers") from None
    if times.size == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) < 0):
        raise ConfigError(f"t must be a non-empty, finite, sorted array of times (got {times.size} entries)")
    if times[0] < fit.t0:
        raise ConfigError(f"t starts at {float(times[0])!r}, before the fit's t0={fit.t0!r}")
    unknowns = tuple(Unknown(n, v, v - 1.0, v + 1.0) for n, v in zip(fit.names, fit.estimate))
    check_unknowns(unknowns, system.state_names, system.param_names, len(unknowns) + 1)
    theta, z = system.param_vector(), system.initial_state(z0).copy()
    pn, sn = list(system.param_names), list(system.state_names)
    for u in unknowns:
        if u.is_initial_state:
            z[sn.index(u.component)] = u.guess
        else:
            theta[pn.index(u.name)] = u.guess
    try:
        return parametric_solver(system, 1e-12, 1e-12, solver)(z, theta, fit.t0, times)[0]
    except ParametricSolveFailed as exc:
        raise AtlasError(f"predict_fit: cannot integrate system {system.name!r}: {exc}") from None

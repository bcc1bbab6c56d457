"""The simultaneous collocation fit: parameters and trajectory found together, no orbit integrated.

Shooting integrates an orbit from every trial parameter; from a bad start that orbit wanders into
a false minimum of the misfit or escapes before the last observation (docs/FAMILIES.md measures
both). :func:`fit_collocation` never integrates one. The record [t0, t_last] is cut into K equal
windows, and in each the trajectory is the collocation solver's trial solution
(:mod:`atlasnn.solver`): ẑ_k(s) = z_k + s·W_k φ(s/h) with fixed random tanh features φ. Unknowns:
the parameters θ, every window's start state z_k (z_0's unknown components only) and its output
weights W_k. Residuals, all at once:

* Hamilton's equations at P Chebyshev–Lobatto nodes of every window, dẑ/ds − J∇H(ẑ; θ),
* continuity, ẑ_k(h) − z_{k+1},
* the data, ẑ(t_i)[observed] − y_i,

the first two weighted by a penalty μ (relative to the data's scale), which is raised 1e3 → 1e6
(each stage starting from the last): at a small μ the trajectory may bend towards the data while
θ moves, which is what lets the fit cross the misfit's false minima; at a large one it obeys the
equations to far below the noise. The trajectory starts from a spline through the data (the
unobserved components at their initial value), so it begins near the data whatever θ is.

The Jacobian is block-banded (a window's residuals see its own unknowns, the next start and θ), so
Levenberg–Marquardt solves its damped normal equations with a sparse LU (SciPy's SuperLU): a dense
solve over the 10³–10⁴ unknowns would cost seconds per step. Optimistix's LM works on dense
operators only, hence the hand-written loop.

The estimate is then polished by single shooting started from it (:func:`fit_shooting`), which gives
the least-squares estimate of the record and its Gauss–Newton σ exactly. If that orbit cannot be
integrated, the collocation estimate stays, with σ from the penalised problem's own covariance, and a
note says so.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Any, ClassVar, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.interpolate import CubicSpline

from atlasnn.compile_cache import program_cache
from atlasnn.errors import AtlasError, ConfigError
from atlasnn.inverse._base import AbstractFitMethod
from atlasnn.inverse._field import field_scale
from atlasnn.inverse._orbits import PARAMETRIC_SOLVERS
from atlasnn.inverse._fit_result import FitResult, distrust, flag_misfit
from atlasnn.inverse._shooting import check_shooting_inputs, fit_shooting
from atlasnn.observations import INITIAL_STATE_PREFIX, Observations, Unknown, fixed_values
from atlasnn.solver import RandomFeatures, collocation_nodes, require_float64
from atlasnn.systems import HamiltonianSystem, parametric_field

__all__ = ["CollocationFit", "fit_collocation"]


@dataclasses.dataclass(frozen=True)
class CollocationFit(AbstractFitMethod):
    """The simultaneous collocation fit as a method object (for [`atlasnn.inverse.fit`][atlasnn.inverse.fit]), and
    the settings of ``fit_collocation``.

    Attributes:
        windows: windows over the record, or ``"auto"``: length 1/‖A‖ (A = D(J∇H) at z0 and the
            guess), at least 2 and at most one per observation.
        features: random tanh features per window (M).
        points: collocation nodes per window (default M + 8).
        scale: the features' slopes are uniform in ±scale on normalised window time.
        penalties: the penalty weights μ of the stages, increasing.
        max_steps: Levenberg–Marquardt steps per stage at most.
        seed: the draw of the features.
        polish: finish with single shooting from the estimate (exact least squares and σ).
        polish_solver: the orbit's solve in that shooting (``fit_shooting``'s ``solver``:
            ``"gauss"`` or ``"dop853"``).
    """

    windows: int | str = "auto"
    features: int = 16
    points: int | None = None
    scale: float = 4.0
    penalties: tuple[float, ...] = (1e3, 1e4, 1e5, 1e6)
    max_steps: int = 200
    seed: int = 0
    polish: bool = True
    polish_solver: str = "gauss"
    name: ClassVar[str] = "collocation"

    def fit(self, system, observations, unknowns, *, z0=None, t0=0.0, seed=0):
        return fit_collocation(system, observations, unknowns, z0, t0=t0, config=dataclasses.replace(self, seed=seed))

    def describe(self, unknowns):
        return "simultaneous collocation of trajectory and parameters, then shooting from it"

    def __post_init__(self):
        if self.windows != "auto" and (isinstance(self.windows, bool) or not isinstance(self.windows, int)
                                       or self.windows < 1):
            raise ConfigError(f"collocation fit: windows must be a positive integer or \"auto\", got {self.windows!r}")
        for name in ("features", "max_steps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"collocation fit: {name} must be a positive integer, got {v!r}")
        if self.points is not None and (not isinstance(self.points, int) or self.points < self.features):
            raise ConfigError(f"collocation fit: points must be an integer ≥ features ({self.features}), "
                              f"got {self.points!r}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ConfigError(f"collocation fit: scale must be a positive number, got {self.scale!r}")
        if self.polish_solver not in PARAMETRIC_SOLVERS:
            raise ConfigError(f"collocation fit: polish_solver must be one of {list(PARAMETRIC_SOLVERS)}, "
                              f"got {self.polish_solver!r}")
        mus = tuple(self.penalties)
        if not mus or any(not (math.isfinite(m) and m > 0) for m in mus) or list(mus) != sorted(mus):
            raise ConfigError(f"collocation fit: penalties must be positive and increasing, got {self.penalties!r}")


class _Layout(NamedTuple):
    """The fixed arrays of one problem (traced by the compiled residual)."""

    theta: jax.Array  # θ with the system's values (unknown entries replaced per call)
    q: jax.Array  # orthonormal rate basis at the nodes (P, M)
    c: jax.Array  # value basis at the nodes in that basis (P, M)
    rinv: jax.Array  # R⁻¹ of the rate basis' QR (M, M)
    a: jax.Array
    b: jax.Array  # the features
    h: jax.Array
    scale: jax.Array  # the data's scale S


class _WindowData(NamedTuple):
    """The data of each window (a leading window axis)."""

    tau: jax.Array  # normalised observation times (K, D)
    y: jax.Array  # observed values (K, D, C)
    mask: jax.Array  # 1 where a slot holds an observation (K, D)
    last: jax.Array  # 1 in the last window (no continuity row)


@program_cache
@functools.lru_cache(maxsize=16)
def _programs(system: HamiltonianSystem, param_index: tuple[int, ...], observed: tuple[int, ...]):
    """Compiled (residuals, Jacobian blocks) over all windows for a system, its unknown parameters
    and observed components; the rest (shapes aside) are arguments."""
    field = parametric_field(system)
    pidx = jnp.asarray(param_index, dtype=jnp.int32)
    obs = jnp.asarray(observed, dtype=jnp.int32)

    def window(x, z_next, unknown, lay: _Layout, data: _WindowData, mu):
        tau, y, mask, last = data
        n = z_next.shape[0]
        z, w = x[:n], x[n:].reshape(n, -1)
        theta = lay.theta.at[pidx].set(unknown)
        zz = z + lay.c @ w.T
        physics = (lay.q @ w.T - jax.vmap(field, (0, None))(zz, theta)) * (mu / lay.scale / math.sqrt(lay.q.shape[0]))
        gap = (1.0 - last) * (mu / lay.scale) * (zz[-1] - z_next)
        phi = jnp.tanh(tau[:, None] * lay.a + lay.b)
        zd = z + ((lay.h * tau)[:, None] * phi) @ lay.rinv @ w.T
        misfit = mask[:, None] * (zd[:, obs] - y) / lay.scale
        return jnp.concatenate([physics.reshape(-1), gap, misfit.reshape(-1)])

    axes = (0, 0, None, None, 0, None)
    res = jax.jit(jax.vmap(window, axes))
    jac = jax.jit(jax.vmap(jax.jacfwd(window, argnums=(0, 2)), axes))
    return res, jac


class _Problem:
    """One fit's layout: the windows, the data in them, the unknowns' places, the sparse pattern."""

    def __init__(self, system, observations, unknowns, z0, t0, cfg: CollocationFit, windows: int):
        n, m = system.state_dim, cfg.features
        self.n, self.m, self.k = n, m, windows
        self.params = [u for u in unknowns if not u.name.startswith(INITIAL_STATE_PREFIX)]
        self.states = [u for u in unknowns if u.name.startswith(INITIAL_STATE_PREFIX)]
        self.unknowns = unknowns
        pidx = tuple(system.param_names.index(u.name) for u in self.params)
        self.sidx = [system.state_names.index(u.name[len(INITIAL_STATE_PREFIX):]) for u in self.states]
        observed = tuple(observations.indices(system.state_names))
        self.residuals, self.blocks = _programs(system, pidx, observed)
        t_last = float(observations.t[-1])
        h = (t_last - t0) / windows
        feats = RandomFeatures.draw(m, cfg.scale, cfg.seed)
        tau = collocation_nodes(cfg.points or m + 8)
        phi = np.tanh(tau[:, None] * feats.a + feats.b)
        values, rates = h * tau[:, None] * phi, phi + tau[:, None] * (1.0 - phi ** 2) * feats.a
        q, r = np.linalg.qr(rates)
        rinv = np.linalg.inv(r)
        slot = np.minimum(((observations.t - t0) / h).astype(int), windows - 1)
        depth = max(1, int(np.bincount(slot, minlength=windows).max()))
        tau_d, y_d, mask = np.zeros((windows, depth)), np.zeros((windows, depth, len(observed))), np.zeros((windows, depth))
        fill = np.zeros(windows, int)
        for i, k in enumerate(slot):
            tau_d[k, fill[k]] = (observations.t[i] - (t0 + k * h)) / h
            y_d[k, fill[k]], mask[k, fill[k]] = observations.values[i], 1.0
            fill[k] += 1
        last = np.zeros(windows)
        last[-1] = 1.0
        self.scale = float(np.sqrt(np.mean(observations.values ** 2))) or 1.0
        self.layout = _Layout(jnp.asarray(system.param_vector()), jnp.asarray(q), jnp.asarray(values @ rinv),
                              jnp.asarray(rinv), jnp.asarray(feats.a), jnp.asarray(feats.b), jnp.asarray(h),
                              jnp.asarray(self.scale))
        self.data = _WindowData(jnp.asarray(tau_d), jnp.asarray(y_d), jnp.asarray(mask), jnp.asarray(last))
        self.t0, self.h, self.nodes, self.q = t0, h, tau, q
        self._pattern(len(tau), depth * len(observed))
        self.x0 = self._start(system, observations, z0)

    @property
    def width(self) -> int:
        return self.n * (1 + self.m)

    def _pattern(self, points: int, data_rows: int) -> None:
        """Row and column indices of the Jacobian's nonzeros, in the order :meth:`jacobian` fills them."""
        k, n, p, w = self.k, self.n, len(self.params), self.width
        rows = points * n + n + data_rows
        r = np.arange(k)[:, None, None] * rows + np.arange(rows)[None, :, None]
        own = (np.broadcast_to(r, (k, rows, w)), np.broadcast_to(p + np.arange(k)[:, None, None] * w + np.arange(w), (k, rows, w)))
        par = (np.broadcast_to(r, (k, rows, p)), np.broadcast_to(np.arange(p), (k, rows, p)))
        gap_r = (np.arange(k - 1)[:, None] * rows + points * n + np.arange(n)).ravel()
        gap_c = (p + (np.arange(1, k)[:, None]) * w + np.arange(n)).ravel()
        self.rows_total, self.cols_total = k * rows, p + k * w
        self.pattern = (np.concatenate([own[0].ravel(), par[0].ravel(), gap_r]),
                        np.concatenate([own[1].ravel(), par[1].ravel(), gap_c]))
        fixed = [p + j for j in range(n) if j not in self.sidx]  # z_0's known components
        self.free = np.setdiff1d(np.arange(self.cols_total), fixed)

    def _start(self, system, observations, z0) -> np.ndarray:
        """θ at the guesses; the states and rates of a cubic spline through the data (and through
        the initial value at t0 when the data start later; unobserved components held at their
        initial value); z_0 the known initial state (its unknown components at their guesses)."""
        x = np.zeros(self.cols_total)
        x[:len(self.params)] = [u.guess for u in self.params]
        block = x[len(self.params):].reshape(self.k, self.width)
        starts = self.t0 + self.h * np.arange(self.k)
        block[:, :self.n] = z0
        for u, j in zip(self.states, self.sidx):
            block[:, j] = u.guess
        for col, j in enumerate(observations.indices(system.state_names)):
            # repeated times (replicate measurements) enter the spline once, as their mean
            t, which = np.unique(observations.t, return_inverse=True)
            v = np.bincount(which, weights=observations.values[:, col]) / np.bincount(which)
            if t[0] > self.t0:  # anchored at the initial value, not extrapolated back to t0
                t, v = np.concatenate([[self.t0], t]), np.concatenate([[block[0, j]], v])
            if t.size < 2:  # every value at t0: the component starts held at it
                continue
            spline = CubicSpline(t, v)
            block[1:, j] = spline(starts[1:])
            rates = spline(starts[:, None] + self.h * self.nodes[None, :], 1)  # (K, P)
            for k in range(self.k):  # a row of block is contiguous: its reshape is a view
                block[k, self.n:].reshape(self.n, self.m)[j] = rates[k] @ self.q
        return x

    def split(self, x):
        p = len(self.params)
        block = jnp.asarray(x[p:].reshape(self.k, self.width))
        nxt = jnp.concatenate([block[1:, :self.n], block[-1:, :self.n]])
        return block, nxt, jnp.asarray(x[:p])

    def residual(self, x, mu) -> np.ndarray:
        block, nxt, unknown = self.split(x)
        return np.asarray(self.residuals(block, nxt, unknown, self.layout, self.data, mu)).ravel()

    def jacobian(self, x, mu) -> sparse.csc_matrix:
        block, nxt, unknown = self.split(x)
        own, par = self.blocks(block, nxt, unknown, self.layout, self.data, mu)
        gap = np.full((self.k - 1) * self.n, -mu / self.scale)
        values = np.concatenate([np.asarray(own).ravel(), np.asarray(par).ravel(), gap])
        full = sparse.csc_matrix((values, self.pattern), shape=(self.rows_total, self.cols_total))
        return full[:, self.free]

    def clip(self, x) -> np.ndarray:
        """The unknowns kept inside their bounds."""
        p = len(self.params)
        for i, u in enumerate(self.params):
            x[i] = min(max(x[i], u.low), u.high)
        for u, j in zip(self.states, self.sidx):
            x[p + j] = min(max(x[p + j], u.low), u.high)
        return x

    def estimate(self, x) -> np.ndarray:
        p = len(self.params)
        values = {u.name: x[i] for i, u in enumerate(self.params)}
        values.update({u.name: x[p + j] for u, j in zip(self.states, self.sidx)})
        return np.array([values[u.name] for u in self.unknowns])


def _levenberg_marquardt(prob: _Problem, x: np.ndarray, mu: float, max_steps: int) -> tuple[np.ndarray, int]:
    """Minimise ‖r(x; μ)‖² from x: damped Gauss–Newton steps (Marquardt's diagonal scaling) solved
    by sparse LU, the unknowns clipped to their bounds; (x, steps taken)."""
    r = prob.residual(x, mu)
    cost, damping, steps = float(r @ r), 1e-3, 0
    for steps in range(1, max_steps + 1):
        J = prob.jacobian(x, mu)
        A, g = (J.T @ J).tocsc(), J.T @ r
        diag = A.diagonal() + 1e-12 * A.diagonal().max()
        while True:
            step = sparse_linalg.spsolve(A + damping * sparse.diags(diag, format="csc"), -g)
            trial = x.copy()
            trial[prob.free] += step
            trial = prob.clip(trial)
            r_new = prob.residual(trial, mu)
            new = float(r_new @ r_new)
            if math.isfinite(new) and new < cost:
                damping = max(damping / 3.0, 1e-12)
                break
            damping *= 4.0
            if damping > 1e12:
                return x, steps
        gain = (cost - new) / cost
        x, r, cost = trial, r_new, new
        if gain < 1e-10:
            break
    return x, steps


def _auto_windows(system, unknowns, z0, span: float, n_obs: int) -> int:
    """Windows of length 1/‖A‖ (:func:`field_scale`: the largest over the unknowns' guesses and
    bounds, so the windows do not depend on the guess); at least 2, at most one per observation."""
    norm = field_scale(system, unknowns, z0)
    length = 1.0 / norm if math.isfinite(norm) and norm > 0 else span
    return int(min(max(2, math.ceil(span / length)), max(2, n_obs)))


def _own_covariance(prob: _Problem, x, mu, n_data: int):
    """σ of the unknowns from the penalised problem's Gauss–Newton matrix at its last stage:
    the block of (JᵀJ)⁻¹ of the unknowns, times the data's residual variance."""
    J = prob.jacobian(x, mu)
    r = prob.residual(x, mu)
    data_rss = float(np.sum(r[_data_rows(prob)] ** 2)) * prob.scale ** 2
    p, cols = len(prob.unknowns), []
    for u in prob.unknowns:
        if u.name.startswith(INITIAL_STATE_PREFIX):
            j = prob.sidx[prob.states.index(u)]
            cols.append(int(np.searchsorted(prob.free, len(prob.params) + j)))
        else:
            cols.append(prob.params.index(u))
    lu = sparse_linalg.splu((J.T @ J).tocsc())
    unit = np.zeros((J.shape[1], p))
    unit[cols, np.arange(p)] = 1.0
    block = lu.solve(unit)[cols] / prob.scale ** 2
    s2 = data_rss / (n_data - p)  # n_data > p: check_shooting_inputs
    return s2 * block, math.sqrt(s2)


def _data_rows(prob: _Problem) -> np.ndarray:
    rows = prob.rows_total // prob.k
    data = rows - (len(prob.nodes) * prob.n + prob.n)
    return (np.arange(prob.k)[:, None] * rows + (rows - data) + np.arange(data)).ravel()


def fit_collocation(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown],
                    z0: Any = None, *, t0: float = 0.0, config: CollocationFit | None = None) -> FitResult:
    """Fit unknown parameters of H (and initial-state components) to observations by the
    simultaneous collocation fit of the module docstring, then polish by shooting.

    Raises:
        ConfigError: bad observations, unknowns or settings (as :func:`fit_shooting`).
        SystemError_: the system has no ``parametric`` H or no parameters.
    """
    tic = time.perf_counter()
    cfg = config or CollocationFit()
    system.require_parametric("the collocation fit")
    unknowns = check_shooting_inputs(system, observations, unknowns, t0=float(t0))
    require_float64()
    with jax.enable_x64(True):
        state = np.asarray(system.initial_state(z0), np.float64).copy()
        span = float(observations.t[-1]) - float(t0)
        windows = cfg.windows if cfg.windows != "auto" else _auto_windows(system, unknowns, state, span,
                                                                        observations.t.size)
        prob = _Problem(system, observations, tuple(unknowns), state, float(t0), cfg, windows)
        x, steps = prob.x0, []
        for mu in cfg.penalties:
            x, taken = _levenberg_marquardt(prob, x, mu, cfg.max_steps)
            steps.append(taken)
        estimate = prob.estimate(x)
        search = {"collocation_estimate": estimate.tolist(), "windows": windows, "features": cfg.features,
                  "lm_steps": steps}
        polished = (_polish(system, observations, unknowns, estimate, z0, float(t0), search, cfg.polish_solver)
                    if cfg.polish else None)
        if polished is None:
            n_data = int(observations.n_values - fixed_values(observations, unknowns, float(t0)).sum())
            cov, noise = _own_covariance(prob, x, cfg.penalties[-1], n_data)
            fit = FitResult(names=tuple(u.name for u in unknowns), estimate=estimate,
                            std=np.sqrt(np.abs(np.diag(cov))), covariance=cov, noise_estimate=noise,
                            residual_rms=noise, wall_time=0.0, n_rhs=0, n_solves=0, method="collocation",
                            success=bool(np.all(np.isfinite(estimate))), message="collocation fit (not polished)",
                            identifiable=True, t0=float(t0), n_data=n_data)
            if cfg.polish:
                fit.notes.append(f"not polished by shooting ({search['polish']}): σ from the collocation problem")
            fit = flag_misfit(fit, observations)
        else:
            fit = polished
        fit.search = {**fit.search, **search}
        fit.wall_time = time.perf_counter() - tic
    return fit


def _polish(system, observations, unknowns, estimate, z0, t0, search, solver) -> FitResult | None:
    """Single shooting from the collocation estimate (None, and the reason in ``search``, where
    the orbit cannot be integrated)."""
    start = [dataclasses.replace(u, guess=float(v)) for u, v in zip(unknowns, estimate)]
    try:
        fit = fit_shooting(system, observations, start, z0, t0=t0, solver=solver)
    except ConfigError:
        raise
    except AtlasError as exc:
        search["polish"] = str(exc)
        return None
    moved = np.abs(fit.estimate - estimate) / np.where(fit.std > 0, fit.std, np.inf)
    search["polish_moved_sigmas"] = float(np.max(moved)) if moved.size else 0.0
    search["polish_seconds"] = fit.wall_time
    fit.method = "collocation"
    if search["polish_moved_sigmas"] > 10.0:
        distrust(fit, f"shooting moved the collocation estimate by {search['polish_moved_sigmas']:.3g}σ while "
                      "polishing it: the collocation problem was not solved to the data's accuracy; raise "
                      "windows or features")
    return fit

"""Parameter identification by one network trained on the data and Hamilton's equations together.

The unknowns φ (parameters of H, initial-state components) are mapped from free variables u by
φ = low + (high − low)·sigmoid(u), so they stay within their bounds. The trial solution is the
library's, with the initial state made of the known and the unknown components:

    ẑ(t) = z0(φ) + f(t − t0; γ) N(t; θ),

and the least-squares objective stacks three kinds of residuals:

    physics  r(t_k) = dẑ/dt − J∇H(ẑ; θ_H(φ))          at K collocation times (weight 1/√K),
    energy   √λ_reg (H(ẑ(t_k)) − H(z0(φ)))            (weight 1/√K),
    data     w (ẑ_c(t_i) − y_i) / s_y                  at the M observations (weight 1/√M),

s_y the RMS of the observations. A small data weight w (default 0.01) keeps the trajectory on
Hamilton's equations and lets the data choose φ, rather than letting the network bend to the noise.
Adam (collocation times drawn afresh every epoch) is followed by Levenberg–Marquardt on fixed
Chebyshev times (:func:`atlasnn.training.lm_minimise`).

The uncertainty is a Gauss–Newton estimate at the optimum from the network alone: the network's
tangent to the solution manifold, S = −J_{P,θ}⁺ J_{P,u} (its change with u that keeps the physics
residuals fixed, minimum-norm), gives the data's effective sensitivity G = J_{D,u} + J_{D,θ} S, and
Cov(u) = s² (GᵀG)⁻¹ with s² = RSS/(n_data − n_unknowns); φ's covariance by the chain rule. (The
plain Laplace covariance of all of (θ, u) is useless here: an over-parameterised network fits any
u at finitely many points, so its marginal for u is unbounded.)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree

from atlasnn.errors import ConfigError
from atlasnn.inverse._fit_result import FitResult, flag_misfit, gauss_newton_covariance
from atlasnn.nn import make_model
from atlasnn.observations import Observations, Unknown, check_unknowns, fixed_values
from atlasnn.systems import HamiltonianSystem
from atlasnn.training import LMConfig, lm_minimise, trainable_filter

__all__ = ["JointConfig", "fit_joint"]


@dataclass(frozen=True)
class JointConfig:
    """Settings of ``fit_joint``: the network (``width``, ``depth``, ``scaling``), Adam
    (``epochs``, ``lr``, ``batch`` collocation times per epoch), LM (``lm_steps``, ``lm_points``
    Chebyshev times), ``lam_reg`` and the data weight ``data_weight`` (module docstring)."""

    width: int = 48
    depth: int = 2
    scaling: str = "rational_exp"
    epochs: int = 3000
    lr: float = 2e-3
    batch: int = 128
    lm_steps: int = 300
    lm_points: int = 96
    lam_reg: float = 1.0
    data_weight: float = 0.01

    def __post_init__(self) -> None:
        for name, low in (("width", 1), ("depth", 1), ("epochs", 0), ("batch", 2), ("lm_steps", 0),
                          ("lm_points", 2)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ConfigError(f"inverse {name} must be an integer >= {low}, got {v!r}")
        for name in ("lr", "lam_reg", "data_weight"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ConfigError(f"inverse {name} must be a finite number > 0, got {v!r}")


class _Problem:
    """The residuals of one fit, as functions of the flat vector x = (θ of the network, u)."""

    def __init__(self, system, obs: Observations, unknowns: tuple[Unknown, ...], z0, t0: float, T: float,
                 cfg: JointConfig, seed: int):
        self.system, self.obs, self.unknowns, self.cfg = system, obs, unknowns, cfg
        self.t0, self.T = t0, T
        self.low = np.asarray([u.low for u in unknowns])
        self.high = np.asarray([u.high for u in unknowns])
        guess = (np.asarray([u.guess for u in unknowns]) - self.low) / (self.high - self.low)
        guess = np.clip(guess, 1e-6, 1 - 1e-6)
        self.u0 = np.log(guess / (1 - guess))
        self.z0_base = np.asarray(z0, np.float64)
        self.theta_base = system.param_vector()
        self.p_idx = [(j, system.param_names.index(u.name)) for j, u in enumerate(unknowns) if not u.is_initial_state]
        self.z_idx = [(j, system.state_names.index(u.component)) for j, u in enumerate(unknowns) if u.is_initial_state]
        self.cols = obs.indices(system.state_names)
        self.scale_y = float(np.sqrt(np.mean(obs.values**2))) or 1.0
        model = make_model(self._z0_of(self.u0), scaling=cfg.scaling, width=cfg.width, depth=cfg.depth,
                           t0=t0, seed=seed)
        params, self.rest = eqx.partition(model, trainable_filter(model, freeze_gamma=False))
        self.x_net, self.unravel = ravel_pytree(params)
        self.n_net = int(self.x_net.size)

    def phi(self, u):
        if isinstance(u, jax.Array):
            low, high = jnp.asarray(self.low, u.dtype), jnp.asarray(self.high, u.dtype)
            return low + (high - low) * jax.nn.sigmoid(u)
        return self.low + (self.high - self.low) / (1 + np.exp(-u))

    def _z0_of(self, u):
        z0 = np.array(self.z0_base)
        phi = self.phi(np.asarray(u))
        for j, i in self.z_idx:
            z0[i] = phi[j]
        return z0

    def split(self, x):
        return x[: self.n_net], x[self.n_net :]

    def parts(self, x, t_col):
        """(physics residuals (K, 2d + 1), data residuals (M, C)) at collocation times t_col."""
        xn, u = self.split(x)
        phi = self.phi(u)
        dtype = xn.dtype
        theta = jnp.asarray(self.theta_base, dtype)
        z0 = jnp.asarray(self.z0_base, dtype)
        for j, i in self.p_idx:
            theta = theta.at[i].set(phi[j])
        for j, i in self.z_idx:
            z0 = z0.at[i].set(phi[j])
        model = eqx.combine(self.unravel(xn), self.rest)
        shift = z0 - jax.lax.stop_gradient(model.z0)
        z, dz = model.value_and_rate(t_col)
        z = z + shift
        th = jnp.broadcast_to(theta, (z.shape[0], theta.size))
        energy, vf = self.system.field_at(z, th)
        e0 = self.system.energy_at(z0[None], th[:1])[0]
        phys = jnp.concatenate([dz - vf, math.sqrt(self.cfg.lam_reg) * (energy - e0)[:, None]], axis=1)
        zd = model(jnp.asarray(self.obs.t, dtype)) + shift
        data = zd[:, self.cols] - jnp.asarray(self.obs.values, dtype)
        return phys, data

    def residual(self, x, t_col):
        phys, data = self.parts(x, t_col)
        w = self.cfg.data_weight / self.scale_y
        return jnp.concatenate([phys.reshape(-1) / math.sqrt(phys.shape[0]),
                                w * data.reshape(-1) / math.sqrt(data.shape[0])])


def _adam(prob: _Problem, x, seed: int):
    cfg = prob.cfg
    opt = optax.adam(optax.cosine_decay_schedule(cfg.lr, max(cfg.epochs, 1), 0.01))
    key = jax.random.PRNGKey(seed + 31)

    def loss(x, e):
        t = prob.t0 + (prob.T - prob.t0) * jax.random.uniform(jax.random.fold_in(key, e), (cfg.batch,), x.dtype)
        r = prob.residual(x, t)
        return jnp.dot(r, r)

    def step(carry, e):
        x, s = carry
        val, g = jax.value_and_grad(loss)(x, e)
        upd, s = opt.update(g, s, x)
        return (optax.apply_updates(x, upd), s), val

    (x, _), hist = jax.jit(lambda x: jax.lax.scan(step, (x, opt.init(x)), jnp.arange(cfg.epochs)))(x)
    return x, np.asarray(hist)


def _chebyshev(t0: float, T: float, k: int) -> np.ndarray:
    return t0 + (T - t0) * (1 - np.cos(np.pi * np.arange(k) / (k - 1))) / 2


def _uncertainty(prob: _Problem, x, t_col, informs: np.ndarray):
    """(covariance of φ, s, RSS) from the tangent Gauss–Newton estimate (module docstring), over
    the data values ``informs`` marks (those an unknown can change)."""
    jac = jax.jacfwd(lambda v: prob.parts(v, t_col), argnums=0)
    with jax.enable_x64(True):
        x64 = jnp.asarray(np.asarray(x), jnp.float64)
        jp, jd = jac(x64)
        phys, data = prob.parts(x64, jnp.asarray(t_col, jnp.float64))
    jp = np.asarray(jp).reshape(-1, x.size)
    jd = np.asarray(jd).reshape(-1, x.size)
    n = prob.n_net
    tangent = -np.linalg.lstsq(jp[:, :n], jp[:, n:], rcond=1e-10)[0]
    G = (jd[:, n:] + jd[:, :n] @ tangent)[informs]
    d = np.asarray(data).reshape(-1)[informs]
    rss, dof = float(d @ d), d.size - G.shape[1]
    cov_u, cond, weak = gauss_newton_covariance(G, rss, dof)
    u = np.asarray(x[n:], np.float64)
    dphi = (prob.high - prob.low) * np.exp(-u) / (1 + np.exp(-u)) ** 2
    return cov_u * np.outer(dphi, dphi), math.sqrt(rss / dof), rss, cond, weak


def _stop_message(stop: str) -> str:
    if stop == "stalled":  # the damping grew without finding a better step: a minimum to float precision
        return "Levenberg–Marquardt stopped: stalled (no better step at any damping: a minimum)"
    return f"Levenberg–Marquardt stopped: {stop}"


def fit_joint(system: HamiltonianSystem, observations: Observations, unknowns: Sequence[Unknown], z0: Any = None,
              *, t0: float = 0.0, T: float | None = None, config: JointConfig = JointConfig(),
              seed: int = 0) -> FitResult:
    """Fit the unknowns to the observations with one network on [t0, T] (default: the last
    observation time); returns a :class:`~atlasnn.evaluation.FitResult` (method "network (joint)")."""
    start = time.perf_counter()
    system.require_parametric("parameter identification")
    T = float(observations.t[-1]) if T is None else float(T)
    observations.check_interval(float(t0), T)
    unknowns = check_unknowns(unknowns, system.state_names, system.param_names, observations.n_values,
                              observations=observations, t0=float(t0))
    prob = _Problem(system, observations, unknowns, system.initial_state(z0), float(t0), T, config, seed)
    x = jnp.concatenate([prob.x_net, jnp.asarray(prob.u0, prob.x_net.dtype)])
    if config.epochs:
        x, _ = _adam(prob, x, seed)
    t_col = _chebyshev(prob.t0, T, config.lm_points)
    stop = "none"
    if config.lm_steps:
        res = lambda v, t: prob.residual(v, t)  # noqa: E731
        jac = lambda v, t: jax.jacrev(prob.residual)(v, t)  # noqa: E731
        out = lm_minimise(res, jac, x, jnp.asarray(t_col, x.dtype), LMConfig(steps=config.lm_steps, patience=40))
        x, stop = out.x, out.stop_reason
    informs = ~fixed_values(observations, unknowns, float(t0)).reshape(-1)  # the network starts at z0 too
    cov, s, rss, cond, weak = _uncertainty(prob, x, t_col, informs)
    names = tuple(u.name for u in unknowns)
    notes = [f"{names[j]} is not identifiable from these data (condition number {cond:.3g})" for j in weak]
    m = int(informs.sum())
    return flag_misfit(FitResult(names=names, estimate=np.asarray(prob.phi(np.asarray(x[prob.n_net:], np.float64))),
                     std=np.sqrt(np.abs(np.diag(cov))), covariance=cov, noise_estimate=s,
                     residual_rms=math.sqrt(rss / m), wall_time=time.perf_counter() - start, n_rhs=0, n_solves=0,
                     method="network (joint)", success=bool(np.all(np.isfinite(np.asarray(x)))),
                     message=_stop_message(stop), identifiable=not weak, notes=notes, t0=float(t0), n_data=m,
                     cond=cond), observations)

"""A Levenberg–Marquardt (damped Gauss–Newton) phase after Adam, on fixed collocation times.

The physics loss at K fixed times t_1..t_K is a sum of squares,

    L(θ) = ‖R(θ)‖²,   R = (1/√K) · [ r(t_n) ; √λ_reg (H(ẑ(t_n)) − E0) ]_{n=1..K},

r = dẑ/dt − J∇H(ẑ), so that L is the library's physics loss at those times (m = K(2d + 1)
residuals). Each trial solves the damped system (JᵀJ + μD) Δ = −JᵀR, J = ∂R/∂θ, D = diag(JᵀJ)
floored (Marquardt's scaling). With J_s = J D^{-1/2} it is solved in the smaller of its two forms
by Cholesky: (J_s J_sᵀ + μI) y = R, Δ_s = −J_sᵀ y when m ≤ n (the usual case: a 48×2 network has
n ≈ 2.5·10³ parameters, a window a few hundred residuals), else the normal equations. The gain
ratio ρ = actual / predicted decrease decides, by Nielsen's rule: ρ > 0 accepts and sets
μ ← μ·max(1/3, 1 − (2ρ − 1)³); otherwise μ ← μν, ν ← 2ν. μ starts at τ·max diag(J_sᵀJ_s).

Geodesic acceleration (Transtrum & Sethna's second-order correction, on by default): with the
step v, the second directional derivative r_vv = d²/dε² R(θ + εv) (forward over forward mode)
gives an acceleration a from the same damped system and factor; the trial point is θ + v + a/2,
and a trial with 2‖a‖ > 0.75‖v‖ is rejected like one that raised the loss. It gets LM out of the
long curved valleys it otherwise crawls along (measured: one oscillator window stalled at a loss
of 3.8e-7 without it, 2.4e-9 with it; never slower, 2–3× faster on Kepler windows).

J is built point by point: the residuals of time t_n depend on the network at t_n alone, so J is
the stack over n of one point's (2d + 1) × n Jacobian by reverse mode (a ``vmap`` over the K
times), measured faster than ``jacfwd``/``jacrev`` of the whole vector. The loop is one
``lax.while_loop``; the collocation times are an argument, so windows of any length share one
compiled program per shape. ``precision``: ``"model"`` (the network's own float32, the default:
measured the fastest way to a given error, docs/ESTIMATE.md), ``"float64"`` (a float64 copy, the
result cast back: worth it only for errors below ~1e-6, which the float32 solution cannot hold
anyway), or ``"mixed"`` (float64 residuals and solve, float32 Jacobian).

Why: the networks are small and a window has a few hundred residuals, so a Gauss–Newton step is
affordable and reaches losses Adam does not (measured: a pendulum window's max error 4e-6 after
32 000 Adam epochs, 3e-7 after 2 000 Adam epochs and 150 LM trials in 0.8 s).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import program_cache
from atlasnn.precision import on_device, trace_settings
from atlasnn.training._flat import cast_floats, ravel, unravel_on_host
from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.solutions import stack_models, unstack_models
from atlasnn.systems import HamiltonianSystem
from atlasnn.training._loss import energy_and_vector_field
from atlasnn.training._step import compile_training_program, trainable_filter

__all__ = ["LMConfig", "LMResult", "LMOutcome", "levenberg_marquardt", "lm_batch", "lm_minimise", "lm_nodes", "lm_points"]

NODES = ("chebyshev", "uniform")
LM_PRECISIONS = ("model", "float64", "mixed")
_STOP = {1: "tolerance", 2: "no_improvement", 3: "stalled", 4: "budget"}

@dataclass(frozen=True)
class LMConfig:
    """Settings of a Levenberg–Marquardt phase.

    ``steps``: the budget of trials (accepted or rejected); ``n_points`` K (default: by
    :func:`lm_points`, from the window's length and the state's dimension) and ``nodes``
    (``"chebyshev"``: Chebyshev–Lobatto times, clustered at the ends; ``"uniform"``); ``lam_reg``
    as in training; ``freeze_gamma``: γ of the scaling fixed (default) or optimised too;
    ``mu_init`` τ; ``geodesic``/``accel_ratio``: the geodesic acceleration (module docstring);
    ``loss_tol``: stop at L ≤ loss_tol; ``patience`` / ``min_rel_improvement``: stop
    when L has not dropped by that relative amount in that many trials; ``precision``: see the
    module docstring.
    """

    steps: int = 100
    n_points: int | None = None
    nodes: str = "chebyshev"
    lam_reg: float = 1.0
    freeze_gamma: bool = True
    mu_init: float = 1e-3
    geodesic: bool = True
    accel_ratio: float = 0.75
    loss_tol: float = 0.0
    patience: int = 15
    min_rel_improvement: float = 1e-3
    precision: str = "model"
    diag_floor: float = 1e-10

    def __post_init__(self) -> None:
        for name, options in (("nodes", NODES), ("precision", LM_PRECISIONS)):
            if getattr(self, name) not in options:
                raise ConfigError(f"lm.{name} must be one of {list(options)}, got {getattr(self, name)!r}")
        for name, low in (("steps", 1), ("n_points", 2), ("patience", 1)):
            v = getattr(self, name)
            if v is None and name == "n_points":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ConfigError(f"lm.{name} must be an integer >= {low}, got {v!r}")
        for name in ("lam_reg", "mu_init", "loss_tol", "min_rel_improvement", "diag_floor", "accel_ratio"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ConfigError(f"lm.{name} must be a finite number >= 0, got {v!r}")
        for name in ("freeze_gamma", "geodesic"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"lm.{name} must be true or false, got {getattr(self, name)!r}")

    def replace(self, **changes: Any) -> "LMConfig":
        return dataclasses.replace(self, **changes)


class LMState(NamedTuple):
    """The loop's carry (all arrays, so it can be vmapped)."""

    x: jax.Array  # flat trainable parameters
    R: jax.Array  # residual vector at x (m,)
    Js: jax.Array  # column-scaled Jacobian at x (m, n), when not ``stale``
    scale: jax.Array  # D^{-1/2} (n,)
    gram: jax.Array  # Js Jsᵀ (m ≤ n) or Jsᵀ Js (m > n)
    stale: jax.Array  # x moved (or the loop starts): the next trial forms Js, scale, gram first
    loss: jax.Array  # ‖R‖²
    mu: jax.Array
    nu: jax.Array
    ref_loss: jax.Array  # loss at the last real improvement (patience test)
    since: jax.Array
    step: jax.Array
    accepted: jax.Array
    stop: jax.Array  # 0 running, else a key of _STOP
    history: jax.Array  # loss after each trial (NaN where none)


#: the tree of an LMState (a program's result), for its exported form
_STATE_TREE = jax.tree_util.tree_structure(LMState(*([0] * len(LMState._fields))))

#: the K a phase picks (see :func:`lm_points`): few distinct shapes, so few compiled programs
_POINT_BUCKETS = (32, 48, 64, 100)


def lm_points(length: float, dim: int) -> int:
    """The default K: about 16 times per unit of time (at least 32, at most 100), and at most about
    600 residuals K(2d + 1), rounded up to one of 32, 48, 64, 100. The Gram matrix costs
    O(K²(2d + 1)² n) per accepted trial: measured on the 12-dimensional figure-eight, one window's
    phase took 96 s at K = 100 and 10 s at K = 32 for the same error (4e-6 of the range); K = 100
    is what the 4π windows of the one- and two-dimensional problems need (K = 50 failed there)."""
    want = min(max(32, math.ceil(16 * float(length))), max(32, math.ceil(600 / (2 * int(dim) + 1))), 100)
    return next(b for b in _POINT_BUCKETS if b >= want)


def lm_nodes(config: LMConfig, t0: float, T: float, dim: int = 1) -> np.ndarray:
    """The K fixed collocation times on [t0, T] (float64)."""
    n = config.n_points or lm_points(T - t0, dim)
    k = np.arange(n, dtype=np.float64)
    u = k / (n - 1) if config.nodes == "uniform" else (1 - np.cos(np.pi * k / (n - 1))) / 2
    return t0 + (T - t0) * u


def _point_residual(rest, unravel, system, energy0, sqrt_lam):
    """x, t ↦ the (2d + 1) residuals of one collocation time t (before the 1/√K)."""

    def fn(x, t):
        model = eqx.combine(unravel(x), rest)
        z, dz = model.value_and_rate(t[None])
        energy, field = energy_and_vector_field(system, z)
        return jnp.concatenate([(dz - field)[0], sqrt_lam * (energy - energy0)])

    return fn


def residual_fn(rest, unravel, system: HamiltonianSystem, t, energy0, lam_reg) -> Callable:
    """x ↦ R(x) (shape (K(2d+1),), point-major), from one batched pass over the K times."""
    sqrt_lam = jnp.sqrt(lam_reg)
    inv = 1 / jnp.sqrt(jnp.asarray(t.shape[0], t.dtype))

    def fn(x):
        model = eqx.combine(unravel(x), rest)
        z, dz = model.value_and_rate(t)
        energy, field = energy_and_vector_field(system, z)
        per_point = jnp.concatenate([dz - field, sqrt_lam * (energy - energy0)[:, None]], axis=1)
        return per_point.reshape(-1) * inv

    return fn


def jacobian_fn(rest, unravel, system: HamiltonianSystem, t, energy0, lam_reg) -> Callable:
    """x ↦ J(x) = ∂R/∂x (m × n), point by point (see the module docstring)."""
    inv = 1 / jnp.sqrt(jnp.asarray(t.shape[0], t.dtype))
    point = _point_residual(rest, unravel, system, energy0, jnp.sqrt(lam_reg))
    per_point = jax.vmap(jax.jacrev(point), in_axes=(None, 0))

    def fn(x):
        return per_point(x, t).reshape(-1, x.shape[0]) * inv  # (K, 2d+1, n) → (m, n)

    return fn


def _scaled(J, floor: float):
    """(J D^{-1/2}, D^{-1/2}) for Marquardt's D = diag(JᵀJ), floored (in J's type)."""
    d = jnp.sum(J * J, axis=0)
    d = jnp.maximum(d, floor * jnp.max(d))
    scale = 1 / jnp.sqrt(d)
    return J * scale, scale


def _gram(Js, dtype):
    """Js Jsᵀ (m ≤ n) or Jsᵀ Js (m > n), formed and returned in ``dtype`` (the phase's type:
    a float32 Gram matrix has rounding errors larger than the damping μ·I once μ is small)."""
    m, n = Js.shape
    Js = Js.astype(dtype)
    return Js @ Js.T if m <= n else Js.T @ Js


def _solve(Js, gram, R, mu):
    """(Δ_s, predicted decrease of ½‖R‖², solve) of the damped system at μ, by Cholesky (in R's
    type); ``solve(b)`` gives the scaled step for another right-hand side b with the same factor
    (the geodesic acceleration).

    The factorisation runs in float64 whatever the phase's type (the phase always traces with
    x64 on), by ``jnp.linalg.cholesky`` and two triangular solves: measured on this CPU's jaxlib,
    a 300 × 300 factorisation took 0.26 s in float32 and 0.28 s through ``cho_factor`` against
    ~1 ms this way (other paths fall back to slow expansions above 256 rows), and the damped
    Gram matrix is better conditioned in float64 anyway."""
    m, n = Js.shape
    a = gram.astype(jnp.float64) + mu.astype(jnp.float64) * jnp.eye(gram.shape[0], dtype=jnp.float64)
    low = jnp.linalg.cholesky(a)

    def cho_solve(b):
        half = jax.scipy.linalg.solve_triangular(low, b.astype(jnp.float64), lower=True)
        return jax.scipy.linalg.solve_triangular(low.T, half, lower=False).astype(R.dtype)

    if m <= n:
        def solve(b):
            return -(Js.T @ cho_solve(b).astype(Js.dtype)).astype(R.dtype)

        y = cho_solve(R)
        step = -(Js.T @ y.astype(Js.dtype)).astype(R.dtype)
        gy = R - mu * y  # = Js Jsᵀ y = −Js Δs
        pred = 0.5 * jnp.dot(gy, gy) + mu * jnp.dot(y, gy)  # ½‖JsΔs‖² + μ‖Δs‖²,  ‖Δs‖² = yᵀ G y
    else:
        def solve(b):
            return -cho_solve((Js.T @ b.astype(Js.dtype)).astype(R.dtype))

        step = solve(R)
        jd = (Js @ step.astype(Js.dtype)).astype(R.dtype)
        pred = 0.5 * jnp.dot(jd, jd) + mu * jnp.dot(step, step)
    return step, pred, solve


# ------------------------------------------------------------------------ the loop
def _make_step(res, jac, config: LMConfig, n_hist: int):
    """One trial of the loop: a pure function of (LMState, data)."""
    floor = config.diag_floor

    def fresh(x):
        Js, scale = _scaled(jac(x), floor)
        return Js, scale, _gram(Js, x.dtype)

    def step(s: LMState, data) -> LMState:
        # the Jacobian is formed here only, at the start of the trial after an accepted one (and
        # of the first): one copy of its code in the program, not a second in the initial state
        Js, scale, gram = jax.lax.cond(s.stale, fresh, lambda _: (s.Js, s.scale, s.gram), s.x)
        # μ0 = τ · max diag(JsᵀJs) on the first trial
        mu = jnp.where(s.step == 0, config.mu_init * jnp.max(jnp.sum(Js * Js, axis=0)).astype(s.x.dtype), s.mu)
        s = s._replace(Js=Js, scale=scale, gram=gram, mu=mu)
        ds, pred, solve = _solve(s.Js, s.gram, s.R, s.mu)
        scale = s.scale.astype(s.x.dtype)
        v = scale * ds
        if config.geodesic:  # the second directional derivative of R along v, forward over forward
            rvv = jax.jvp(lambda x: jax.jvp(res, (x,), (v,))[1], (s.x,), (v,))[1]
            acc = solve(rvv)  # (J_sᵀJ_s + μI) a_s = −J_sᵀ r_vv
            x_new = s.x + v + 0.5 * scale * acc
            small = 2 * jnp.linalg.norm(acc) <= config.accel_ratio * jnp.linalg.norm(ds)
        else:
            x_new, small = s.x + v, True
        R_new = res(x_new)
        loss_new = jnp.dot(R_new, R_new)
        rho = 0.5 * (s.loss - loss_new) / pred
        ok = jnp.isfinite(loss_new) & jnp.isfinite(rho) & (pred > 0) & small
        accept = ok & (rho > 0)
        mu_new = jnp.where(accept, s.mu * jnp.maximum(1 / 3, 1 - (2 * rho - 1) ** 3), s.mu * s.nu)
        nu_new = jnp.where(accept, 2.0, 2 * s.nu).astype(s.nu.dtype)
        x = jnp.where(accept, x_new, s.x)
        R = jnp.where(accept, R_new, s.R)
        loss = jnp.where(accept, loss_new, s.loss)
        real = loss < s.ref_loss * (1 - data["min_rel"])
        ref_loss = jnp.where(real, loss, s.ref_loss)
        since = jnp.where(real, 0, s.since + 1)
        n = s.step + 1
        stalled = ~jnp.isfinite(mu_new) | (mu_new > 1e30)
        stop = jnp.where(loss <= data["loss_tol"], 1,
                         jnp.where(since >= data["patience"], 2,
                                   jnp.where(stalled, 3, jnp.where(n >= data["budget"], 4, 0))))
        history = s.history.at[jnp.minimum(n, n_hist - 1)].set(loss)
        # (under vmap, lax.while_loop itself holds the members that have stopped)
        return LMState(x, R, s.Js, s.scale, s.gram, accept, loss, mu_new, nu_new, ref_loss, since, n,
                       s.accepted + accept.astype(jnp.int32), stop.astype(jnp.int32), history)

    return step


def _init_state(x, res, jac, config: LMConfig, n_hist: int, data) -> LMState:
    R = res(x)
    J = jax.eval_shape(jac, x)  # placeholders of Js, scale and gram: the first trial forms them
    k = min(J.shape)
    Js, scale, gram = jnp.zeros(J.shape, J.dtype), jnp.zeros((J.shape[1],), J.dtype), jnp.zeros((k, k), x.dtype)
    loss = jnp.dot(R, R)
    i32 = lambda v: jnp.asarray(v, jnp.int32)  # noqa: E731
    hist = jnp.full((n_hist,), jnp.nan, x.dtype).at[0].set(loss)
    stop = jnp.where(loss <= data["loss_tol"], 1, 0).astype(jnp.int32)
    return LMState(x, R, Js, scale, gram, jnp.asarray(True), loss, jnp.zeros((), x.dtype),
                   jnp.asarray(2.0, x.dtype), loss, i32(0), i32(0), i32(0), stop, hist)


def _data(config: LMConfig, dtype) -> dict[str, jax.Array]:
    return {"loss_tol": on_device(config.loss_tol, dtype), "patience": on_device(config.patience, jnp.int32),
            "min_rel": on_device(config.min_rel_improvement, dtype),
            "budget": on_device(config.steps, jnp.int32)}


def _energy0(model, system, energy0):
    if energy0 is not None:
        return float(energy0)
    with jax.enable_x64(True):
        return float(system.energy(on_device(model.z0, np.float64)))



@dataclass
class LMResult:
    """What a phase returns: the model after the last accepted trial (the lowest loss seen), in
    the input's float type, and the loss after each trial (``loss[0]``: the input's)."""

    model: TrialSolution
    loss: np.ndarray
    initial_loss: float
    final_loss: float
    steps: int
    accepted: int
    stop_reason: str
    wall_time: float
    compile_time: float
    config: LMConfig


def _functions(config: LMConfig, system, unravel, unravel_jac, rest, t, e0, lam, jac_dtype):
    res = residual_fn(rest, unravel, system, t, e0, lam)
    if jac_dtype == t.dtype:
        return res, jacobian_fn(rest, unravel, system, t, e0, lam)
    inner = jacobian_fn(cast_floats(rest, jac_dtype), unravel_jac, system, t.astype(jac_dtype), e0.astype(jac_dtype),
                        lam.astype(jac_dtype))
    return res, lambda x: inner(x.astype(jac_dtype))


_COMPILED: dict[Any, Any] = program_cache({})


def _compiled_loop(config: LMConfig, system, unravel, unravel_jac, jac_dtype, args, batched: bool, layout: str):
    """The whole phase as one compiled program per (system, config, shapes, parameter layout); the
    collocation times, E0 and λ_reg are arguments, so windows of other lengths reuse it. Kept on
    disk in its exported form where the system qualifies (:func:`atlasnn.compile_cache.compiled_from_disk`)."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    sig = tuple((tuple(np.shape(v)), str(jnp.asarray(v).dtype)) for v in leaves)
    key = (id(system), batched, config.replace(lam_reg=0.0, loss_tol=0.0, patience=1, min_rel_improvement=0.0),
           treedef, sig, str(jac_dtype), trace_settings(), layout)
    hit = _COMPILED.get(key)
    if hit is not None and hit[0] is system:
        return hit[1], 0.0
    n_hist = config.steps + 1

    def run(x, rest, t, e0, lam, data):
        res, jac = _functions(config, system, unravel, unravel_jac, rest, t, e0, lam, jac_dtype)
        body = _make_step(res, jac, config, n_hist)
        s0 = _init_state(x, res, jac, config, n_hist, data)
        return jax.lax.while_loop(lambda s: s.stop == 0, lambda s: body(s, data), s0)

    fn = jax.jit(jax.vmap(run, in_axes=(0, 0, 0, 0, None, None)) if batched else run)
    start = time.perf_counter()
    settings = {"batched": batched, "config": repr(key[2]), "jac_dtype": str(jac_dtype), "parameters": layout}
    compiled = compile_training_program(fn, args, system, key=settings, out_tree=_STATE_TREE, prefix="lm")
    _COMPILED[key] = (system, compiled)
    return compiled, time.perf_counter() - start


def levenberg_marquardt(model: TrialSolution, system: HamiltonianSystem, T: float,
                        config: LMConfig = LMConfig(), *, energy0: float | None = None) -> LMResult:
    """Run a Levenberg–Marquardt phase on [model.t0, T] (E0 default: H(model.z0)). LM accepts
    decreases only: the returned model has the lowest loss seen."""
    return lm_batch([model], system, T, config, energy0=energy0)[0]


def lm_batch(models: Sequence[TrialSolution], system: HamiltonianSystem, T: float | Sequence[float],
             config: LMConfig = LMConfig(), *, energy0: float | Sequence[float] | None = None) -> list[LMResult]:
    """:func:`levenberg_marquardt` for several models of one shape (e.g. seeds, or windows of
    different lengths) as one compiled program (``vmap`` of the loop; each stops on its own). A
    result's ``wall_time`` is the batch's wall time divided by the batch size."""
    models = list(models)
    n = len(models)
    if n < 1:
        raise ConfigError("lm_batch needs at least one model")
    Ts = list(T) if isinstance(T, (list, tuple)) else [T] * n
    e0s = list(energy0) if isinstance(energy0, (list, tuple)) else [energy0] * n
    e0s = [_energy0(m, system, e) for m, e in zip(models, e0s)]
    in_dtype = models[0].z0.dtype
    with jax.enable_x64(True):  # the factorisation is float64 in every precision (see _solve)
        dtype = jnp.float64 if config.precision in ("float64", "mixed") else in_dtype
        jac_dtype = jnp.float32 if config.precision == "mixed" else dtype
        parts = []
        for m in models:
            params, rest = eqx.partition(cast_floats(m, dtype), trainable_filter(m, config.freeze_gamma))
            x, unravel = ravel(params)
            parts.append((x, rest, unravel, ravel(cast_floats(params, jac_dtype))[1], params))
        unravel, unravel_jac = parts[0][2], parts[0][3]
        dim = system.dim
        points = {config.n_points or lm_points(float(t) - float(m.t0), dim) for m, t in zip(models, Ts)}
        if len(points) > 1:  # one program: every member of a batch on the largest K
            config = config.replace(n_points=max(points))
        times = [on_device(lm_nodes(config, float(m.t0), float(t), dim), dtype) for m, t in zip(models, Ts)]
        if n > 1:
            x, rest = stack_models([p[0] for p in parts]), stack_models([p[1] for p in parts])
            t, e0 = stack_models(times), on_device(np.asarray(e0s), dtype)
        else:
            x, rest, t, e0 = parts[0][0], parts[0][1], times[0], on_device(e0s[0], dtype)
        args = (x, rest, t, e0, on_device(config.lam_reg, dtype), _data(config, dtype))
        layout = str([jax.tree_util.tree_structure(parts[0][4])]
                     + [(np.shape(v), str(v.dtype)) for v in jax.tree_util.tree_leaves(parts[0][4])])
        compiled, compile_time = _compiled_loop(config, system, unravel, unravel_jac, jac_dtype, args, n > 1, layout)
        start = time.perf_counter()
        state = compiled(*args)
        jax.block_until_ready(state.x)
        wall = time.perf_counter() - start
        out = []
        for part, si in zip(parts, unstack_models(state, n) if n > 1 else [state]):
            model = cast_floats(eqx.combine(unravel_on_host(si.x, part[4]), part[1]), in_dtype)
            hist = np.asarray(si.history, np.float64)
            hist = hist[np.isfinite(hist)]
            out.append(LMResult(model, hist, float(hist[0]), float(si.loss), int(si.step), int(si.accepted),
                                _STOP.get(int(si.stop), "running"), wall / n, compile_time, config))
    return out


class LMOutcome(NamedTuple):
    """What :func:`lm_minimise` returns: the parameters with the lowest loss seen, the loss after
    each trial, why it stopped, and the counts."""

    x: jax.Array
    history: np.ndarray
    stop_reason: str
    steps: int
    accepted: int


@program_cache
@functools.lru_cache(maxsize=8)
def _minimise_program(res: Callable, jac: Callable, config: LMConfig) -> Callable:
    """The jitted loop of :func:`lm_minimise` for one problem, kept so that calls with new ``args``
    (e.g. fresh collocation points) reuse its program instead of tracing it again."""
    n_hist = config.steps + 1

    def run(x, args, data):
        r, j = (lambda v: res(v, args)), (lambda v: jac(v, args))
        body = _make_step(r, j, config, n_hist)
        s0 = _init_state(x, r, j, config, n_hist, data)
        return jax.lax.while_loop(lambda s: s.stop == 0, lambda s: body(s, data), s0)

    return jax.jit(run)


def lm_minimise(res: Callable, jac: Callable, x0: jax.Array, args: Any, config: LMConfig = LMConfig()) -> LMOutcome:
    """The same damped Gauss–Newton loop for any least-squares problem min ‖res(x, args)‖²:
    ``res(x, args)`` gives the residual vector (m,), ``jac(x, args)`` its Jacobian (m, n). One
    compiled program (``args`` are its arguments, so new data of the same shape reuses nothing
    but costs no retrace of the loop's logic). Used by bundles and parameter fits."""
    with jax.enable_x64(True):  # the factorisation is float64 (see _solve); x keeps its own type
        data = _data(config, x0.dtype)
        state = _minimise_program(res, jac, config)(x0, args, data)
        hist = np.asarray(state.history, np.float64)
    return LMOutcome(state.x, hist[np.isfinite(hist)], _STOP.get(int(state.stop), "running"), int(state.step),
                     int(state.accepted))

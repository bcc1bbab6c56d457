"""Second-order polishing after Adam: L-BFGS on a fixed set of collocation times.

The objective is the same physics loss as in training (Hamilton residual + λ_reg × energy
penalty, E0 as given), at fixed times: the uniform grid of ``n_points`` times on [t0, T], no
jitter (a line search needs one function, not a new sample at every evaluation). It can follow
any scheme: a single interval, a transfer target, every window of time-marching.

The optimiser is Optax's ``optax.lbfgs`` (two-loop recursion) with its zoom line search (strong
Wolfe conditions, with Hager–Zhang's approximate decrease test for very flat steps). In float32
the line search stalls once the loss is near 1e-7–1e-6 (measured, docs/runs/march-explore.md:
3 of 4 oscillator windows stopped after 32–573 steps, where float64 ran 2 000 steps without a
failure). The safeguards:

- a step whose new loss is not finite or not lower than the current one is rejected: the
  parameters stay, and the L-BFGS memory is cleared (its curvature pairs are the likely culprit);
- two rejections in a row mean the method has stalled at the resolution of the arithmetic: stop;
- the run also stops when the best loss has not improved by a relative ``min_rel_improvement``
  in ``patience`` steps, or after ``steps`` steps;
- ``precision="float64"`` polishes a float64 copy and rounds the result back, keeping it only if
  its loss in the model's own type is lower.

The best parameters seen are returned, so the polished model is never worse than its input on
the polishing objective. (A lower loss on fixed points is not always a smaller error: see the
measurements before making polishing a default.)

The compiled part (:func:`polish_steps`) is a pure function of (flat trainable parameters,
static rest, data, carry) with no Python control flow on data: it can be ``jax.vmap``-ed over
seeds (a stopped member then just holds its parameters while the others go on).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree

from atlasnn.compile_cache import program_cache
from atlasnn.precision import trace_settings
from atlasnn.training._flat import cast_floats
from atlasnn.training._collocation import check_interval, uniform_grid
from atlasnn.errors import ConfigError
from atlasnn.training._loss import physics_loss
from atlasnn.training._step import trainable_filter
from atlasnn.nn import TrialSolution
from atlasnn.systems import HamiltonianSystem

__all__ = ["PolishConfig", "PolishResult", "polish", "polish_steps", "PolishCarry", "make_lbfgs"]


@dataclass(frozen=True)
class PolishConfig:
    """Settings of an L-BFGS polishing phase.

    ``n_points``: the fixed collocation times (uniform grid on [t0, T], ends included);
    ``steps``: the step budget; ``memory``: the number of L-BFGS curvature pairs;
    ``linesearch_steps``: the zoom line search's budget per step; ``patience`` and
    ``min_rel_improvement``: stop when the best loss has not dropped by that relative amount in
    that many steps; ``lam_reg`` and ``freeze_gamma`` as in training; ``chunk``: steps per
    compiled call (the host checks the stop flag between chunks); ``precision``: ``"model"``
    (polish in the model's float type) or ``"float64"`` (polish a float64 copy, then round the
    result back to the model's type; kept only if its loss, in the model's type, is lower).
    """

    steps: int = 1000
    n_points: int = 400
    memory: int = 20
    linesearch_steps: int = 25
    patience: int = 100
    min_rel_improvement: float = 1e-3
    lam_reg: float = 1.0
    freeze_gamma: bool = True
    chunk: int = 100
    precision: str = "model"

    def __post_init__(self) -> None:
        def bad(name, value, why):
            raise ConfigError(f"polish.{name} {why}, got {value!r}")

        def is_int(v):
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        for name, low in (("steps", 1), ("n_points", 2), ("memory", 1), ("linesearch_steps", 1),
                          ("patience", 1), ("chunk", 1)):
            v = getattr(self, name)
            if not is_int(v) or v < low:
                bad(name, v, f"must be an integer >= {low}")
        r = self.min_rel_improvement
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) or not 0 <= r < 1:
            bad("min_rel_improvement", r, "must be a number in [0, 1)")
        lam = self.lam_reg
        if isinstance(lam, bool) or not isinstance(lam, (int, float)) or not math.isfinite(lam) or lam < 0:
            bad("lam_reg", lam, "must be a finite number >= 0")
        if not isinstance(self.freeze_gamma, bool):
            bad("freeze_gamma", self.freeze_gamma, "must be true or false")
        if self.precision not in PRECISIONS:
            bad("precision", self.precision, f"must be one of {list(PRECISIONS)}")

    def replace(self, **changes: Any) -> "PolishConfig":
        return dataclasses.replace(self, **changes)


class PolishCarry(NamedTuple):
    """The state of a polishing run between compiled calls (all arrays; vmap-able)."""

    params: Any  # current parameters
    opt_state: Any  # L-BFGS + line-search state
    value: jax.Array  # loss at ``params``
    grad: Any  # its gradient
    best_params: Any
    best_value: jax.Array
    ref_value: jax.Array  # the best loss at the last "real" improvement (patience test)
    since: jax.Array  # steps since ``ref_value`` was set
    rejected: jax.Array  # consecutive rejected steps
    n_rejected: jax.Array  # rejected steps in all
    stop: jax.Array  # 0 running, 1 no improvement, 2 stalled, 3 budget
    step: jax.Array  # steps taken


@dataclass
class PolishResult:
    """What :func:`polish` returns.

    ``model``: the best parameters seen (never worse than the input on the polishing objective);
    ``loss``: the loss at the start of every step taken (``loss[0]`` is the input's);
    ``initial_loss`` / ``final_loss``: the input's and the returned model's objective;
    ``stop_reason``: "no_improvement" | "stalled" | "budget"; ``rejected_steps``: steps the
    float32 safeguard refused.
    """

    model: TrialSolution
    loss: np.ndarray
    initial_loss: float
    final_loss: float
    steps: int
    stop_reason: str
    rejected_steps: int
    wall_time: float
    compile_time: float
    config: PolishConfig
    interval: tuple[float, float]


_STOP_REASONS = {1: "no_improvement", 2: "stalled", 3: "budget"}
PRECISIONS = ("model", "float64")


def make_lbfgs(config: PolishConfig) -> optax.GradientTransformationExtraArgs:
    """optax.lbfgs with a zoom line search whose first trial step is 1 (the quasi-Newton step)."""
    return optax.lbfgs(
        memory_size=config.memory,
        linesearch=optax.scale_by_zoom_linesearch(
            max_linesearch_steps=config.linesearch_steps, initial_guess_strategy="one"
        ),
    )


def _objective(rest, unravel, system: HamiltonianSystem, t, energy0, lam_reg):
    """x ↦ L(θ(x)) for the flat parameter vector x (one leaf: a much smaller compiled graph for
    the L-BFGS memory updates and the line search than one per network array)."""

    def fn(x):
        return physics_loss(eqx.combine(unravel(x), rest), system, t, energy0, lam_reg)[0]

    return fn


def polish_init(params: jax.Array, rest, unravel, system: HamiltonianSystem, data: dict[str, jax.Array],
                opt: optax.GradientTransformationExtraArgs) -> PolishCarry:
    """The starting carry: the loss and gradient at the input (flat) parameters."""
    fn = _objective(rest, unravel, system, data["t"], data["energy0"], data["lam_reg"])
    value, grad = jax.value_and_grad(fn)(params)
    i32 = lambda v: jnp.asarray(v, jnp.int32)  # noqa: E731
    return PolishCarry(params, opt.init(params), value, grad, params, value, value,
                       i32(0), i32(0), i32(0), i32(0), i32(0))


def polish_steps(carry: PolishCarry, rest, unravel, system: HamiltonianSystem, data: dict[str, jax.Array],
                 opt: optax.GradientTransformationExtraArgs, n_steps: int) -> tuple[PolishCarry, jax.Array]:
    """Take up to ``n_steps`` L-BFGS steps (a pure function; stopped runs hold still).

    The parameters in ``carry`` are flat (``jax.flatten_util.ravel_pytree`` of the trainable
    partition; ``unravel`` maps them back). ``data`` holds the fixed times ``t``, ``energy0``,
    ``lam_reg`` and the stopping settings ``budget``, ``patience``, ``min_rel`` (arrays, so other
    values do not recompile). Returns the new carry and the loss at the start of each step (NaN
    for steps not taken).
    """
    fn = _objective(rest, unravel, system, data["t"], data["energy0"], data["lam_reg"])

    def step(c: PolishCarry, _):
        running = c.stop == 0
        updates, state = opt.update(c.grad, c.opt_state, c.params, value=c.value, grad=c.grad, value_fn=fn)
        new_params = optax.apply_updates(c.params, updates)
        new_value = optax.tree.get(state, "value")
        new_grad = optax.tree.get(state, "grad")
        accept = jnp.isfinite(new_value) & (new_value < c.value)
        # a rejected step: keep the parameters, clear the L-BFGS memory (fresh state)
        fresh = opt.init(c.params)
        pick = lambda a, b: jax.tree_util.tree_map(lambda x, y: jnp.where(accept, x, y), a, b)  # noqa: E731
        params = pick(new_params, c.params)
        opt_state = pick(state, fresh)
        value = jnp.where(accept, new_value, c.value)
        grad = pick(new_grad, c.grad)
        better = value < c.best_value
        best_params = jax.tree_util.tree_map(lambda x, y: jnp.where(better, x, y), params, c.best_params)
        best_value = jnp.minimum(value, c.best_value)
        real = best_value < c.ref_value * (1 - data["min_rel"])
        ref_value = jnp.where(real, best_value, c.ref_value)
        since = jnp.where(real, 0, c.since + 1)
        rejected = jnp.where(accept, 0, c.rejected + 1)
        n = c.step + 1
        stop = jnp.where(rejected >= 2, 2, jnp.where(since >= data["patience"], 1,
                                                     jnp.where(n >= data["budget"], 3, 0)))
        new = PolishCarry(params, opt_state, value, grad, best_params, best_value, ref_value,
                          since, rejected, c.n_rejected + (~accept).astype(jnp.int32),
                          stop.astype(jnp.int32), n)
        out = jax.tree_util.tree_map(lambda x, y: jnp.where(running, x, y), new, c)
        return out, jnp.where(running, c.value, jnp.nan)

    return jax.lax.scan(step, carry, None, length=n_steps)


_CACHE: dict[Any, Any] = program_cache({})


def _compiled_steps(args: tuple, unravel, system: HamiltonianSystem, config: PolishConfig):
    """Compile a chunk of steps once per (system, optimiser settings, argument shapes)."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    sig = tuple((tuple(np.shape(x)), str(jnp.asarray(x).dtype)) for x in leaves)
    key = (id(system), config.memory, config.linesearch_steps, config.chunk, treedef, sig,
           trace_settings())
    hit = _CACHE.get(key)
    if hit is not None and hit[0] is system:
        return hit[1], 0.0
    opt = make_lbfgs(config)
    start = time.perf_counter()
    # unravel depends only on the structure, shapes and dtypes of the parameters (in the key)
    fn = jax.jit(lambda c, r, d: polish_steps(c, r, unravel, system, d, opt, config.chunk))
    compiled = fn.lower(*args).compile()
    _CACHE[key] = (system, compiled)
    return compiled, time.perf_counter() - start


def polish_data(config: PolishConfig, t0: float, T: float, energy0: float, dtype) -> dict[str, jax.Array]:
    """The traced inputs of a polishing run: fixed times, E0, λ_reg and the stopping settings."""
    check_interval(float(t0), float(T), config.n_points)
    return {
        "t": uniform_grid(float(t0), float(T), config.n_points, dtype),
        "energy0": jnp.asarray(energy0, dtype),
        "lam_reg": jnp.asarray(config.lam_reg, dtype),
        "budget": jnp.asarray(config.steps, jnp.int32),
        "patience": jnp.asarray(config.patience, jnp.int32),
        "min_rel": jnp.asarray(config.min_rel_improvement, dtype),
    }


def polish(
    model: TrialSolution,
    system: HamiltonianSystem,
    T: float,
    config: PolishConfig = PolishConfig(),
    *,
    energy0: float | None = None,
) -> PolishResult:
    """Polish a trained model by L-BFGS on the physics loss at fixed times on [model.t0, T].

    Args:
        model: the trained trial solution (e.g. ``TrainResult.model``).
        system: its Hamiltonian system.
        T: the end of the interval (the training interval's).
        config: steps, points, memory, stopping rule, λ_reg, γ frozen or not.
        energy0: E0 of the energy penalty; default H(model.z0).

    Returns:
        A :class:`PolishResult`; its ``model`` has the lowest objective seen.
    """
    if model.state_dim != system.state_dim:
        raise ConfigError(
            f"model state dimension {model.state_dim} does not match system {system.name!r} "
            f"(2d = {system.state_dim})"
        )
    e0 = float(system.energy(model.z0)) if energy0 is None else float(energy0)
    dtype = model.z0.dtype
    if config.precision == "model" or dtype == jnp.float64:
        return _polish(model, system, T, config, e0)
    with jax.enable_x64(True):
        res = _polish(cast_floats(model, jnp.float64), system, T, config, e0)
    polished = cast_floats(res.model, dtype)
    # rounded back to the model's type: keep it only if it is still better there
    data = polish_data(config, float(model.t0), float(T), e0, dtype)
    before, after = (float(physics_loss(m, system, data["t"], data["energy0"], data["lam_reg"])[0])
                     for m in (model, polished))
    better = after < before
    return dataclasses.replace(res, model=polished if better else model, initial_loss=before,
                               final_loss=after if better else before)


def _polish(model: TrialSolution, system: HamiltonianSystem, T: float, config: PolishConfig,
            e0: float) -> PolishResult:
    dtype = model.z0.dtype
    data = polish_data(config, float(model.t0), float(T), e0, dtype)
    params, rest = eqx.partition(model, trainable_filter(model, config.freeze_gamma))
    flat, unravel = ravel_pytree(params)
    # the starting loss and gradient run eagerly: one more compilation would cost seconds
    carry = polish_init(flat, rest, unravel, system, data, make_lbfgs(config))
    chunk, compile_time = _compiled_steps((carry, rest, data), unravel, system, config)
    start = time.perf_counter()
    losses = []
    while int(carry.stop) == 0:
        carry, hist = chunk(carry, rest, data)
        hist = np.asarray(hist, dtype=np.float64)
        losses.append(hist[np.isfinite(hist)])
    wall = time.perf_counter() - start
    initial = float(losses[0][0]) if losses and losses[0].size else float("nan")
    return PolishResult(
        model=eqx.combine(unravel(carry.best_params), rest),
        loss=np.concatenate(losses) if losses else np.zeros(0),
        initial_loss=initial,
        final_loss=float(carry.best_value),
        steps=int(carry.step),
        stop_reason=_STOP_REASONS[int(carry.stop)],
        rejected_steps=int(carry.n_rejected),
        wall_time=wall,
        compile_time=compile_time,
        config=config,
        interval=(float(model.t0), float(T)),
    )

"""Training a bundle ẑ(t; z0, λ) on Hamilton's equations over a whole box of members.

Each Adam epoch draws a fresh batch of collocation points (t, z0, λ) uniformly from the box
(inside the compiled loop, ``fold_in(key, epoch)``) and minimises the physics loss of the
library, averaged over members:

    L = mean ‖∂ẑ/∂t − J∇H(ẑ; λ)‖² + λ_reg · mean (H(ẑ; λ) − H(z0; λ))².

Time-marching (``window``): [t0, T] is cut into windows; window k is trained with the earlier
windows frozen, started from their end state s_k(z0, λ) (the whole map handed over), and
initialised from window k − 1's weights with γ frozen (the paper's transfer); window 0 learns γ.
A Levenberg–Marquardt phase on a fixed set of points may follow Adam in each window
(``lm_steps``): the generic least-squares loop :func:`atlasnn.training.lm_minimise`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree

from atlasnn.errors import ConfigError
from atlasnn.nn import BundleTrial, make_bundle_model
from atlasnn.solutions import BundleSolution, bundle_start, window_edges
from atlasnn.systems import BundleBox, HamiltonianSystem
from atlasnn.training._lm import LMConfig, lm_minimise
from atlasnn.training._loss import energy_and_vector_field

__all__ = ["BundleTrainConfig", "BundleTraining", "train_bundle", "bundle_residuals"]


@dataclass(frozen=True)
class BundleTrainConfig:
    """Settings of [`train_bundle`][atlasnn.training.train_bundle].

    ``windows`` equal windows over [t0, T] (1: no time-marching); per window ``epochs`` Adam epochs
    of ``batch`` fresh collocation points, the learning rate decaying by a cosine from ``lr`` to
    ``lr * lr_final_ratio``; ``lam_reg`` the energy penalty's weight; ``lm_steps``
    Levenberg–Marquardt trials after Adam on ``lm_points`` fixed points (0: none); ``chunk`` epochs
    per compiled call (progress is reported between chunks); ``warm_start``: window k starts from
    window k − 1's weights (else from a fresh draw; γ is window 0's either way); ``retry_factor``:
    a window ending above that many times the previous window's loss is trained again (see
    [`train_bundle`][atlasnn.training.train_bundle]; ``inf``: never); ``members``: how collocation members are drawn,
    ``"uniform"`` in the box or ``"edges"`` (half of them from the arcsine law, crowding the faces
    and corners, where the extreme members are: measured on the oscillator bundle, uniform
    draws left the corner of large amplitude and large lam 100x worse than the median);
    ``lm_rounds``: the LM trials are split into that many rounds, each on a fresh draw of
    ``lm_points`` points (one round: one fixed set). Why: about 1 300 parameters fitted to 1 024
    points in four dimensions (t, z0, λ) overfit them: on the oscillator bundle the LM loss of
    window 6 of 8 was 4e-6 on its points and 7e-4 on fresh ones; with 8 rounds 6e-6 on fresh
    ones, and the median member's error fell from 3.8e-3 to 2.9e-3 (seed 0). Short rounds can do
    worse: each round starts LM's damping afresh, and its first steps fit the new points alone
    (a 16-wide bundle with 4 rounds of 10 trials on 192 points ended 10x above one round of 40).
    ``margin``: collocation members are drawn from the box widened by this fraction of its width on
    every side, so that the box's own faces and corners are not the edge of what was trained.

    These defaults are the bundle's everywhere: a config's [bundle] keys default to them
    (``atlasnn config``), and the built-in oscillator bundle uses them per window (2 000 Adam
    epochs, 200 LM trials on 1 024 points), adding 12 windows and 8 LM rounds for its interval.
    """

    windows: int = 1
    epochs: int = 2000
    batch: int = 1024
    lr: float = 2e-3
    lr_final_ratio: float = 0.01
    lam_reg: float = 1.0
    lm_steps: int = 200
    lm_points: int = 1024
    chunk: int = 1000
    warm_start: bool = True
    retry_factor: float = 10.0
    members: str = "edges"
    lm_rounds: int = 1
    margin: float = 0.0

    def __post_init__(self) -> None:
        for name, low in (("windows", 1), ("epochs", 0), ("batch", 1), ("lm_steps", 0), ("lm_points", 2),
                          ("chunk", 1), ("lm_rounds", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ConfigError(f"bundle training {name} must be an integer >= {low}, got {v!r}")
        for name in ("lr", "lr_final_ratio", "lam_reg", "margin"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ConfigError(f"bundle training {name} must be a finite number >= 0, got {v!r}")
        if self.members not in ("uniform", "edges"):
            raise ConfigError(f"bundle training members must be 'uniform' or 'edges', got {self.members!r}")
        r = self.retry_factor
        if isinstance(r, bool) or not isinstance(r, (int, float)) or math.isnan(r) or r < 1:
            raise ConfigError(f"bundle training retry_factor must be a number >= 1 (inf: never retry), got {r!r}")
        if self.epochs == 0 and self.lm_steps == 0:
            raise ConfigError("bundle training needs epochs > 0 or lm_steps > 0")


@dataclass
class BundleTraining:
    """What :func:`train_bundle` returns: the solution, per window the Adam loss per epoch and the
    LM loss per trial, the training and compile seconds (all windows)."""

    solution: BundleSolution
    adam_loss: list[np.ndarray]
    lm_loss: list[np.ndarray]
    train_time: float
    compile_time: float
    lm_stop: list[str] = field(default_factory=list)
    retried: list[bool] = field(default_factory=list)


def _theta_fn(system: HamiltonianSystem, box: BundleBox) -> Callable[[jax.Array], jax.Array]:
    """λ (K, P) ↦ the system's full parameter vector per point (K, P_all)."""
    base, idx = box.theta_layout(system)

    def theta(lam):
        full = jnp.tile(jnp.asarray(base, lam.dtype), (lam.shape[0], 1))
        return full.at[:, idx].set(lam) if idx.size else full

    return theta


def bundle_residuals(model: BundleTrial, system: HamiltonianSystem, box: BundleBox, t, z0, lam,
                     start=None) -> tuple[jax.Array, jax.Array]:
    """Per point: (∂ẑ/∂t − J∇H(ẑ; λ) of shape (K, 2d), H(ẑ; λ) − H(z0; λ) of shape (K,))."""
    dtype = model.weights[0].dtype
    z0 = jnp.asarray(z0, dtype)
    theta = _theta_fn(system, box)(jnp.asarray(lam, dtype))
    z, dz = model.value_and_rate(t, z0, lam, start=start)
    if system.params:
        energy, vf = system.field_at(z, theta)
        energy0 = system.energy_at(z0, theta)
    else:
        energy, vf = energy_and_vector_field(system, z)
        energy0 = system.energy(z0)
    return dz - vf, energy - energy0


def _draw(key, box: BundleBox, n: int, dtype, t_low: float, t_high: float, members: str = "uniform",
          margin: float = 0.0):
    """n points (t in [t_low, t_high], z0, λ) in the box (fixed z0 components stay fixed); t is
    uniform, the members uniform or, with ``members = "edges"``, every other point's member from
    the arcsine law (cos πU), which crowds the faces and corners of the box; ``margin``: the
    members' box widened by that fraction of its width on every side."""
    low = np.asarray([*box.z0_low, *(a for a, _ in box.params.values())], np.float64)
    high = np.asarray([*box.z0_high, *(b for _, b in box.params.values())], np.float64)
    low, high = low - margin * (high - low), high + margin * (high - low)
    low, high = np.concatenate([[t_low], low]), np.concatenate([[t_high], high])
    u = jax.random.uniform(key, (n, low.size), dtype)
    if members == "edges":
        arcsine = 0.5 - 0.5 * jnp.cos(jnp.pi * u[:, 1:])
        u = u.at[1::2, 1:].set(arcsine[1::2])
    x = jnp.asarray(low, dtype) + u * jnp.asarray(high - low, dtype)
    d = box.state_dim
    return x[:, 0], x[:, 1 : 1 + d], x[:, 1 + d :]


def _partition(model: BundleTrial, freeze_gamma: bool):
    spec = jax.tree_util.tree_map(eqx.is_inexact_array, model)
    if freeze_gamma:
        spec = eqx.tree_at(lambda m: m.scaling, spec, jax.tree_util.tree_map(lambda _: False, model.scaling))
    return eqx.partition(model, spec)


@dataclass(frozen=True)
class _Window:
    """One window's problem: the box, its time span, the frozen earlier windows."""

    system: HamiltonianSystem
    box: BundleBox
    t_low: float
    t_high: float
    prev: tuple[BundleTrial, ...]
    edges: np.ndarray

    def residuals(self, model, t, z0, lam):
        start = bundle_start(self.prev, jnp.asarray(self.edges, z0.dtype), z0, lam) if self.prev else None
        start = None if start is None else jax.lax.stop_gradient(start)
        return bundle_residuals(model, self.system, self.box, t, z0, lam, start=start)


def _adam(model, win: _Window, cfg: BundleTrainConfig, key, freeze_gamma: bool, progress):
    params, rest = _partition(model, freeze_gamma)
    opt = optax.adam(optax.cosine_decay_schedule(cfg.lr, max(cfg.epochs, 1), cfg.lr_final_ratio))
    state = opt.init(params)
    dtype = model.weights[0].dtype

    def loss_fn(p, epoch):
        t, z0, lam = _draw(jax.random.fold_in(key, epoch), win.box, cfg.batch, dtype, win.t_low, win.t_high,
                           cfg.members, cfg.margin)
        r, de = win.residuals(eqx.combine(p, rest), t, z0, lam)
        return jnp.mean(jnp.sum(r**2, axis=-1)) + cfg.lam_reg * jnp.mean(de**2)

    def epoch_step(carry, epoch):
        p, s = carry
        loss, g = jax.value_and_grad(loss_fn)(p, epoch)
        upd, s = opt.update(g, s, p)
        return (optax.apply_updates(p, upd), s), loss

    @jax.jit
    def run_chunk(p, s, start):
        return jax.lax.scan(epoch_step, (p, s), start + jnp.arange(cfg.chunk))

    t_start = time.perf_counter()
    compiled = run_chunk.lower(params, state, 0).compile()
    compile_time = time.perf_counter() - t_start
    losses = []
    t_start = time.perf_counter()
    for start in range(0, cfg.epochs, cfg.chunk):
        (params, state), loss = compiled(params, state, start)
        losses.append(np.asarray(loss))
        if progress is not None:
            progress(min(start + cfg.chunk, cfg.epochs), float(losses[-1][-1]))
    loss = np.concatenate(losses)[: cfg.epochs] if losses else np.zeros(0)
    return eqx.combine(params, rest), loss, time.perf_counter() - t_start, compile_time


def _lm(model, win: _Window, cfg: BundleTrainConfig, key, freeze_gamma: bool):
    params, rest = _partition(model, freeze_gamma)
    x0, unravel = ravel_pytree(params)
    points = _draw(key, win.box, cfg.lm_points, x0.dtype, win.t_low, win.t_high, cfg.members, cfg.margin)
    sqrt_lam, inv = math.sqrt(cfg.lam_reg), 1 / math.sqrt(cfg.lm_points)

    def point(x, ti, zi, li):
        r, de = win.residuals(eqx.combine(unravel(x), rest), ti[None], zi[None], li[None])
        return jnp.concatenate([r[0], sqrt_lam * de]) * inv

    def res(x, args):
        return jax.vmap(point, in_axes=(None, 0, 0, 0))(x, *args).reshape(-1)

    def jac(x, args):
        return jax.vmap(jax.jacrev(point), in_axes=(None, 0, 0, 0))(x, *args).reshape(-1, x.shape[0])

    rounds = max(1, min(cfg.lm_rounds, cfg.lm_steps))
    steps = [cfg.lm_steps // rounds + (i < cfg.lm_steps % rounds) for i in range(rounds)]
    history, x, out = [], x0, None
    for i, n in enumerate(steps):
        if i:
            points = _draw(jax.random.fold_in(key, i), win.box, cfg.lm_points, x0.dtype, win.t_low, win.t_high,
                           cfg.members, cfg.margin)
        out = lm_minimise(res, jac, x, points, LMConfig(steps=n, patience=30))
        x = out.x
        history.append(out.history if not i else out.history[1:])  # a later round's start: not a trial
    out = out._replace(history=np.concatenate(history)) if rounds > 1 else out
    return eqx.combine(unravel(out.x), rest), out


def _next_window(prev: BundleTrial, t0: float, warm: bool, seed: int) -> BundleTrial:
    """Window k's starting model, started at t0 with window 0's γ (frozen, the paper's transfer):
    window k − 1's weights (``warm``) or a fresh draw. Measured on a 3-window oscillator bundle
    (1 000 Adam epochs, 40 LM trials a window): warm ended windows 1 and 2 at LM losses 1.2e-5 and
    4.9e-5, fresh at 2.8e-5 and 7.4e-5, warm with the time input shifted to local time at 2.4e-4
    and 4.0e-4 (the old network's shape is no guess for the next window's displacement)."""
    if warm:
        return BundleTrial(prev.weights, prev.biases, prev.scaling, float(t0), prev.centre, prev.inv_half,
                           prev.activation)
    width, depth = int(prev.weights[0].shape[0]), len(prev.weights) - 1
    fresh = make_bundle_model(prev.centre, 1 / np.asarray(prev.inv_half), prev.state_dim, scaling=prev.scaling,
                              width=width, depth=depth, t0=t0, activation=prev.activation, seed=seed)
    return BundleTrial(fresh.weights, fresh.biases, prev.scaling, float(t0), prev.centre, prev.inv_half,
                       prev.activation)


def _train_window(model, win: _Window, config: BundleTrainConfig, key, k: int, report):
    """Adam then LM on one window: (model, Adam losses, LM losses, LM stop, seconds, compile seconds)."""
    loss, seconds, compiling = np.zeros(0), 0.0, 0.0
    if config.epochs:
        model, loss, seconds, compiling = _adam(model, win, config, jax.random.fold_in(key, 0), k > 0, report)
    lm_loss, stop = np.zeros(0), ""
    if config.lm_steps:
        start = time.perf_counter()
        model, out = _lm(model, win, config, jax.random.fold_in(key, 1), k > 0)
        seconds += time.perf_counter() - start
        lm_loss, stop = out.history, out.stop_reason
    return model, loss, lm_loss, stop, seconds, compiling


def _final(loss: np.ndarray, lm_loss: np.ndarray) -> float:
    return float((lm_loss if lm_loss.size else loss)[-1]) if (lm_loss.size or loss.size) else math.inf


def train_bundle(system: HamiltonianSystem, box: BundleBox, config: BundleTrainConfig = BundleTrainConfig(), *,
                 scaling: str = "rational_exp", width: int = 32, depth: int = 2, seed: int = 0,
                 progress: Callable[[int, int, float], None] | None = None,
                 on_window: Callable[[int, float, float], None] | None = None) -> BundleTraining:
    """Train a bundle over ``box`` (time-marched over ``config.windows`` windows); ``progress``
    is called as (window, epoch, loss) between Adam chunks, ``on_window`` as (window, final loss,
    seconds so far) when a window is done.

    A window whose final loss is more than ``config.retry_factor`` times the previous window's is
    trained once more from a fresh draw (and the other start: fresh if it was warm), and the
    attempt with the lower loss is kept (``BundleTraining.retried``). Why: the later windows of
    a bundle are harder (the members drift out of phase) and an unlucky start can end 100x above
    its neighbours (measured: window 7 of 8 of the oscillator bundle at 2.3e-4 between 2.8e-6 and
    1.8e-5; its members' errors then reached 0.5)."""
    box.check_system(system)
    edges = window_edges(box.t0, box.T, config.windows)
    model = make_bundle_model(box.centre(), box.half_width(), box.state_dim, scaling=scaling, width=width,
                              depth=depth, t0=box.t0, seed=seed)
    key = jax.random.PRNGKey(seed + 7919)
    windows, adam_losses, lm_losses, stops, retried = [], [], [], [], []
    train_time = compile_time = 0.0
    for k in range(config.windows):
        win = _Window(system, box, float(edges[k]), float(edges[k + 1]), tuple(windows), edges[: k + 1])
        if k:
            model = _next_window(windows[-1], edges[k], config.warm_start, seed + 7 * k)
        report = None if progress is None else (lambda e, loss, k=k: progress(k, e, loss))
        best = _train_window(model, win, config, jax.random.fold_in(key, 2 * k), k, report)
        train_time, compile_time = train_time + best[4], compile_time + best[5]
        again = k > 0 and _final(best[1], best[2]) > config.retry_factor * _final(adam_losses[-1], lm_losses[-1])
        if again:
            other = _next_window(windows[-1], edges[k], not config.warm_start, seed + 7 * k + 1)
            second = _train_window(other, win, config, jax.random.fold_in(key, 2 * k + 1), k, report)
            train_time, compile_time = train_time + second[4], compile_time + second[5]
            if _final(second[1], second[2]) < _final(best[1], best[2]):
                best = second
        model, loss, lm_loss, stop = best[:4]
        windows.append(model)
        retried.append(bool(again))
        if on_window is not None:
            on_window(k, _final(loss, lm_loss), train_time + compile_time)
        adam_losses.append(loss)
        lm_losses.append(lm_loss)
        stops.append(stop)
    solution = BundleSolution(tuple(windows), edges, box, system)
    return BundleTraining(solution, adam_losses, lm_losses, train_time, compile_time, stops, retried)

"""The compiled part of training: one chunk of epochs in ``lax.scan``, for one model or a batch.

Each epoch draws its jittered collocation times, evaluates the physics loss and its gradient,
updates the parameters with Adam and keeps the bookkeeping (best parameters per rule, tolerance,
divergence) on the device; :mod:`atlasnn.training._train` runs the host loop around it.

A batch of S models of the same shape (typically S seeds of one config) is trained by
``jax.vmap`` of the same chunk over a leading axis of every argument: parameters, Adam states,
bookkeeping, per-run settings and PRNG keys. Each model keeps its own stopping and best-parameter
bookkeeping, exactly as if it ran alone; a model that has stopped is carried along unchanged.

What is compiled depends only on the system, the :class:`Mode` (best rule, schedule, causal
weighting, fixed point), the batch size and the shapes; learning rate, epochs, tolerance, jitter,
λ_reg, interval, E0, seed and whether γ is frozen are traced values, so another run of the same
shape reuses the compiled program. γ is always among the program's trainable leaves; a frozen γ
gets a zero gradient and keeps its value (selected, so bit for bit), which makes a first window
with γ learned and the later ones with γ frozen one program, not two.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import optax

from atlasnn.compile_cache import compile_lowered, compiled_from_disk, cpu_loop_options, program_cache
from atlasnn.precision import on_device, trace_settings
from atlasnn.training._collocation import jittered, uniform_grid, with_release_fixed_point
from atlasnn.training._loss import causal_physics_loss, physics_loss
from atlasnn.nn import TrialSolution
from atlasnn.systems import HamiltonianSystem, defined_by_data

# One Adam transformation for every run; lr and betas live in its state (inject_hyperparams),
# so runs with other hyperparameters reuse the same compiled step.
_ADAM = optax.inject_hyperparams(optax.adam)(learning_rate=1e-3, b1=0.9, b2=0.999, eps=1e-8)
_adam_init = jax.jit(_ADAM.init)  # one program; eagerly, optax's init runs one per leaf shape and op


def trainable_filter(model: TrialSolution, freeze_gamma: bool) -> TrialSolution:
    """A bool tree: network weights always trainable, γ unless frozen, z0 never."""
    spec = jax.tree_util.tree_map(lambda _: False, model)
    spec = eqx.tree_at(lambda m: m.net, spec, jax.tree_util.tree_map(eqx.is_inexact_array, model.net))
    if not freeze_gamma:
        spec = eqx.tree_at(
            lambda m: m.scaling, spec, jax.tree_util.tree_map(eqx.is_inexact_array, model.scaling)
        )
    return spec


def gamma_filter(model: TrialSolution) -> TrialSolution:
    """A bool tree true at γ's leaves only (the time scaling's arrays)."""
    spec = jax.tree_util.tree_map(lambda _: False, model)
    return eqx.tree_at(lambda m: m.scaling, spec, jax.tree_util.tree_map(eqx.is_inexact_array, model.scaling))


def _gamma_where(flag, a, b=None):
    """``a`` with its γ leaves taken from ``b`` (zeros when ``b`` is None) where ``flag`` is false
    (trees shaped as the trainable parameters, γ included)."""
    other = jax.tree_util.tree_map(jnp.zeros_like, a.scaling) if b is None else b.scaling
    return eqx.tree_at(lambda m: m.scaling, a,
                       jax.tree_util.tree_map(lambda x, y: jnp.where(flag, x, y), a.scaling, other))


def restrict_opt_state(opt_state: Any, model: TrialSolution, freeze_gamma: bool) -> Any:
    """Adam's state of a run, keeping only the moments of the leaves trainable under
    ``freeze_gamma`` (a transfer's target, a frozen-γ window, the saved state of a frozen run)."""
    spec = trainable_filter(model, freeze_gamma)
    adam, *others = opt_state.inner_state
    adam = adam._replace(mu=eqx.filter(adam.mu, spec), nu=eqx.filter(adam.nu, spec))
    return opt_state._replace(inner_state=(adam, *others))


def set_hyperparams(opt_state, cfg, dtype):
    hp = dict(opt_state.hyperparams)
    hp["learning_rate"] = on_device(cfg.lr, dtype)
    hp["b1"] = on_device(cfg.betas[0], dtype)
    hp["b2"] = on_device(cfg.betas[1], dtype)
    return opt_state._replace(hyperparams=hp)


def init_opt_state(params, cfg, dtype):
    """Adam's state for ``params`` with the config's lr and betas."""
    return set_hyperparams(_adam_init(params), cfg, dtype)


def initial_track(params, dtype, threshold: float = math.inf) -> dict[str, Any]:
    """The trainer's device-side bookkeeping; ``threshold`` is the best rule's starting loss
    (∞, or 1 for ``release_exact``, whose ``best_params`` then start as the initial ones)."""
    inf = on_device(math.inf, dtype)
    return {
        "best_params": params,  # per best_rule
        "best_loss": on_device(threshold, dtype),
        "best_epoch": on_device(-1, jnp.int32),
        "any_params": params,  # lowest finite loss over the whole run (divergence fallback)
        "any_loss": inf,
        "any_epoch": on_device(-1, jnp.int32),
        "stop": on_device(0, jnp.int32),  # 0 running, 1 tolerance met, 2 diverged
        "stop_epoch": on_device(-1, jnp.int32),
    }


def _select(pred, a, b):
    return jax.tree_util.tree_map(lambda x, y: jnp.where(pred, x, y), a, b)


@dataclass(frozen=True)
class Mode:
    """The parts of a config that change the compiled epoch (the rest are traced values)."""

    rule: str  # "release" | "lowest" | "release_exact" ("last" trains as "lowest")
    schedule: str
    lr_final_ratio: float
    causal: bool
    fixed_point: bool

    @classmethod
    def of(cls, cfg) -> "Mode":
        """The mode of a :class:`~atlasnn.training._records.TrainConfig`."""
        rule = "lowest" if cfg.best_rule == "last" else cfg.best_rule
        ratio = float(cfg.lr_final_ratio) if cfg.lr_schedule != "constant" else 1.0
        return cls(rule, cfg.lr_schedule, ratio, cfg.causal_eps > 0, cfg.release_fixed_point)

    def lr_factor(self, progress: jax.Array) -> jax.Array:
        """lr(e)/lr for progress = e / budget in [0, 1] (an Optax schedule over unit time)."""
        if self.schedule == "cosine":
            return optax.cosine_decay_schedule(1.0, decay_steps=1, alpha=self.lr_final_ratio)(progress)
        if self.schedule == "exponential":
            return optax.exponential_decay(1.0, transition_steps=1, decay_rate=self.lr_final_ratio)(progress)
        return jnp.ones_like(progress)


def _collocation(settings, key, epoch, mode: Mode):
    t0, T = settings["t0"], settings["T"]
    t = jittered(settings["grid"], jax.random.fold_in(key, epoch), settings["sigma"], t0, T)
    if mode.fixed_point:
        t = with_release_fixed_point(t, t0, T)
    return jnp.sort(t) if mode.causal else t


def _objective(mode: Mode, settings, rest, system):
    """p, t ↦ (objective, (physics loss, residual term, energy penalty))."""

    def fn(p, t):
        model = eqx.combine(p, rest)
        if mode.causal:
            dt = (settings["T"] - settings["t0"]) / (settings["grid"].shape[0] - 1)
            return causal_physics_loss(model, system, t, settings["energy0"], settings["lam_reg"],
                                       settings["causal_eps"], dt)
        loss, (res, en) = physics_loss(model, system, t, settings["energy0"], settings["lam_reg"])
        return loss, (loss, res, en)

    return fn


def _run_chunk(params, rest, opt_state, track, epochs, settings, key, system, mode: Mode):
    """Run the epochs in ``epochs`` (shape (chunk,)); a compiled unit (see :func:`compiled_chunk`)."""
    grad_fn = jax.value_and_grad(_objective(mode, settings, rest, system), has_aux=True)
    n_gamma = eqx.combine(params, rest).scaling.gamma_array().shape[0]
    dtype = settings["grid"].dtype
    exact = mode.rule == "release_exact"

    def skipped(carry, epoch):
        nan = jnp.asarray(jnp.nan, dtype)
        return carry, (nan, nan, nan, jnp.full((n_gamma,), jnp.nan, dtype))

    def one_epoch(carry, epoch):
        p, o, tr = carry
        t = _collocation(settings, key, epoch, mode)
        (_, (loss, res, en)), grads = grad_fn(p, t)
        # γ is a trainable leaf in every run; frozen, its gradient is zero and its value held
        # (selected, not multiplied: the value stays bit for bit whatever the gradient)
        grads = _gamma_where(settings["train_gamma"], grads)
        gamma = eqx.combine(p, rest).scaling.gamma_array()
        if mode.schedule != "constant":
            progress = epoch.astype(dtype) / settings["budget"].astype(dtype)
            hp = dict(o.hyperparams)
            hp["learning_rate"] = settings["lr"] * mode.lr_factor(progress).astype(dtype)
            o = o._replace(hyperparams=hp)
        updates, o_new = _ADAM.update(grads, o, p)
        p_new = _gamma_where(settings["train_gamma"], eqx.apply_updates(p, updates), p)
        finite = jnp.isfinite(loss)
        # bookkeeping: the loss was measured on p (before this epoch's update)
        better_any = finite & (loss < tr["any_loss"])
        eligible = epoch >= settings["best_start"] if mode.rule in ("release", "release_exact") else True
        better = finite & eligible & (loss < tr["best_loss"])
        tr = dict(tr)
        tr["any_params"] = _select(better_any, p, tr["any_params"])
        tr["any_loss"] = jnp.where(better_any, loss, tr["any_loss"])
        tr["any_epoch"] = jnp.where(better_any, epoch, tr["any_epoch"])
        tr["best_params"] = _select(better, p_new if exact else p, tr["best_params"])
        tr["best_loss"] = jnp.where(better, loss, tr["best_loss"])
        tr["best_epoch"] = jnp.where(better, epoch, tr["best_epoch"])
        met = finite & ((loss < settings["tolerance"]) if exact else (loss <= settings["tolerance"]))
        stop = jnp.where(~finite, 2, jnp.where(met, 1, 0)).astype(jnp.int32)
        tr["stop"] = stop
        tr["stop_epoch"] = jnp.where(stop > 0, epoch, tr["stop_epoch"])
        # on a stop the parameters that produced the stopping loss stay as they are (the release
        # rule keeps the update of a tolerance stop)
        hold = (stop == 2) if exact else (stop > 0)
        p = _select(hold, p, p_new)
        o = _select(hold, o, o_new)
        return (p, o, tr), (loss, res, en, gamma)

    def body(carry, epoch):
        running = (carry[2]["stop"] == 0) & (epoch < settings["budget"])
        # on a CPU a conditional skips the finished epochs' work; elsewhere (a GPU) each
        # conditional would wait for its predicate on the host, so the epoch is computed and
        # masked instead (the same values: a finished run keeps its carry either way)
        return jax.lax.platform_dependent(
            carry, epoch,
            cpu=lambda c, e: jax.lax.cond(running, one_epoch, skipped, c, e),
            default=lambda c, e: _select(running, one_epoch(c, e), skipped(c, e)))

    (params, opt_state, track), (loss, res, en, gamma) = jax.lax.scan(
        body, (params, opt_state, track), epochs
    )
    return params, opt_state, track, dict(zip(_CHUNK_OUTPUTS, (loss, res, en, gamma)))


def _classes(x):
    """The classes of the Equinox modules in ``x`` (a model, or a part of one), nested ones too."""
    if isinstance(x, eqx.Module):
        yield type(x)
        for f in dataclasses.fields(x):
            yield from _classes(getattr(x, f.name, None))
    elif isinstance(x, (list, tuple)):
        for y in x:
            yield from _classes(y)
    elif isinstance(x, dict):
        for y in x.values():
            yield from _classes(y)


def may_keep(system: HamiltonianSystem, model_part) -> bool:
    """Whether a training program of ``system`` and this network may be kept on disk: the system is
    defined by data (:func:`atlasnn.systems.defined_by_data`) and every module of the network (the
    trial solution, its MLP, its time scaling) is one of atlasnn's own classes, whose source is in
    the program's key; a class of the user's is named in the key, but its code is not."""
    return defined_by_data(system) and all(c.__module__.startswith("atlasnn.") for c in _classes(model_part))


_CHUNK_CACHE: dict[Any, Any] = program_cache({})
#: atlasnn's packages the training programs are built from (the key of their exported forms on disk)
TRAINING_PACKAGES = ("training", "nn", "systems", "solutions")
_CHUNK_OUTPUTS = ("loss", "residual", "energy", "gamma")  # the per-epoch series a chunk returns


def training_compiler_options() -> dict | None:
    """XLA's options for compiling the two training programs, the Adam chunk and the
    Levenberg–Marquardt loop. On a CPU: XLA's loop emitters instead of its newer fusion emitters.
    They compile these programs in 60–80 % of the time (the first-hour case's: 1.9 → 1.1 s and
    2.0 → 1.55 s on one core; cold runs of 32 seeds, 5.35 → 3.9 s of the training's compiling)
    and run them as fast; they sum in another order, so a run's numbers differ in their last bits
    from XLA's defaults, as they do from one machine to another, with no difference in accuracy
    resolved over those seeds (measured when this was chosen: CHANGELOG.md, 2026-11-27, and git's
    history of docs/benchmarks/). Elsewhere (a GPU): XLA's defaults."""
    return cpu_loop_options()


def compile_training_program(fn: Callable, args: tuple, system: HamiltonianSystem, *, key: dict, out_tree,
                             prefix: str):
    """A training program (the jitted ``fn``) compiled for ``args`` with
    :func:`training_compiler_options`: read back from (or kept in) its exported form on disk where
    the system and the network (``args[1]``, the model's static part) qualify (:func:`may_keep`;
    ``key``: the program's own settings; ``out_tree``: its result's tree), else traced here."""
    options = training_compiler_options()
    if may_keep(system, args[1]):  # kept on disk: a later process neither traces nor lowers it
        kept = compiled_from_disk(fn, args, key={"system": system.describe(), **key}, packages=TRAINING_PACKAGES,
                                  out_tree=out_tree, prefix=prefix, options=options)
        if kept is not None:
            return kept
    return compile_lowered(fn.lower(*args), options)


def compiled_chunk(args: tuple, system: HamiltonianSystem, mode: Mode, batched: bool = False,
                   announce: Callable[[], None] | None = None):
    """``_run_chunk`` compiled once per (system, mode, batched, argument structure and shapes);
    with ``batched`` every argument but the epochs has a leading batch axis. Returns
    (compiled function, seconds spent compiling: 0 on a cache hit). ``announce`` is called before
    a program is traced and compiled (or loaded from the persistent cache), not on a hit. Kept on
    disk in its exported form where the system qualifies (:func:`atlasnn.compile_cache.compiled_from_disk`):
    a later process loads it instead of tracing and lowering it again."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    sig = tuple((tuple(x.shape), str(x.dtype)) for x in leaves)
    key = (id(system), mode, batched, treedef, sig, trace_settings())
    hit = _CHUNK_CACHE.get(key)
    if hit is not None and hit[0] is system:
        return hit[1], 0.0
    if announce is not None:
        announce()
    start = time.perf_counter()

    def chunk(params, rest, opt_state, track, epochs, settings, key):
        return _run_chunk(params, rest, opt_state, track, epochs, settings, key, system=system, mode=mode)

    if batched:
        chunk = jax.vmap(chunk, in_axes=(0, 0, 0, 0, None, 0, 0))
    fn = jax.jit(chunk)
    params, _, opt_state, track = args[:4]
    out_tree = jax.tree_util.tree_structure((params, opt_state, track, dict.fromkeys(_CHUNK_OUTPUTS, 0)))
    compiled = compile_training_program(fn, args, system, key={"mode": repr(mode), "batched": batched},
                                        out_tree=out_tree, prefix="adam")
    elapsed = time.perf_counter() - start
    _CHUNK_CACHE[key] = (system, compiled)
    return compiled, elapsed


def run_settings(cfg, model: TrialSolution, system: HamiltonianSystem, T: float,
                 energy0: float | None, dtype) -> dict[str, jax.Array]:
    """The traced values of a run (a second run with other values reuses the compiled step)."""
    t0 = float(model.t0)
    tol = cfg.tolerance if cfg.tolerance is not None else -1.0
    start = math.floor(cfg.best_start_fraction * cfg.epochs)
    if cfg.best_rule == "release_exact":  # the release's test is epoch > fraction × budget
        start += 1
    return {
        "grid": uniform_grid(t0, T, cfg.n_points, dtype),
        "t0": on_device(t0, dtype),
        "T": on_device(T, dtype),
        "sigma": on_device(cfg.sigma, dtype),
        "energy0": on_device(system.energy(model.z0) if energy0 is None else energy0, dtype),
        "lam_reg": on_device(cfg.lam_reg, dtype),
        "tolerance": on_device(tol, dtype),
        "budget": on_device(cfg.epochs, jnp.int32),
        "best_start": on_device(int(start), jnp.int32),
        "lr": on_device(cfg.lr, dtype),
        "causal_eps": on_device(cfg.causal_eps, dtype),
        "train_gamma": on_device(not cfg.freeze_gamma, bool),
    }

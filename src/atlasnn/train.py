"""The training loop: Adam on the physics loss, many epochs per compiled call.

One host call runs ``chunk`` epochs inside ``lax.scan``; inside it every epoch draws its
jittered collocation times, evaluates the loss and its gradient, updates the parameters and
keeps the running bookkeeping (best parameters, tolerance, divergence) on the device. The host
looks at the result once per chunk (progress bar, stopping). Histories come back per chunk.

Stopping: at the epoch budget, or at the first epoch whose loss ≤ tolerance (the parameters of
that epoch are returned), or at the first non-finite loss (divergence: the lowest-loss finite
parameters seen are returned).

Which parameters are returned when the budget runs out (``best_rule``):

- ``"release"`` (default, as in the authors' release): the lowest-loss parameters seen in the
  last 20% of the budget (epochs ≥ ``best_start_fraction`` × budget);
- ``"lowest"``: the lowest-loss parameters seen in the whole run;
- ``"last"``: the parameters after the final update;
- ``"release_exact"``: what the authors' release does, to the letter (SPEC §8 / docs/METHOD.md):
  the parameters *after* the update of the epoch with the lowest loss (measured before that
  update) among epochs e > ``best_start_fraction`` × budget, with a running threshold that starts
  at 1 (if no loss in that window falls below 1, the initial parameters are returned); the
  tolerance test is ``loss < tolerance`` (strict) and also returns the post-update parameters.

Options that change what one epoch does (all off by default):

- ``lr_schedule``: ``"constant"``, or ``"cosine"`` / ``"exponential"`` decay (Optax schedules) from
  ``lr`` at epoch 0 to ``lr × lr_final_ratio`` at the end of the epoch budget;
- ``causal_eps`` > 0: causal weighting of the per-point loss (:func:`atlasnn.loss.causal_physics_loss`);
  the recorded loss, the tolerance and the best rule use the unweighted physics loss;
- ``release_fixed_point``: one collocation time pinned at t0 + 1 every epoch, as in the release.

Freezing γ uses Equinox partitioning: a frozen γ is not a trainable leaf at all, so it cannot
change (bit-identical after training).

The run is deterministic: the network initialisation is the model's; the jitter of epoch e uses
``fold_in(PRNGKey(seed), e)``, so the same seed and config give the same losses, and a run
resumed from a saved :class:`TrainState` continues exactly where it stopped.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from atlasnn.collocation import check_interval, jittered, uniform_grid, with_release_fixed_point
from atlasnn.errors import ConfigError
from atlasnn.loss import causal_physics_loss, physics_loss
from atlasnn.model import TrialSolution
from atlasnn.systems import HamiltonianSystem

BEST_RULES = ("release", "lowest", "last", "release_exact")
LR_SCHEDULES = ("constant", "cosine", "exponential")

# One Adam transformation for every run; lr and betas live in its state (inject_hyperparams),
# so runs with other hyperparameters reuse the same compiled step.
_ADAM = optax.inject_hyperparams(optax.adam)(learning_rate=1e-3, b1=0.9, b2=0.999, eps=1e-8)


@dataclass(frozen=True)
class TrainConfig:
    """Everything that controls one training run (interval aside).

    The defaults are a usable general setting; the paper's experiments set theirs in configs.
    ``betas`` default to Adam's usual (0.9, 0.999); the authors' release used (0.999, 0.9999).
    ``sigma`` is the jitter scale in units of the grid spacing Δt (0 switches jitter off).
    """

    epochs: int = 10_000
    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.999)
    lam_reg: float = 1.0
    n_points: int = 200
    sigma: float = 0.0
    tolerance: float | None = None
    best_rule: str = "release"
    best_start_fraction: float = 0.8
    freeze_gamma: bool = False
    seed: int = 0
    chunk: int = 1000
    progress: bool = True
    lr_schedule: str = "constant"
    lr_final_ratio: float = 0.01
    causal_eps: float = 0.0
    release_fixed_point: bool = False

    def __post_init__(self) -> None:
        def bad(name, value, why):
            raise ConfigError(f"train.{name} {why}, got {value!r}")

        def is_int(v):
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        def is_num(v):
            return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)

        if not is_int(self.epochs) or self.epochs < 1:
            bad("epochs", self.epochs, "must be an integer >= 1")
        if not is_num(self.lr) or self.lr <= 0:
            bad("lr", self.lr, "must be a finite number > 0")
        if (
            not isinstance(self.betas, (tuple, list)) or len(self.betas) != 2
            or not all(is_num(b) and 0 <= b < 1 for b in self.betas)
        ):
            bad("betas", self.betas, "must be two numbers in [0, 1)")
        object.__setattr__(self, "betas", tuple(float(b) for b in self.betas))
        if not is_num(self.lam_reg) or self.lam_reg < 0:
            bad("lam_reg", self.lam_reg, "must be a finite number >= 0")
        if not is_int(self.n_points) or self.n_points < 2:
            bad("n_points", self.n_points, "must be an integer >= 2")
        if not is_num(self.sigma) or self.sigma < 0:
            bad("sigma", self.sigma, "must be a finite number >= 0")
        if self.tolerance is not None and (not is_num(self.tolerance) or self.tolerance < 0):
            bad("tolerance", self.tolerance, "must be a finite number >= 0 (or absent)")
        if self.best_rule not in BEST_RULES:
            bad("best_rule", self.best_rule, f"must be one of {list(BEST_RULES)}")
        if not is_num(self.best_start_fraction) or not 0 <= self.best_start_fraction <= 1:
            bad("best_start_fraction", self.best_start_fraction, "must be in [0, 1]")
        if not is_int(self.seed) or self.seed < 0:
            bad("seed", self.seed, "must be an integer >= 0")
        if not is_int(self.chunk) or self.chunk < 1:
            bad("chunk", self.chunk, "must be an integer >= 1")
        if self.lr_schedule not in LR_SCHEDULES:
            bad("lr_schedule", self.lr_schedule, f"must be one of {list(LR_SCHEDULES)}")
        if not is_num(self.lr_final_ratio) or not 0 < self.lr_final_ratio <= 1:
            bad("lr_final_ratio", self.lr_final_ratio, "must be in (0, 1]")
        if not is_num(self.causal_eps) or self.causal_eps < 0:
            bad("causal_eps", self.causal_eps, "must be a finite number >= 0")
        if not isinstance(self.release_fixed_point, bool):
            bad("release_fixed_point", self.release_fixed_point, "must be true or false")
        if self.release_fixed_point and self.n_points < 3:
            bad("n_points", self.n_points, "must be >= 3 with release_fixed_point (it pins the third point)")

    def replace(self, **changes: Any) -> "TrainConfig":
        return dataclasses.replace(self, **changes)


@dataclass
class History:
    """Per-epoch records: total loss, Hamilton residual term, energy penalty, and γ."""

    loss: np.ndarray
    residual: np.ndarray
    energy: np.ndarray
    gamma: np.ndarray  # (epochs, n_gamma)
    gamma_names: tuple[str, ...] = ()

    @classmethod
    def empty(cls, gamma_names: tuple[str, ...]) -> "History":
        z = np.zeros((0,), np.float64)
        return cls(z, z, z, np.zeros((0, len(gamma_names))), tuple(gamma_names))

    def extend(self, other: dict[str, np.ndarray], n: int) -> "History":
        return History(
            np.concatenate([self.loss, other["loss"][:n]]),
            np.concatenate([self.residual, other["residual"][:n]]),
            np.concatenate([self.energy, other["energy"][:n]]),
            np.concatenate([self.gamma, other["gamma"][:n]]),
            self.gamma_names,
        )

    def __len__(self) -> int:
        return int(self.loss.shape[0])

    def as_dict(self) -> dict[str, Any]:
        out = {"loss": self.loss, "residual": self.residual, "energy": self.energy}
        for i, name in enumerate(self.gamma_names):
            out[f"gamma_{name}"] = self.gamma[:, i]
        return out


@dataclass
class TrainState:
    """Everything needed to continue a run: the model, Adam's state and the bookkeeping."""

    model: TrialSolution
    opt_state: Any
    track: dict[str, Any]  # device-side bookkeeping (best params, flags); see _initial_track
    epoch: int  # the next epoch to run
    history: History


@dataclass
class TrainResult:
    """What a training run returns.

    ``model`` holds the returned parameters (per ``best_rule``, tolerance or divergence);
    ``final_model`` the parameters after the last update; ``state`` can resume the run.
    """

    model: TrialSolution
    history: History
    epochs_run: int
    tolerance_met: bool
    stop_reason: str  # "budget" | "tolerance" | "diverged" | "interrupted"
    best_epoch: int  # the epoch whose parameters ``model`` holds (-1: after the last update)
    wall_time: float
    compile_time: float
    config: TrainConfig
    interval: tuple[float, float]
    state: TrainState
    diverged_epoch: int | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def final_loss(self) -> float:
        return float(self.history.loss[-1]) if len(self.history) else float("nan")

    @property
    def best_loss(self) -> float:
        return float(self.state.track["best_loss"])

    @property
    def final_model(self) -> TrialSolution:
        return self.state.model

    @property
    def opt_state(self) -> Any:
        return self.state.opt_state

    @property
    def epochs_per_second(self) -> float:
        return self.epochs_run / self.wall_time if self.wall_time > 0 else float("nan")


# --------------------------------------------------------------------------- helpers
def trainable_filter(model: TrialSolution, freeze_gamma: bool) -> TrialSolution:
    """A bool tree: network weights always trainable, γ unless frozen, z0 never."""
    spec = jax.tree_util.tree_map(lambda _: False, model)
    spec = eqx.tree_at(lambda m: m.net, spec, jax.tree_util.tree_map(eqx.is_inexact_array, model.net))
    if not freeze_gamma:
        spec = eqx.tree_at(
            lambda m: m.scaling, spec, jax.tree_util.tree_map(eqx.is_inexact_array, model.scaling)
        )
    return spec


def _set_hyperparams(opt_state, cfg: TrainConfig, dtype):
    hp = dict(opt_state.hyperparams)
    hp["learning_rate"] = jnp.asarray(cfg.lr, dtype)
    hp["b1"] = jnp.asarray(cfg.betas[0], dtype)
    hp["b2"] = jnp.asarray(cfg.betas[1], dtype)
    return opt_state._replace(hyperparams=hp)


def init_opt_state(params, cfg: TrainConfig, dtype):
    """Adam's state for ``params`` with the config's lr and betas."""
    return _set_hyperparams(_ADAM.init(params), cfg, dtype)


def _initial_track(params, dtype, threshold: float = math.inf) -> dict[str, Any]:
    """The trainer's device-side bookkeeping; ``threshold`` is the best rule's starting loss
    (∞, or 1 for ``release_exact``, whose ``best_params`` then start as the initial ones)."""
    inf = jnp.asarray(jnp.inf, dtype)
    return {
        "best_params": params,  # per best_rule
        "best_loss": jnp.asarray(threshold, dtype),
        "best_epoch": jnp.asarray(-1, jnp.int32),
        "any_params": params,  # lowest finite loss over the whole run (divergence fallback)
        "any_loss": inf,
        "any_epoch": jnp.asarray(-1, jnp.int32),
        "stop": jnp.asarray(0, jnp.int32),  # 0 running, 1 tolerance met, 2 diverged
        "stop_epoch": jnp.asarray(-1, jnp.int32),
    }


def _select(pred, a, b):
    return jax.tree_util.tree_map(lambda x, y: jnp.where(pred, x, y), a, b)


@dataclass(frozen=True)
class _Mode:
    """The parts of a config that change the compiled epoch (the rest are traced values)."""

    rule: str  # "release" | "lowest" | "release_exact" ("last" trains as "lowest")
    schedule: str
    lr_final_ratio: float
    causal: bool
    fixed_point: bool

    @classmethod
    def of(cls, cfg: "TrainConfig") -> "_Mode":
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


def _collocation(settings, key, epoch, mode: _Mode):
    t0, T = settings["t0"], settings["T"]
    t = jittered(settings["grid"], jax.random.fold_in(key, epoch), settings["sigma"], t0, T)
    if mode.fixed_point:
        t = with_release_fixed_point(t, t0, T)
    return jnp.sort(t) if mode.causal else t


def _objective(mode: _Mode, settings, rest, system):
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


def _run_chunk(params, rest, opt_state, track, epochs, settings, key, system, mode: _Mode):
    """Run the epochs in ``epochs`` (shape (chunk,)); a compiled unit (see ``_compiled_chunk``)."""
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
        gamma = eqx.combine(p, rest).scaling.gamma_array()
        if mode.schedule != "constant":
            progress = epoch.astype(dtype) / settings["budget"].astype(dtype)
            hp = dict(o.hyperparams)
            hp["learning_rate"] = settings["lr"] * mode.lr_factor(progress).astype(dtype)
            o = o._replace(hyperparams=hp)
        updates, o_new = _ADAM.update(grads, o, p)
        p_new = eqx.apply_updates(p, updates)
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
        return jax.lax.cond(running, one_epoch, skipped, carry, epoch)

    (params, opt_state, track), (loss, res, en, gamma) = jax.lax.scan(
        body, (params, opt_state, track), epochs
    )
    return params, opt_state, track, {"loss": loss, "residual": res, "energy": en, "gamma": gamma}


_CHUNK_CACHE: dict[Any, Any] = {}


def _compiled_chunk(args: tuple, system: HamiltonianSystem, mode: _Mode):
    """Compile ``_run_chunk`` once per (system, mode, argument structure and shapes)."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    sig = tuple((tuple(x.shape), str(x.dtype)) for x in leaves)
    key = (id(system), mode, treedef, sig, jax.config.read("jax_enable_x64"))
    hit = _CHUNK_CACHE.get(key)
    if hit is not None and hit[0] is system:
        return hit[1], 0.0
    start = time.perf_counter()
    fn = jax.jit(lambda *a: _run_chunk(*a, system=system, mode=mode))
    compiled = fn.lower(*args).compile()
    elapsed = time.perf_counter() - start
    _CHUNK_CACHE[key] = (system, compiled)
    return compiled, elapsed


def _progress_bar(enabled: bool, total: int, initial: int, desc: str):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="ep", dynamic_ncols=True, leave=True)


def _settings(cfg: TrainConfig, model: TrialSolution, system: HamiltonianSystem, T: float,
              energy0: float | None, dtype) -> dict[str, jax.Array]:
    """The traced values of a run (a second run with other values reuses the compiled step)."""
    t0 = float(model.t0)
    tol = cfg.tolerance if cfg.tolerance is not None else -1.0
    start = math.floor(cfg.best_start_fraction * cfg.epochs)
    if cfg.best_rule == "release_exact":  # the release's test is epoch > fraction × budget
        start += 1
    return {
        "grid": uniform_grid(t0, T, cfg.n_points, dtype),
        "t0": jnp.asarray(t0, dtype),
        "T": jnp.asarray(T, dtype),
        "sigma": jnp.asarray(cfg.sigma, dtype),
        "energy0": jnp.asarray(system.energy(model.z0) if energy0 is None else energy0, dtype),
        "lam_reg": jnp.asarray(cfg.lam_reg, dtype),
        "tolerance": jnp.asarray(tol, dtype),
        "budget": jnp.asarray(cfg.epochs, jnp.int32),
        "best_start": jnp.asarray(int(start), jnp.int32),
        "lr": jnp.asarray(cfg.lr, dtype),
        "causal_eps": jnp.asarray(cfg.causal_eps, dtype),
    }


# ------------------------------------------------------------------------------ train
def train(
    model: TrialSolution,
    system: HamiltonianSystem,
    T: float,
    config: TrainConfig = TrainConfig(),
    *,
    opt_state: Any = None,
    resume: TrainState | None = None,
    desc: str = "train",
    on_chunk: Callable[[TrainState], None] | None = None,
    energy0: float | None = None,
) -> TrainResult:
    """Train ``model`` on [model.t0, T] and return a :class:`TrainResult`.

    Args:
        model: the trial solution to train (its z0 and t0 define the problem).
        system: the Hamiltonian system.
        T: the end of the training interval.
        config: epochs, lr, betas, λ_reg, K, jitter σ, tolerance, best rule, γ freezing, seed.
        opt_state: an Adam state to start from (transfer carries the source's); must match the
            trainable parameters. Its lr and betas are replaced by the config's.
        resume: a :class:`TrainState` from an earlier, interrupted run of the same config.
        desc: label of the progress bar.
        on_chunk: called with the current :class:`TrainState` after every chunk (checkpointing).
        energy0: the energy E0 of the penalty term; default H(model.z0). Time-marching passes the
            energy of the problem's initial state, so that window after window is held to it.

    Ctrl-C between epochs stops the run cleanly: the result has ``stop_reason="interrupted"``
    and a ``state`` to resume from.
    """
    cfg = config
    t0 = float(model.t0)
    check_interval(t0, float(T), cfg.n_points)
    if model.state_dim != system.state_dim:
        raise ConfigError(
            f"model state dimension {model.state_dim} does not match system {system.name!r} "
            f"(2d = {system.state_dim})"
        )
    dtype = model.z0.dtype
    gamma_names = tuple(model.scaling.gamma_names)

    if resume is not None:
        model = resume.model
    spec = trainable_filter(model, cfg.freeze_gamma)
    params, rest = eqx.partition(model, spec)
    if resume is not None:
        opt_state, track, start_epoch, history = resume.opt_state, resume.track, resume.epoch, resume.history
    else:
        if opt_state is None:
            opt_state = init_opt_state(params, cfg, dtype)
        else:
            try:
                opt_state = _set_hyperparams(opt_state, cfg, dtype)
                if jax.tree_util.tree_structure(opt_state.inner_state[0].mu) != jax.tree_util.tree_structure(params):
                    raise ValueError
            except (AttributeError, ValueError, IndexError, TypeError):
                raise ConfigError("opt_state does not match the trainable parameters of this model") from None
        track = _initial_track(params, dtype, 1.0 if cfg.best_rule == "release_exact" else math.inf)
        start_epoch, history = 0, History.empty(gamma_names)

    mode = _Mode.of(cfg)
    settings = _settings(cfg, model, system, float(T), energy0, dtype)
    key = jax.random.PRNGKey(cfg.seed)
    epochs0 = jnp.arange(cfg.chunk, dtype=jnp.int32)
    compiled, compile_time = _compiled_chunk((params, rest, opt_state, track, epochs0, settings, key), system, mode)

    bar = _progress_bar(cfg.progress, cfg.epochs, start_epoch, desc)
    epoch = start_epoch
    interrupted = False
    start = time.perf_counter()
    try:
        while epoch < cfg.epochs and int(track["stop"]) == 0:
            epochs = jnp.arange(epoch, epoch + cfg.chunk, dtype=jnp.int32)
            params, opt_state, track, hist = compiled(params, rest, opt_state, track, epochs, settings, key)
            hist = jax.device_get(hist)
            stop = int(track["stop"])
            n = min(cfg.chunk, cfg.epochs - epoch)
            if stop:
                n = int(track["stop_epoch"]) - epoch + 1
            history = history.extend(hist, n)
            epoch += n
            if bar is not None:
                bar.update(n)
                post = {"loss": f"{history.loss[-1]:.3e}"}
                for i, g in enumerate(gamma_names):
                    post[g] = f"{history.gamma[-1, i]:.4f}"
                bar.set_postfix(post, refresh=False)
            if on_chunk is not None:
                on_chunk(TrainState(eqx.combine(params, rest), opt_state, track, epoch, history))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - start

    stop = int(track["stop"])
    final_model = eqx.combine(params, rest)
    state = TrainState(final_model, opt_state, track, epoch, history)
    diverged_epoch = None
    if interrupted:
        reason = "interrupted"
        chosen, best_epoch = final_model, -1
    elif stop == 1:
        reason, chosen, best_epoch = "tolerance", final_model, int(track["stop_epoch"])
    elif stop == 2:
        reason, diverged_epoch = "diverged", int(track["stop_epoch"])
        chosen = eqx.combine(track["any_params"], rest)
        best_epoch = int(track["any_epoch"])
    else:
        reason = "budget"
        if cfg.best_rule == "release_exact":  # the initial parameters when no loss fell below 1
            chosen, best_epoch = eqx.combine(track["best_params"], rest), int(track["best_epoch"])
        elif cfg.best_rule == "last" or int(track["best_epoch"]) < 0:
            chosen, best_epoch = final_model, -1
        else:
            chosen, best_epoch = eqx.combine(track["best_params"], rest), int(track["best_epoch"])
    return TrainResult(
        model=chosen,
        history=history,
        epochs_run=epoch,
        tolerance_met=stop == 1,
        stop_reason=reason,
        best_epoch=best_epoch,
        wall_time=wall,
        compile_time=compile_time,
        config=cfg,
        interval=(t0, float(T)),
        state=state,
        diverged_epoch=diverged_epoch,
    )

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
- ``causal_eps`` > 0: causal weighting of the per-point loss (:func:`atlasnn.training._loss.causal_physics_loss`);
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
from typing import Any, Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.training._collocation import check_interval
from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.systems import HamiltonianSystem
from atlasnn.training._step import (
    Mode,
    compiled_chunk,
    init_opt_state,
    initial_track,
    run_settings,
    set_hyperparams,
    trainable_filter,
)

BEST_RULES = ("release", "lowest", "last", "release_exact")
LR_SCHEDULES = ("constant", "cosine", "exponential")

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
    track: dict[str, Any]  # device-side bookkeeping (best params, flags); see training._step.initial_track
    epoch: int  # the next epoch to run
    history: History


def state_template(model: TrialSolution, config: "TrainConfig") -> TrainState:
    """An empty :class:`TrainState` of ``model`` under ``config``: the structure (trainable
    partition, Adam state, bookkeeping) a saved state is restored into."""
    params, _ = eqx.partition(model, trainable_filter(model, config.freeze_gamma))
    dtype = model.z0.dtype
    return TrainState(model=model, opt_state=init_opt_state(params, config, dtype),
                      track=initial_track(params, dtype), epoch=0,
                      history=History.empty(tuple(model.scaling.gamma_names)))


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


def _progress_bar(enabled: bool, total: int, initial: int, desc: str):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="ep", dynamic_ncols=True, leave=True)


def _stack(trees: Sequence[Any]) -> Any:
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *trees)


def _unstack(tree: Any, i: int) -> Any:
    return jax.tree_util.tree_map(lambda x: x[i], tree)


@dataclass
class _Run:
    """Host-side state of one run of a batch (parameters live in the stacked device arrays)."""

    cfg: TrainConfig
    T: float
    history: History
    epoch: int  # the next epoch to run
    active: bool


def _start(model, system, T, cfg, opt_state, resume, energy0, index):
    """(params, rest, opt_state, track, settings, key, _Run) of one run, checked."""
    check_interval(float(model.t0), float(T), cfg.n_points)
    if model.state_dim != system.state_dim:
        raise ConfigError(
            f"model state dimension {model.state_dim} does not match system {system.name!r} "
            f"(2d = {system.state_dim})"
        )
    dtype = model.z0.dtype
    if resume is not None:
        model = resume.model
    params, rest = eqx.partition(model, trainable_filter(model, cfg.freeze_gamma))
    if resume is not None:
        opt_state, track, epoch, history = resume.opt_state, resume.track, resume.epoch, resume.history
    else:
        if opt_state is None:
            opt_state = init_opt_state(params, cfg, dtype)
        else:
            try:
                opt_state = set_hyperparams(opt_state, cfg, dtype)
                if jax.tree_util.tree_structure(opt_state.inner_state[0].mu) != jax.tree_util.tree_structure(params):
                    raise ValueError
            except (AttributeError, ValueError, IndexError, TypeError):
                where = "" if index is None else f" (run {index} of the batch)"
                raise ConfigError(f"opt_state does not match the trainable parameters of this model{where}") from None
        track = initial_track(params, dtype, 1.0 if cfg.best_rule == "release_exact" else math.inf)
        epoch, history = 0, History.empty(tuple(model.scaling.gamma_names))
    settings = run_settings(cfg, model, system, float(T), energy0, dtype)
    active = epoch < cfg.epochs and int(track["stop"]) == 0
    run = _Run(cfg, float(T), history, epoch, active)
    return params, rest, opt_state, track, settings, jax.random.PRNGKey(cfg.seed), run


def _check_batch(runs: list[_Run], rests: list[Any]) -> None:
    """Runs trained as one program must agree on what is compiled and on the host loop."""
    first = runs[0].cfg
    for i, r in enumerate(runs[1:], 1):
        for name in ("n_points", "chunk", "freeze_gamma"):
            if getattr(r.cfg, name) != getattr(first, name):
                raise ConfigError(f"runs trained as one batch must share train.{name}: run {i} has "
                                  f"{getattr(r.cfg, name)!r}, run 0 has {getattr(first, name)!r}")
        if Mode.of(r.cfg) != Mode.of(first):
            raise ConfigError(f"runs trained as one batch must share best_rule, lr_schedule, lr_final_ratio, "
                              f"causal weighting and release_fixed_point (run {i} differs from run 0)")
    shapes = [jax.tree_util.tree_structure(x) for x in rests]
    if any(s != shapes[0] for s in shapes[1:]):
        raise ConfigError("models trained as one batch must have the same architecture, scaling and t0")
    running = {r.epoch for r in runs if r.active}
    if len(running) > 1:
        raise ConfigError(f"resumed runs of one batch are at different epochs {sorted(running)}; resume them separately")


def _result(run: _Run, params, rest, opt_state, track, interrupted: bool, wall: float,
            compile_time: float, t0: float, batch: int) -> TrainResult:
    """The TrainResult of one run from its final device state (see the module docstring)."""
    cfg = run.cfg
    stop = int(track["stop"])
    final_model = eqx.combine(params, rest)
    state = TrainState(final_model, opt_state, track, run.epoch, run.history)
    diverged_epoch = None
    if interrupted and run.active:
        reason, chosen, best_epoch = "interrupted", final_model, -1
    elif stop == 1:
        reason, chosen, best_epoch = "tolerance", final_model, int(track["stop_epoch"])
    elif stop == 2:
        reason, diverged_epoch = "diverged", int(track["stop_epoch"])
        chosen, best_epoch = eqx.combine(track["any_params"], rest), int(track["any_epoch"])
    else:
        reason = "budget"
        if cfg.best_rule == "release_exact":  # the initial parameters when no loss fell below 1
            chosen, best_epoch = eqx.combine(track["best_params"], rest), int(track["best_epoch"])
        elif cfg.best_rule == "last" or int(track["best_epoch"]) < 0:
            chosen, best_epoch = final_model, -1
        else:
            chosen, best_epoch = eqx.combine(track["best_params"], rest), int(track["best_epoch"])
    info = {"batch_size": batch, "batch_wall_time": wall} if batch > 1 else {}
    return TrainResult(
        model=chosen, history=run.history, epochs_run=run.epoch, tolerance_met=stop == 1,
        stop_reason=reason, best_epoch=best_epoch, wall_time=wall / batch, compile_time=compile_time,
        config=cfg, interval=(t0, run.T), state=state, diverged_epoch=diverged_epoch, info=info,
    )


def _advance(runs: list[_Run], hist: dict, track: dict, epoch: int, batched: bool) -> int:
    """Append one chunk's history to every run still active; returns the epochs advanced."""
    stops, stop_epochs = np.atleast_1d(jax.device_get(track["stop"])), np.atleast_1d(jax.device_get(track["stop_epoch"]))
    advanced = 0
    for i, run in enumerate(runs):
        if not run.active:
            continue
        n = min(run.cfg.chunk, run.cfg.epochs - epoch)
        if stops[i]:
            n = int(stop_epochs[i]) - epoch + 1
        run.history = run.history.extend(_unstack(hist, i) if batched else hist, n)
        run.epoch = epoch + n
        run.active = run.epoch < run.cfg.epochs and not stops[i]
        advanced = max(advanced, n)
    return advanced


def _postfix(runs: list[_Run]) -> dict[str, str]:
    if len(runs) == 1:
        h = runs[0].history
        post = {"loss": f"{h.loss[-1]:.3e}"}
        post.update({g: f"{h.gamma[-1, i]:.4f}" for i, g in enumerate(h.gamma_names)})
        return post
    last = [r.history.loss[-1] for r in runs if len(r.history)]
    return {"loss": f"{np.nanmedian(last):.3e} (median)", "running": f"{sum(r.active for r in runs)}/{len(runs)}"}


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
    callback = None if on_chunk is None else (lambda states: on_chunk(states[0]))
    return train_batch([model], system, T, [config], opt_states=[opt_state], resumes=[resume],
                       desc=desc, on_chunk=callback, energy0=energy0)[0]


def train_batch(
    models: Sequence[TrialSolution],
    system: HamiltonianSystem,
    T: float | Sequence[float],
    configs: Sequence[TrainConfig],
    *,
    opt_states: Sequence[Any] | None = None,
    resumes: Sequence[TrainState | None] | None = None,
    desc: str = "train",
    on_chunk: Callable[[list[TrainState]], None] | None = None,
    energy0: float | Sequence[float | None] | None = None,
) -> list[TrainResult]:
    """Train S models as ONE compiled program (``jax.vmap`` over a leading batch axis).

    Typically the S models are S seeds of one config (``configs[i] = cfg.replace(seed=i)``), but
    any runs that share the compiled program can be batched: same architecture, scaling and t0,
    the same ``n_points``, ``chunk``, ``freeze_gamma`` and :class:`~atlasnn.training._step.Mode`
    (best rule, schedule, causal weighting, fixed point); epochs, lr, betas, tolerance, jitter,
    λ_reg, seed, the interval end T, z0 and E0 may differ per run. Every run stops, keeps its
    best parameters and diverges on its own, exactly as :func:`train` would do it alone (the
    batched arithmetic may differ from a lone run in the last bits). ``T``, ``energy0``,
    ``opt_states`` and ``resumes`` are one value for all or one per run. ``on_chunk`` receives
    the list of current :class:`TrainState` after every chunk. A result's ``wall_time`` is its
    share of the batch's (batch wall time / S; ``info["batch_wall_time"]`` has the whole).
    """
    n = len(models)
    if n < 1 or len(configs) != n:
        raise ConfigError(f"train_batch needs one config per model, got {n} models and {len(configs)} configs")

    def per_run(value, what):
        if isinstance(value, (list, tuple)):
            if len(value) != n:
                raise ConfigError(f"train_batch: {what} has {len(value)} entries for {n} models")
            return list(value)
        return [value] * n

    Ts, e0s = per_run(T, "T"), per_run(energy0, "energy0")
    opts, resumes_ = per_run(opt_states, "opt_states"), per_run(resumes, "resumes")
    parts = [_start(m, system, t, c, o, r, e, i if n > 1 else None)
             for i, (m, t, c, o, r, e) in enumerate(zip(models, Ts, configs, opts, resumes_, e0s))]
    params, rests, opt_state, track, settings, keys, runs = (list(x) for x in zip(*parts))
    _check_batch(runs, rests)
    batched = n > 1
    args = [params, rests, opt_state, track, settings, keys]
    params, rest, opt_state, track, settings, key = (_stack(a) if batched else a[0] for a in args)
    cfg0 = runs[0].cfg
    epoch = max((r.epoch for r in runs if r.active), default=max(r.epoch for r in runs))
    epochs0 = jnp.arange(cfg0.chunk, dtype=jnp.int32)
    compiled, compile_time = compiled_chunk((params, rest, opt_state, track, epochs0, settings, key),
                                            system, Mode.of(cfg0), batched)

    def states() -> list[TrainState]:
        if not batched:
            return [TrainState(eqx.combine(params, rest), opt_state, track, runs[0].epoch, runs[0].history)]
        return [TrainState(eqx.combine(_unstack(params, i), _unstack(rest, i)), _unstack(opt_state, i),
                           _unstack(track, i), r.epoch, r.history) for i, r in enumerate(runs)]

    bar = _progress_bar(cfg0.progress, max(r.cfg.epochs for r in runs), epoch, desc)
    interrupted = False
    start = time.perf_counter()
    try:
        while any(r.active for r in runs):
            epochs = jnp.arange(epoch, epoch + cfg0.chunk, dtype=jnp.int32)
            params, opt_state, track, hist = compiled(params, rest, opt_state, track, epochs, settings, key)
            step = _advance(runs, jax.device_get(hist), track, epoch, batched)
            epoch += step
            if bar is not None:
                bar.update(step)
                bar.set_postfix(_postfix(runs), refresh=False)
            if on_chunk is not None:
                on_chunk(states())
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - start
    t0 = float(models[0].t0)
    if not batched:
        return [_result(runs[0], params, rest, opt_state, track, interrupted, wall, compile_time, t0, 1)]
    return [_result(r, _unstack(params, i), _unstack(rest, i), _unstack(opt_state, i), _unstack(track, i),
                    interrupted, wall, compile_time, t0, n) for i, r in enumerate(runs)]

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

Freezing γ: the compiled chunk has γ among its trainable leaves in every run and a traced flag
that zeroes its gradient and holds its value (bit for bit), so γ learned and γ frozen are one
program. Outside the loop a run's state keeps its own layout: with γ frozen, γ is not a
trainable leaf of the Adam state or the bookkeeping that a :class:`TrainState` holds, saves and
resumes from (Equinox partitioning, :func:`~atlasnn.training._step.trainable_filter`); it is
widened into the program's layout on entry and restricted again on the way out.

The run is deterministic: the network initialisation is the model's; the jitter of epoch e uses
``fold_in(PRNGKey(seed), e)``, so the same seed and config give the same losses, and a run
resumed from a saved :class:`TrainState` continues exactly where it stopped.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import equinox as eqx
import jax
import numpy as np

from atlasnn.training._collocation import check_interval
from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.precision import on_device
from atlasnn.solutions import stack_models, unstack_models
from atlasnn.systems import HamiltonianSystem
from atlasnn.training._records import History, TrainConfig, TrainResult, TrainState
from atlasnn.training._step import (
    Mode,
    compiled_chunk,
    gamma_filter,
    init_opt_state,
    initial_track,
    restrict_opt_state,
    run_settings,
    set_hyperparams,
    trainable_filter,
)


def _progress_bar(enabled: bool, total: int, initial: int, desc: str):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="ep", dynamic_ncols=True, leave=True)


def _announcer(enabled: bool, desc: str) -> Callable[[], None] | None:
    """A line before the epoch loop is compiled (seconds cold, more on a GPU), with progress on:
    without it nothing moves between the run's first line and the bar."""
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return lambda: tqdm.write(f"{desc}: compiling the epoch loop (or loading it from the cache)…", file=sys.stderr)


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


def _widen(tree, model, zeros: bool):
    """A parameter-shaped tree of a run's own layout in the program's (γ a trainable leaf):
    γ's missing leaves are the model's γ, or zeros (Adam's moments)."""
    gamma = eqx.filter(model, gamma_filter(model))
    if zeros:
        gamma = jax.tree_util.tree_map(lambda x: np.zeros(x.shape, x.dtype), gamma)
    return eqx.combine(tree, gamma)


def _widen_state(opt_state, track, model):
    adam, *others = opt_state.inner_state
    adam = adam._replace(mu=_widen(adam.mu, model, True), nu=_widen(adam.nu, model, True))
    track = {**track, "best_params": _widen(track["best_params"], model, False),
             "any_params": _widen(track["any_params"], model, False)}
    return opt_state._replace(inner_state=(adam, *others)), track


def _own_state(opt_state, track, model, freeze_gamma: bool):
    """The inverse of :func:`_widen_state`: Adam's state and the bookkeeping in the run's own
    layout (γ's leaves dropped when it is frozen)."""
    if not freeze_gamma:
        return opt_state, track
    spec = trainable_filter(model, True)
    track = {**track, "best_params": eqx.filter(track["best_params"], spec),
             "any_params": eqx.filter(track["any_params"], spec)}
    return restrict_opt_state(opt_state, model, True), track


def _start(model, system, T, cfg, opt_state, resume, energy0, index, memo):
    """(params, rest, opt_state, track, settings, key, _Run) of one run, checked. ``memo`` holds
    what runs of one batch can share (a fresh Adam state per parameter layout, H(z0) per z0): each
    is computed once, in the same way as for a lone run, so the values are the same."""
    check_interval(float(model.t0), float(T), cfg.n_points)
    if model.state_dim != system.state_dim:
        raise ConfigError(
            f"model state dimension {model.state_dim} does not match system {system.name!r} "
            f"(2d = {system.state_dim})"
        )
    dtype = model.z0.dtype
    if resume is not None:
        model = resume.model
    own, _ = eqx.partition(model, trainable_filter(model, cfg.freeze_gamma))
    params, rest = eqx.partition(model, trainable_filter(model, False))  # the program's layout
    if resume is not None:
        opt_state, track = _widen_state(resume.opt_state, resume.track, model)
        epoch, history = resume.epoch, resume.history
    else:
        if opt_state is None:
            layout = (jax.tree_util.tree_structure(params),
                      tuple((x.shape, str(x.dtype)) for x in jax.tree_util.tree_leaves(params)))
            if layout not in memo:
                memo[layout] = init_opt_state(params, cfg, dtype)
            opt_state = set_hyperparams(memo[layout], cfg, dtype)
        else:
            try:
                opt_state = set_hyperparams(opt_state, cfg, dtype)
                if jax.tree_util.tree_structure(opt_state.inner_state[0].mu) != jax.tree_util.tree_structure(own):
                    raise ValueError
            except (AttributeError, ValueError, IndexError, TypeError):
                where = "" if index is None else f" (run {index} of the batch)"
                raise ConfigError(f"opt_state does not match the trainable parameters of this model{where}") from None
            opt_state = _widen_state(opt_state, {"best_params": own, "any_params": own}, model)[0]
        track = initial_track(params, dtype, 1.0 if cfg.best_rule == "release_exact" else math.inf)
        epoch, history = 0, History.empty(tuple(model.scaling.gamma_names))
    if energy0 is None:  # H(z0) once per distinct z0 of the batch
        z0 = np.asarray(model.z0)
        key = ("energy0", z0.tobytes(), str(z0.dtype))
        if key not in memo:
            memo[key] = system.energy(model.z0)
        energy0 = memo[key]
    settings = run_settings(cfg, model, system, float(T), energy0, dtype)
    active = epoch < cfg.epochs and (resume is None or int(track["stop"]) == 0)
    run = _Run(cfg, float(T), history, epoch, active)
    return params, rest, opt_state, track, settings, jax.random.PRNGKey(cfg.seed), run


def _check_batch(runs: list[_Run], rests: list[Any]) -> None:
    """Runs trained as one program must agree on what is compiled and on the host loop."""
    first = runs[0].cfg
    for i, r in enumerate(runs[1:], 1):
        for name in ("n_points", "chunk"):
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
    state = TrainState(final_model, *_own_state(opt_state, track, final_model, cfg.freeze_gamma),
                       run.epoch, run.history)
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
    """Train ``model`` on [model.t0, T] and return a [`TrainResult`][atlasnn.training.TrainResult].

    Args:
        model: the trial solution to train (its z0 and t0 define the problem).
        system: the Hamiltonian system.
        T: the end of the training interval.
        config: epochs, lr, betas, λ_reg, K, jitter σ, tolerance, best rule, γ freezing, seed.
        opt_state: an Adam state to start from (transfer carries the source's); must match the
            trainable parameters. Its lr and betas are replaced by the config's.
        resume: a ``TrainState`` from an earlier, interrupted run of the same config.
        desc: label of the progress bar.
        on_chunk: called with the current ``TrainState`` after every chunk (checkpointing).
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
    the same ``n_points``, ``chunk`` and :class:`~atlasnn.training._step.Mode` (best rule,
    schedule, causal weighting, fixed point); epochs, lr, betas, tolerance, jitter, λ_reg, seed,
    ``freeze_gamma``, the interval end T, z0 and E0 may differ per run. Every run stops, keeps its
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
    memo: dict[Any, Any] = {}
    parts = [_start(m, system, t, c, o, r, e, i if n > 1 else None, memo)
             for i, (m, t, c, o, r, e) in enumerate(zip(models, Ts, configs, opts, resumes_, e0s))]
    params, rests, opt_state, track, settings, keys, runs = (list(x) for x in zip(*parts))
    _check_batch(runs, rests)
    batched = n > 1
    args = [params, rests, opt_state, track, settings, keys]
    params, rest, opt_state, track, settings, key = (stack_models(a) if batched else a[0] for a in args)
    cfg0 = runs[0].cfg
    epoch = max((r.epoch for r in runs if r.active), default=max(r.epoch for r in runs))
    epochs0 = on_device(np.arange(cfg0.chunk), np.int32)
    compiled, compile_time = compiled_chunk((params, rest, opt_state, track, epochs0, settings, key),
                                            system, Mode.of(cfg0), batched, announce=_announcer(cfg0.progress, desc))

    def states() -> list[TrainState]:
        def one(r, model, o, tr):
            return TrainState(model, *_own_state(o, tr, model, r.cfg.freeze_gamma), r.epoch, r.history)

        if not batched:
            return [one(runs[0], eqx.combine(params, rest), opt_state, track)]
        each = zip(unstack_models(params, n), unstack_models(opt_state, n), unstack_models(track, n))
        return [one(r, eqx.combine(p, rests[i]), o, tr) for i, (r, (p, o, tr)) in enumerate(zip(runs, each))]

    bar = _progress_bar(cfg0.progress, max(r.cfg.epochs for r in runs), epoch, desc)
    interrupted = False
    start = time.perf_counter()
    try:
        while any(r.active for r in runs):
            epochs = on_device(np.arange(epoch, epoch + cfg0.chunk), np.int32)
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
    each = zip(unstack_models(params, n), unstack_models(opt_state, n), unstack_models(track, n))
    return [_result(r, p, rests[i], o, tr, interrupted, wall, compile_time, t0, n)
            for i, (r, (p, o, tr)) in enumerate(zip(runs, each))]

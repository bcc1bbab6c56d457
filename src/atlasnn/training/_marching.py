"""Time-marching (windowed) ATLAS-NN: the paper's transfer, applied window after window.

The interval [t0, T] is split into n windows of equal length w (:func:`~atlasnn.solutions._piecewise.window_edges`).
Window k is an ordinary trial solution on its local time s = t − t_k ∈ [0, w],

    ẑ_k(s) = z_k + f(s; γ) N_k(s; θ_k),    z_0 = the problem's z0,  z_{k+1} = ẑ_k(w),

exact at its own start (a hard constraint: no continuity penalty). Window 0 is trained from the
given model with γ learned; γ is then frozen (default) or thawed, and carried from window to
window, as the paper's transfer carries it from source to target. Each window is trained on its
own interval [0, w] with the energy penalty held to E0 = H(z0) of the whole problem, so energy
errors do not accumulate from window to window. Optionally every window is then polished by
L-BFGS (:mod:`atlasnn.training._polish`).

Where window k ≥ 1 starts its network θ (``MarchConfig.start``): from the given model's initial
θ (default), from the previous window's trained θ, or from the previous window's hidden layers
with a zeroed output layer. Measured (docs/runs/march-explore.md): the previous θ starts the
window on the previous trajectory shifted by z_k − z_{k−1}, a good start only when the window is
close to a multiple of the motion's period; on the oscillator with 2π windows it made L2(x)
6–21× worse than the initial θ, with the recommended 4π windows 2–6× worse (5 seeds), and on
Hénon–Heiles it was slightly better (median L2(x) 0.0031 against 0.0047).

Because every window has t0 = 0, the same K, the same shapes and traced settings, the compiled
training step is reused by all windows (window 1 compiles once more for the frozen-γ variant;
see :attr:`~atlasnn.solutions._piecewise.WindowRecord.compile_time`).

The result is one :class:`~atlasnn.solutions._piecewise.PiecewiseSolution` over [t0, T].
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
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.solutions import PiecewiseSolution, WindowRecord, window_edges
from atlasnn.training._lm import LMConfig, LMResult
from atlasnn.training._polish import PolishConfig, PolishResult
from atlasnn.training._progress import MarchProgress
from atlasnn.training._refine import refine
from atlasnn.systems import HamiltonianSystem
from atlasnn.training._records import TrainConfig, TrainResult
from atlasnn.training._train import train_batch
from atlasnn.training._step import restrict_opt_state

__all__ = ["MarchConfig", "march_batch", "n_windows_for", "window_model", "end_state", "window_seed"]

WINDOW_STARTS = ("initial", "previous", "features")

# Window k's jitter stream: seed + k × this (a prime), so windows do not repeat each other's draws.
_SEED_STRIDE = 7919

# The defaults below were chosen by measurement (docs/runs/march-explore.md): they meet the
# long-time targets of issue 10 on the nonlinear oscillator over [0, 20π] and Hénon–Heiles over
# [0, 24π] in every seed tried, without per-system tuning (λ_reg aside, which is the paper's).
DEFAULT_WINDOW = 4 * math.pi
#: The adaptive windows' default per-window tolerance: local error ≤ rtol × the state's range
#: (docs/SUITE.md: what it gives over the suite of hard problems).
DEFAULT_RTOL = 1e-5
# Each window: 2 000 Adam epochs, then a Levenberg–Marquardt phase. Measured against the round-2
# default of 16 000 Adam epochs alone (docs/ESTIMATE.md, "optimisation"): 10–100× lower max error
# on the oscillator over [0, 20π] and Hénon–Heiles over [0, 24π] at less training time.
DEFAULT_WINDOW_TRAIN = TrainConfig(
    epochs=2_000, lr=5e-3, betas=(0.9, 0.999), n_points=100, sigma=0.5, lr_schedule="cosine",
    lr_final_ratio=0.01, causal_eps=10.0, best_rule="lowest", chunk=2000,
)
DEFAULT_WINDOW_LM = LMConfig()
# The network the defaults were measured with: make_model(z0, **DEFAULT_NETWORK, seed=...).
DEFAULT_NETWORK = {"scaling": "rational_exp", "width": 48, "depth": 2, "activation": "sin",
                   "first_layer_scale": 4.0}


@dataclass(frozen=True)
class MarchConfig:
    """The time-marching scheme's settings.

    Windows: ``n_windows``, or ``window`` (the longest window length wanted: n = ⌈(T − t0)/window⌉,
    the windows then being (T − t0)/n long); at most one of them (neither: ``window`` =
    ``DEFAULT_WINDOW`` = 4π, the paper's oscillator source interval).
    ``train``: the Adam run of every window (its ``n_points`` and ``epochs`` are per window; its
    ``freeze_gamma`` is ignored: γ is learned in window 0 and frozen after unless ``thaw``);
    default ``DEFAULT_WINDOW_TRAIN``.
    ``first``: the first window's run, if it should differ (default: ``train``).
    ``thaw``: keep γ trainable after window 0.
    ``carry_adam``: start each window from the previous window's final Adam moments.
    ``start``: where window k ≥ 1 starts its θ: ``"initial"`` (default: the given model's θ, as
    window 0 did), ``"previous"`` (the previous window's trained θ: the paper's transfer, window
    to window) or ``"features"`` (the previous window's hidden layers with the output layer set
    to zero: its features are kept, its phase-specific output is not). γ is always the learned
    one (frozen, or thawed and carried on).
    ``polish``: the second phase of every window after Adam: Levenberg–Marquardt (an
    ``LMConfig``, the default), L-BFGS (a ``PolishConfig``) or none
    (``None``); its ``lam_reg`` is the window's; with its default ``freeze_gamma`` (true) every
    window refines θ only, so one compiled program serves all windows.
    Windows chosen by the error estimate (the default, ``window = "auto"``, see
    ``atlasnn.training._adaptive``): ``rtol``/``atol`` the local error tolerance of a window
    (``atol + rtol × the state's range``), ``first_window`` (default: one period of the fastest
    linear mode at z0), ``min_window`` (default (T − t0)·1e-4), ``max_rejects`` retrainings of one
    window, ``max_windows`` in all.
    """

    n_windows: int | None = None
    window: float | str | None = None
    train: TrainConfig = DEFAULT_WINDOW_TRAIN
    first: TrainConfig | None = None
    thaw: bool = False
    carry_adam: bool = True
    start: str = "initial"
    polish: PolishConfig | LMConfig | None = DEFAULT_WINDOW_LM
    rtol: float = DEFAULT_RTOL
    atol: float = 0.0
    first_window: float | None = None
    min_window: float | None = None
    max_rejects: int = 8
    max_windows: int = 10_000

    @property
    def adaptive(self) -> bool:
        """Whether the windows are chosen by the error estimate (``window = "auto"``, the default)."""
        return self.n_windows is None and self.window in (None, "auto")

    def __post_init__(self) -> None:
        if self.n_windows is not None and self.window is not None:
            raise ConfigError(
                f"march takes n_windows or window, not both; got n_windows={self.n_windows!r}, "
                f"window={self.window!r}"
            )
        if self.n_windows is not None and (
            isinstance(self.n_windows, bool) or not isinstance(self.n_windows, (int, np.integer)) or self.n_windows < 1
        ):
            raise ConfigError(f"march.n_windows must be an integer >= 1, got {self.n_windows!r}")
        if self.window not in (None, "auto") and (
            isinstance(self.window, bool) or not isinstance(self.window, (int, float))
            or not math.isfinite(self.window) or self.window <= 0
        ):
            raise ConfigError(f"march.window must be a finite number > 0 or \"auto\", got {self.window!r}")
        for name in ("rtol", "atol", "first_window", "min_window"):
            v = getattr(self, name)
            if v is None and name in ("first_window", "min_window"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0 or (
                    v == 0 and name != "atol"):
                raise ConfigError(f"march.{name} must be a finite number > 0{' (>= 0)' if name == 'atol' else ''}, "
                                  f"got {v!r}")
        if self.rtol == 0 and self.atol == 0:
            raise ConfigError("march.rtol and march.atol cannot both be 0")
        for name in ("max_rejects", "max_windows"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < (0 if name == "max_rejects" else 1):
                raise ConfigError(f"march.{name} must be an integer >= {0 if name == 'max_rejects' else 1}, got {v!r}")
        for name in ("train", "first"):
            v = getattr(self, name)
            if v is not None and not isinstance(v, TrainConfig):
                raise ConfigError(f"march.{name} must be a TrainConfig, got {type(v).__name__}")
        if self.polish is not None and not isinstance(self.polish, (PolishConfig, LMConfig)):
            raise ConfigError(f"march.polish must be an LMConfig, a PolishConfig or None, got "
                              f"{type(self.polish).__name__}")
        if self.start not in WINDOW_STARTS:
            raise ConfigError(f"march.start must be one of {list(WINDOW_STARTS)}, got {self.start!r}")
        for name in ("thaw", "carry_adam"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"march.{name} must be true or false, got {getattr(self, name)!r}")

    def replace(self, **changes: Any) -> "MarchConfig":
        return dataclasses.replace(self, **changes)


# ----------------------------------------------------------------- pure helpers
def n_windows_for(t0: float, T: float, config: MarchConfig) -> int:
    """The number of windows: ``n_windows``, or ⌈(T − t0)/window⌉ (a 1e-9 relative slack, so
    that 20π split into windows of 4π gives 5, not 6, despite rounding)."""
    if config.n_windows is not None:
        return int(config.n_windows)
    if config.adaptive:
        raise ConfigError("adaptive windows (march.window = \"auto\") have no fixed count; give window or "
                          "n_windows for fixed windows")
    window = float(config.window)
    return max(1, math.ceil((float(T) - float(t0)) / window * (1 - 1e-9)))


def window_seed(seed: int, k: int) -> int:
    """The jitter seed of window k."""
    return (int(seed) + _SEED_STRIDE * int(k)) % (2**31 - 1)


def window_config(config: MarchConfig, k: int) -> TrainConfig:
    """Window k's training config: γ learned in window 0, frozen after unless thawed."""
    base = config.first if (k == 0 and config.first is not None) else config.train
    return base.replace(freeze_gamma=(k > 0 and not config.thaw), seed=window_seed(base.seed, k))


def window_polish(config: MarchConfig, train_cfg: TrainConfig) -> PolishConfig | None:
    if config.polish is None:
        return None
    return config.polish.replace(lam_reg=train_cfg.lam_reg)


def local_model(model: TrialSolution) -> TrialSolution:
    """The same trial solution on local time (t0 = 0); N sees s = t − t_k in every window."""
    if float(model.t0) == 0.0:
        return model
    return TrialSolution(model.net, model.scaling, model.z0, 0.0)


def window_model(previous: TrialSolution, z_start: jax.Array) -> TrialSolution:
    """Window k+1's starting model: the previous window's θ and γ, its own start state z_{k+1}."""
    return eqx.tree_at(lambda m: m.z0, previous, jnp.asarray(z_start, previous.z0.dtype))


def next_window_model(start: str, initial: TrialSolution, trained: TrialSolution,
                      z_start: jax.Array) -> TrialSolution:
    """Window k+1's starting model: γ from the trained window k, z0 = z_start, θ per ``start``."""
    if start == "previous":
        return window_model(trained, z_start)
    if start == "features":
        net = trained.net
        net = eqx.tree_at(lambda n: (n.weights[-1], n.biases[-1]), net,
                          (jnp.zeros_like(net.weights[-1]), jnp.zeros_like(net.biases[-1])))
        return window_model(eqx.tree_at(lambda m: m.net, trained, net), z_start)
    return window_model(eqx.tree_at(lambda m: m.scaling, initial, trained.scaling), z_start)


@jax.jit
def _value_at(model: TrialSolution, s: jax.Array) -> jax.Array:
    return model.value_and_rate(s)[0][0]  # the first row taken inside: eagerly, a program of its own


def end_state(model: TrialSolution, length: float) -> jax.Array:
    """ẑ(w): the state the window hands on to the next one (shape (2d,))."""
    # 8: the piecewise evaluator's smallest width; filled on the host (jnp.full compiles)
    s = jax.device_put(np.full((8,), length, dtype=np.dtype(model.z0.dtype)))
    return _value_at(model, s)


# ------------------------------------------------------------- trainer calls
def _train_windows(models: list[TrialSolution], system: HamiltonianSystem, length: float,
                   configs: list[TrainConfig], opt_states: list[Any], energy0: float, desc: str,
                   on_chunk: Callable | None) -> list[TrainResult]:
    """Adam on one window [0, length] for every model of the batch, as one compiled program:
    the only call into the trainer."""
    return train_batch(models, system, length, configs, opt_states=opt_states, energy0=energy0, desc=desc,
                       on_chunk=on_chunk)


def _polish_window(model: TrialSolution, system: HamiltonianSystem, length: float,
                   config: PolishConfig | LMConfig, energy0: float) -> PolishResult | LMResult:
    """The second phase of a window: Levenberg–Marquardt (an :class:`LMConfig`) or L-BFGS."""
    return refine(model, system, length, config, energy0=energy0)


def _record(k: int, edges: np.ndarray, z_start, res: TrainResult, pol: PolishResult | None,
            model: TrialSolution, wall: float) -> WindowRecord:
    return WindowRecord(
        index=k, start=float(edges[k]), end=float(edges[k + 1]),
        z_start=[float(x) for x in np.asarray(z_start, dtype=np.float64)],
        gamma={n: float(v) for n, v in model.scaling.gamma().items()},
        epochs=int(res.epochs_run), stop_reason=res.stop_reason,
        final_loss=res.final_loss, best_loss=res.best_loss,
        polish_steps=0 if pol is None else pol.steps,
        polish_stop_reason="" if pol is None else pol.stop_reason,
        polish_initial_loss=float("nan") if pol is None else pol.initial_loss,
        loss=res.best_loss if pol is None else pol.final_loss,
        wall_time=wall, compile_time=res.compile_time + (0.0 if pol is None else pol.compile_time),
        history=np.asarray(res.history.loss), polish_history=None if pol is None else pol.loss,
    )


# ---------------------------------------------------------------------- march
def _resumed_windows(resume: list[MarchProgress], edges: np.ndarray, n_models: int) -> int:
    """The number of finished windows of a resumed batch (the same for every model, on ``edges``)."""
    counts = {p.windows for p in resume}
    if len(resume) != n_models or len(counts) != 1:
        raise ConfigError(f"resume needs one progress per model with the same number of windows, got "
                          f"{len(resume)} for {n_models} models ({sorted(counts)} windows)")
    k = counts.pop()
    if k >= len(edges) or not np.allclose(resume[0].edges, edges[:k + 1], rtol=0, atol=1e-12 * abs(edges[-1])):
        raise ConfigError(f"the saved progress ({k} windows, edges ending at {resume[0].t:g}) does not "
                          f"fit these windows ({len(edges) - 1} of length {edges[1] - edges[0]:g})")
    return k


def march_batch(
    models: list[TrialSolution],
    system: HamiltonianSystem,
    T: float,
    configs: list[MarchConfig],
    *,
    on_window: Callable[[int, WindowRecord], None] | None = None,
    on_chunk: Callable | None = None,
    resume: list[MarchProgress] | None = None,
    on_progress: Callable[[list[MarchProgress]], None] | None = None,
) -> list[PiecewiseSolution]:
    """:func:`march` for several models at once (typically the seeds of one config: the same
    windows, the configs differing in their ``train.seed``): every window trains all of them as
    one compiled program (:func:`atlasnn.training._train.train_batch`). ``on_window(i, record)`` names the
    model. ``on_progress`` is called after every window with each model's
    :class:`~atlasnn.training._progress.MarchProgress`; given back as ``resume`` (one per model,
    the same number of windows), the march continues after those windows exactly as it would have
    gone on. A training stopped by KeyboardInterrupt raises it.
    """
    if not models or len(configs) != len(models):
        raise ConfigError(f"march_batch needs one config per model, got {len(models)} models and {len(configs)} configs")
    for model in models:
        if model.state_dim != system.state_dim:
            raise ConfigError(
                f"model state dimension {model.state_dim} does not match system {system.name!r} "
                f"(2d = {system.state_dim})"
            )
    t0 = float(models[0].t0)
    counts = {n_windows_for(t0, T, c) for c in configs}
    if len(counts) != 1 or len({float(m.t0) for m in models}) != 1:
        raise ConfigError("models marched together must share t0 and the windows")
    edges = window_edges(t0, float(T), counts.pop())
    length = float(edges[1] - edges[0])
    with jax.enable_x64(True):
        energy0 = [float(system.energy(jnp.asarray(np.asarray(m.z0, np.float64)))) for m in models]
    initial = [local_model(m) for m in models]
    current = list(initial)
    opt_states: list[Any] = [None] * len(models)
    opt_configs: list[Any] = [None] * len(models)
    trained_all: list[list[TrialSolution]] = [[] for _ in models]
    records_all: list[list[WindowRecord]] = [[] for _ in models]
    n = len(edges) - 1
    first = 0
    if resume is not None:
        first = _resumed_windows(resume, edges, len(models))
        for i, (prog, conf) in enumerate(zip(resume, configs)):
            trained_all[i], records_all[i] = list(prog.trained), list(prog.records)
            opt_states[i], opt_configs[i] = prog.opt_state, prog.opt_config
            current[i] = next_window_model(conf.start, initial[i], prog.trained[-1],
                                           end_state(prog.trained[-1], length))
    for k in range(first, n):
        cfgs = [window_config(c, k) for c in configs]
        starts = [restrict_opt_state(o, m, c.freeze_gamma) if (k > 0 and conf.carry_adam) else None
                  for o, m, c, conf in zip(opt_states, current, cfgs, configs)]
        t_start = time.perf_counter()
        results = _train_windows(current, system, length, cfgs, starts, energy0, f"window {k + 1}/{n}", on_chunk)
        if any(r.stop_reason == "interrupted" for r in results):
            raise KeyboardInterrupt
        adam_wall = (time.perf_counter() - t_start - results[0].compile_time) / len(models)
        for i, (res, cfg, conf) in enumerate(zip(results, cfgs, configs)):
            trained, pol, t_pol = res.model, None, time.perf_counter()
            pcfg = window_polish(conf, cfg)
            if pcfg is not None:
                pol = _polish_window(trained, system, length, pcfg, energy0[i])
                trained = pol.model
            wall = adam_wall + (time.perf_counter() - t_pol - (0.0 if pol is None else pol.compile_time))
            record = _record(k, edges, current[i].z0, res, pol, trained, wall)
            trained_all[i].append(trained)
            records_all[i].append(record)
            if on_window is not None:
                on_window(i, record)
            opt_states[i], opt_configs[i] = res.opt_state, cfg
            current[i] = next_window_model(conf.start, initial[i], trained, end_state(trained, length))
        if on_progress is not None:
            on_progress([MarchProgress(list(edges[:k + 2]), list(trained_all[i]), list(records_all[i]),
                                       opt_states[i], opt_configs[i]) for i in range(len(models))])
    out = []
    for i, conf in enumerate(configs):
        info = {"scheme": "time-marching", "n_windows": n, "window": length, "thaw": conf.thaw,
                "carry_adam": conf.carry_adam, "energy0": energy0[i], "batch_size": len(models)}
        out.append(PiecewiseSolution(trained_all[i], system, edges, records_all[i], info))
    return out

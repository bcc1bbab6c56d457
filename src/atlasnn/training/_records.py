"""What a training is given and what it returns: :class:`TrainConfig` (every setting, checked at
construction), :class:`History` (per-epoch records), :class:`TrainState` (enough to resume) and
:class:`TrainResult`. The loop that uses them is :mod:`atlasnn.training._train`."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.training._step import init_opt_state, initial_track, trainable_filter

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

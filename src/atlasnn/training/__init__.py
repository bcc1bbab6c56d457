"""Training a trial solution on Hamilton's equations: collocation, the physics loss, the compiled
Adam loop (one model or a batch of seeds), transfer, L-BFGS polishing and time-marching."""

from atlasnn.training._collocation import check_interval, jittered, uniform_grid
from atlasnn.training._loss import causal_physics_loss, energy_and_vector_field, hamilton_residual, physics_loss
from atlasnn.training._adaptive import first_window, march, march_adaptive
from atlasnn.training._bundle import BundleTrainConfig, BundleTraining, bundle_residuals, train_bundle
from atlasnn.training._lm import LMConfig, LMOutcome, LMResult, levenberg_marquardt, lm_batch, lm_minimise
from atlasnn.training._marching import (
    DEFAULT_NETWORK,
    DEFAULT_RTOL,
    DEFAULT_WINDOW,
    DEFAULT_WINDOW_LM,
    DEFAULT_WINDOW_TRAIN,
    WINDOW_STARTS,
    MarchConfig,
    march_batch,
    n_windows_for,
)
from atlasnn.training._progress import MarchProgress
from atlasnn.training._polish import PRECISIONS, PolishConfig, PolishResult, polish
from atlasnn.training._refine import RefineConfig, refine
from atlasnn.training._step import init_opt_state, restrict_opt_state, trainable_filter, training_compiler_options
from atlasnn.training._records import (
    BEST_RULES,
    LR_SCHEDULES,
    History,
    TrainConfig,
    TrainResult,
    TrainState,
    state_template,
)
from atlasnn.training._train import train, train_batch
from atlasnn.training._transfer import (
    check_same_architecture,
    transfer,
    transfer_batch,
    transfer_from,
)

__all__ = [
    "TrainConfig",
    "TrainResult",
    "TrainState",
    "History",
    "BEST_RULES",
    "LR_SCHEDULES",
    "train",
    "train_batch",
    "state_template",
    "trainable_filter",
    "training_compiler_options",
    "init_opt_state",
    "transfer",
    "transfer_from",
    "transfer_batch",
    "check_same_architecture",
    "restrict_opt_state",
    "LMConfig",
    "LMOutcome",
    "lm_minimise",
    "BundleTrainConfig",
    "BundleTraining",
    "train_bundle",
    "bundle_residuals",
    "LMResult",
    "levenberg_marquardt",
    "lm_batch",
    "DEFAULT_WINDOW_LM",
    "refine",
    "RefineConfig",
    "PolishConfig",
    "PolishResult",
    "PRECISIONS",
    "polish",
    "MarchConfig",
    "MarchProgress",
    "march",
    "march_batch",
    "march_adaptive",
    "first_window",
    "DEFAULT_RTOL",
    "n_windows_for",
    "DEFAULT_WINDOW",
    "DEFAULT_WINDOW_TRAIN",
    "DEFAULT_NETWORK",
    "WINDOW_STARTS",
    "physics_loss",
    "causal_physics_loss",
    "hamilton_residual",
    "energy_and_vector_field",
    "uniform_grid",
    "jittered",
    "check_interval",
]

"""atlasnn: ATLAS-NN, learnable time-scaled Hamiltonian neural networks (JAX).

The package, one subpackage per concept, data flowing one way (lowest first):

    systems, nn → solutions → training → solver → checkpoint → evaluation → inverse → report → experiments → cli

(``observations``, the data of inverse problems, sits on the ground floor with ``fileio``.)

The names below are this face: what the README and a script use, e.g.
``from atlasnn import HamiltonianSystem, make_model, train, Solution``. They are loaded on first
use (PEP 562), so ``import atlasnn`` and ``atlasnn --help`` stay quick; each also lives in its
subpackage (``atlasnn.training.train``), which is where its documentation is.
"""

from __future__ import annotations

import importlib
from typing import Any

from atlasnn.compile_cache import enable_compile_cache
from atlasnn.errors import AtlasError
from atlasnn.precision import apply_matmul_precision, enable_x64, x64_enabled
from atlasnn.version import __version__

enable_compile_cache()  # before anything compiles (atlasnn.compile_cache; ATLASNN_CACHE_DIR=off)
apply_matmul_precision()  # full float32 products on a GPU too (atlasnn.precision)

# name -> the subpackage that defines it
_FACE = {
    "systems": ("HamiltonianSystem", "builtin_system", "expression_system", "register_system", "BuiltinSystem",
                "BundleBox", "with_params"),
    "nn": ("make_model", "TrialSolution", "TimeScaling", "ModelKind", "register_model", "MODELS"),
    "solutions": ("Solution", "PiecewiseSolution", "BundleSolution", "FlowMapBundle"),
    "training": ("TrainConfig", "train", "train_batch", "transfer", "polish", "PolishConfig", "MarchConfig",
                 "march", "march_batch", "DEFAULT_NETWORK", "DEFAULT_WINDOW_TRAIN", "train_bundle", "BundleTrainConfig"),
    "solver": ("solve", "solve_batch", "Collocation", "AdamMarch", "solve_bundle", "FlowMap"),
    "checkpoint": ("save_checkpoint", "load_checkpoint", "save_piecewise", "load_piecewise", "save_bundle",
                   "load_bundle", "save_flowmap", "load_flowmap"),
    "evaluation": ("reference_solution", "integrate", "error_table", "judge_training", "Metric", "register_metric",
                   "reference_members"),
    "inverse": ("fit", "Shooting", "CollocationFit", "Joint", "Bundle", "FitResult", "fit_joint", "JointConfig",
                "fit_with_bundle", "fit_collocation", "fit_multistart", "fit_shooting", "synthetic_observations"),
    "observations": ("Observations", "Unknown", "load_observations"),
    "experiments": ("run_experiment", "resume_experiment", "run_sweep", "load_config", "run_family"),
}
_WHERE = {name: pkg for pkg, names in _FACE.items() for name in names}
_WHERE["load_config"] = "experiments.config"

__all__ = ["__version__", "AtlasError", "enable_x64", "x64_enabled", *_WHERE]


def __getattr__(name: str) -> Any:
    pkg = _WHERE.get(name)
    if pkg is None:
        raise AttributeError(f"module 'atlasnn' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"atlasnn.{pkg}"), name)
    globals()[name] = value  # looked up once
    return value


def __dir__() -> list[str]:
    return sorted(__all__)

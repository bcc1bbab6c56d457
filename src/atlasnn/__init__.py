"""atlasnn: ATLAS-NN, learnable time-scaled Hamiltonian neural networks, and the float64 Gauss
collocation of its trial solution (JAX).

The face: one door per question, each taking method objects that hold their settings.

* a trajectory: :func:`solve` (and :func:`solve_batch`) with :class:`GaussCollocation` or
  :class:`SplittingComposition` (the default chooses), :class:`AdamMarch` or :class:`Transfer` (the
  deprecated ``Collocation``: ``atlasnn.solver``);
* a bundle (every initial state and parameter of a :class:`BundleBox`): :func:`solve_bundle` with
  :class:`FlowMap` (default) or :class:`NetworkBundle`;
* parameters from observations: :func:`fit` with :class:`Shooting` (default), :class:`CollocationFit`,
  :class:`Joint` or :class:`BundleFit`, returning a :class:`FitResult`;
* a Hamiltonian from trajectories: :func:`learn_hamiltonian` with ``ThroughSolver`` (default) or
  ``HNN`` (``atlasnn.inverse``);
* the paper's experiments: :func:`load_config`, :func:`run_experiment` (and ``atlasnn reproduce``);
* any solution: :func:`save`, :func:`load`.

Everything else lives in its subpackage (``atlasnn.training`` for training, marching and transfer by
hand; ``atlasnn.evaluation``, ``atlasnn.report`` …), in layers, data flowing one way (lowest first):

    systems, nn → solutions → training → solver → checkpoint → evaluation → inverse → report → experiments → cli

(``observations``, the data of inverse problems, sits on the ground floor with ``fileio``.) The
names are loaded on first use (PEP 562), so ``import atlasnn`` and ``atlasnn --help`` stay quick.
"""

from __future__ import annotations

import importlib
from typing import Any

from atlasnn.compile_cache import enable_compile_cache
from atlasnn.errors import AtlasError
from atlasnn.precision import apply_matmul_precision
from atlasnn.version import __version__

enable_compile_cache()  # before anything compiles (atlasnn.compile_cache; ATLASNN_CACHE_DIR=off)
apply_matmul_precision()  # full float32 products on a GPU too (atlasnn.precision)

# name -> the subpackage that defines it
_FACE = {
    "systems": ("HamiltonianSystem", "builtin_system", "expression_system", "BundleBox"),
    "solver": ("solve", "solve_batch", "GaussCollocation", "SplittingComposition", "AdamMarch", "Transfer",
               "solve_bundle", "FlowMap", "NetworkBundle"),
    "checkpoint": ("save", "load"),
    "evaluation": ("reference_solution", "integrate"),
    "inverse": ("fit", "Shooting", "CollocationFit", "Joint", "BundleFit", "FitResult", "learn_hamiltonian"),
    "observations": ("Observations", "Unknown", "load_observations"),
    "experiments": ("run_experiment", "load_config"),
}
_WHERE = {name: pkg for pkg, names in _FACE.items() for name in names}
_WHERE["load_config"] = "experiments.config"

__all__ = ["__version__", "AtlasError", *_WHERE]


def __getattr__(name: str) -> Any:
    pkg = _WHERE.get(name)
    if pkg is None:
        raise AttributeError(f"module 'atlasnn' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"atlasnn.{pkg}"), name)
    globals()[name] = value  # looked up once
    return value


def __dir__() -> list[str]:
    return sorted(__all__)

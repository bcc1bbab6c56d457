"""What several test files share: small experiment configs, a quiet log, equality of two runs, a
small model and its loss per epoch, the command line of a child atlasnn (imported by name: the
folder of the root conftest is on ``sys.path``)."""

from __future__ import annotations

import json
import math
import sys
import tomllib
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.checkpoint import load_checkpoint
from atlasnn.experiments.config import parse_config
from atlasnn.nn import make_model
from atlasnn.training import jittered, physics_loss, uniform_grid

HISTORY = ("loss", "residual", "energy", "gamma")


SHORT = """\
name = "resume-short"
models = ["atlas_exp"]
seeds = [0, 1]

[system]
name = "nonlinear_oscillator"
z0 = [1.3, 1.0]

[network]
width = 8
depth = 2

[interval]
T = "pi"

[train]
epochs = 600
lr = 5e-3
betas = [0.999, 0.9999]
n_points = 16
sigma_per_T = 0.03
chunk = 100

[gamma_init]
atlas_exp = { alpha = 1.0, beta = 1.0 }

[evaluation]
eval_points = 40
fine_factor = 2
"""


TRANSFER = """\
name = "resume-transfer"
kind = "transfer"
models = ["atlas_exp"]
seeds = [0]

[system]
name = "nonlinear_oscillator"
z0 = [1.3, 1.0]

[network]
width = 8
depth = 2

[train]
lr = 5e-3
betas = [0.999, 0.9999]
sigma_per_T = 0.03
chunk = 100

[source]
T = "pi"
train = { n_points = 16, epochs = 400, lr = 8e-3 }

[target]
T = "2*pi"
train = { n_points = 24, epochs = 500 }

[transfer]
baseline = false

[evaluation]
eval_points = 40
fine_factor = 2
"""


def _cfg(text):
    return parse_config(tomllib.loads(text), source="cfg.toml")


def _quiet(*args):
    pass


def assert_same_runs(a: Path, b: Path) -> int:
    """Every checkpoint (history, parameters) and every stored trajectory of run a equals b's."""
    ra, rb = (json.loads((d / "results.json").read_text()) for d in (a, b))
    assert [r["checkpoint"] for r in ra["runs"]] == [r["checkpoint"] for r in rb["runs"]]
    for r in ra["runs"]:
        ca, cb = load_checkpoint(a / r["checkpoint"]), load_checkpoint(b / r["checkpoint"])
        for name in HISTORY:
            ha, hb = getattr(ca.history, name), getattr(cb.history, name)
            first = int(np.argmax(np.any((ha != hb).reshape(len(ha), -1), axis=1))) if ha.shape == hb.shape else None
            assert np.array_equal(ha, hb), (r["checkpoint"], name, ha.shape, hb.shape, "first difference at", first)
        import jax

        for x, y in zip(jax.tree_util.tree_leaves(ca.model), jax.tree_util.tree_leaves(cb.model)):
            assert np.array_equal(np.asarray(x), np.asarray(y)), r["checkpoint"]
    with np.load(a / "arrays.npz") as za, np.load(b / "arrays.npz") as zb:
        assert sorted(za.files) == sorted(zb.files)
        for k in za.files:
            assert np.array_equal(za[k], zb[k]), k
    for x, y in zip(ra["runs"], rb["runs"]):
        assert x["metrics"] == y["metrics"] and x["epochs"] == y["epochs"] and x["best_epoch"] == y["best_epoch"]
    return len(ra["runs"])


TINY = """
name = "tiny"
models = ["hnn", "atlas_exp"]
[system]
name = "harmonic_oscillator"
[network]
width = 8
depth = 1
[interval]
T = 2.0
[train]
epochs = 100
n_points = 16
chunk = 100
[evaluation]
fine_factor = 1
"""


ATLASNN = [sys.executable, "-c", "import runpy, signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
           "runpy.run_module('atlasnn.cli._main', run_name='__main__', alter_sys=True)"]


T_END = 2 * math.pi


def _model(seed: int = 0):
    return make_model((1.0, 0.0), scaling="rational_exp", width=32, depth=2, seed=seed)


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(eqx.filter(tree, eqx.is_inexact_array))]


def _trees_equal(a, b) -> bool:
    la, lb = _leaves(a), _leaves(b)
    return len(la) == len(lb) and all(np.array_equal(x, y) for x, y in zip(la, lb))


@eqx.filter_jit
def _epoch_loss(model, system, grid, sigma, seed, lam_reg, T, epoch):
    """The loss of ``model`` on the collocation points that epoch ``epoch`` of a run draws."""
    dtype = model.z0.dtype
    key = jax.random.fold_in(jax.random.PRNGKey(seed), epoch)
    t = jittered(grid, key, jnp.asarray(sigma, dtype), jnp.asarray(0.0, dtype), jnp.asarray(T, dtype))
    e0 = jnp.asarray(system.energy(model.z0), dtype)
    return physics_loss(model, system, t, e0, jnp.asarray(lam_reg, dtype))[0]


def epoch_loss(model, system, cfg, epoch, T=T_END):
    grid = uniform_grid(0.0, T, cfg.n_points, model.z0.dtype)
    return float(
        _epoch_loss(model, system, grid, cfg.sigma, cfg.seed, cfg.lam_reg, T, jnp.asarray(epoch, jnp.int32))
    )


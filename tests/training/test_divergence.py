"""A diverging run (lr = 1e3) stops at the first non-finite loss, keeps the best finite
parameters, says so with advice on one line, and still writes its results (exit status 0)."""

from __future__ import annotations

import json
import math

import equinox as eqx
import jax
import numpy as np
import pytest

from atlasnn.checkpoint import load_checkpoint
from atlasnn.cli import main

# the module's fixture trains for a quarter to half a minute: the long tier
pytestmark = pytest.mark.long

# HNN with an unbounded activation: at lr = 1e3 the loss overflows after the first update
CONFIG = """\
name = "diverge"
models = ["hnn"]
seeds = [0]

[system]
name = "nonlinear_oscillator"
z0 = [1.3, 1.0]

[network]
width = 8
depth = 2
activation = "silu"

[interval]
T = "pi"

[train]
epochs = 300
lr = 1e3
n_points = 16
chunk = 100

[evaluation]
eval_points = 50
fine_factor = 2
"""


@pytest.fixture(scope="module")
def diverged_run(tmp_path_factory):
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("diverge")
    cfg = tmp / "diverge.toml"
    cfg.write_text(CONFIG)
    out = tmp / "run"
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["run", str(cfg), "--out", str(out), "--no-progress"])
    return code, stdout.getvalue(), out


def test_exit_status_is_zero_because_results_were_written(diverged_run):
    code, _, out = diverged_run
    assert code == 0
    assert (out / "results.json").exists() and (out / "tables.md").exists()
    assert json.loads((out / "meta.json").read_text())["status"] == "complete"


def test_results_record_the_divergence(diverged_run):
    _, _, out = diverged_run
    res = json.loads((out / "results.json").read_text())
    (run,) = res["runs"]
    assert run["stop_reason"] == "diverged"
    assert isinstance(run["diverged_epoch"], int) and 0 < run["diverged_epoch"] < 300
    assert run["epochs"] == run["diverged_epoch"] + 1
    assert 0 <= run["best_epoch"] < run["diverged_epoch"]
    assert math.isfinite(run["returned_loss"])
    assert run["lr"] == 1e3
    assert len(res["warnings"]) == 1 and "diverged at epoch" in res["warnings"][0]


def test_returned_model_is_finite_and_is_the_kept_epoch(diverged_run):
    _, _, out = diverged_run
    ck = load_checkpoint(out / "models" / "hnn_seed0.npz")
    leaves = jax.tree_util.tree_leaves(eqx.filter(ck.model, eqx.is_inexact_array))
    assert all(np.all(np.isfinite(np.asarray(x))) for x in leaves)
    res = json.loads((out / "results.json").read_text())
    run = res["runs"][0]
    assert not np.isfinite(ck.history.loss[-1])  # the history ends at the non-finite loss
    assert ck.history.loss[run["best_epoch"]] == pytest.approx(run["returned_loss"])
    for metric in ("l2_discrete", "mse"):
        assert all(math.isfinite(v) for v in run["metrics"][metric].values())


def test_cli_output_has_one_advice_line(diverged_run):
    _, stdout, out = diverged_run
    res = json.loads((out / "results.json").read_text())
    run = res["runs"][0]
    lines = [ln.strip() for ln in stdout.splitlines() if "diverged at epoch" in ln]
    assert len(lines) == 1, stdout
    line = lines[0]
    assert line.startswith(f"HNN seed 0 diverged at epoch {run['diverged_epoch']} (non-finite loss); "
                           f"kept the parameters of epoch {run['best_epoch']} (loss ")
    assert "Lower train.lr (now 1000, e.g. 100)" in line and "raise train.epochs (now 300)" in line
    assert line == res["warnings"][0]

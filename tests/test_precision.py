"""Tests of the float32 default and the float64 switch (environment variable and function)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import atlasnn
from atlasnn.nn import make_model
from atlasnn.precision import default_float


@pytest.mark.skipif(
    os.environ.get("ATLASNN_X64", "").strip() not in ("", "0", "false", "False"),
    reason="the suite was started with ATLASNN_X64 set",
)
def test_float32_is_the_default():
    assert not atlasnn.precision.x64_enabled()
    assert default_float() == jnp.float32
    model = make_model((1.0, 0.0), scaling="rational_exp", width=16, depth=2)
    leaves = jax.tree_util.tree_leaves(model)
    assert leaves and all(x.dtype == jnp.float32 for x in leaves)


def test_enable_x64_toggles_and_restores():
    before = atlasnn.precision.x64_enabled()
    try:
        atlasnn.precision.enable_x64(True)
        assert atlasnn.precision.x64_enabled() is True
        assert default_float() == jnp.float64
        assert jnp.zeros(2).dtype == jnp.float64
        model = make_model((1.0, 0.0), scaling="tanh", width=4, depth=1)
        assert model.net.weights[0].dtype == jnp.float64 and model.scaling.raw_m.dtype == jnp.float64
        atlasnn.precision.enable_x64(False)
        assert atlasnn.precision.x64_enabled() is False
        assert jnp.zeros(2).dtype == jnp.float32
    finally:
        atlasnn.precision.enable_x64(before)
    assert atlasnn.precision.x64_enabled() == before


_X64_SCRIPT = textwrap.dedent(
    """
    import json
    import jax, numpy as np
    import atlasnn
    from atlasnn.nn._trial import make_model
    from atlasnn.systems import harmonic_oscillator
    from atlasnn.training._train import TrainConfig, train

    system = harmonic_oscillator()
    model = make_model(system.z0, scaling="rational_exp", width=8, depth=1, seed=0)
    res = train(model, system, 1.0, TrainConfig(epochs=40, lr=1e-2, n_points=8, sigma=0.1, chunk=40, progress=False))
    print(json.dumps({
        "x64": atlasnn.precision.x64_enabled(),
        "dtypes": sorted({str(x.dtype) for x in jax.tree_util.tree_leaves(res.model)}),
        "out": str(res.model(np.linspace(0.0, 1.0, 5)).dtype),
        "loss": [float(v) for v in res.history.loss],
    }))
    """
)


@pytest.mark.long
def test_env_switch_trains_in_float64():
    env = dict(os.environ, ATLASNN_X64="1", JAX_PLATFORMS="cpu")
    proc = subprocess.run(
        [sys.executable, "-c", _X64_SCRIPT], env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["x64"] is True
    assert out["dtypes"] == ["float64"]
    assert out["out"] == "float64"
    loss = np.asarray(out["loss"])
    assert loss.shape == (40,) and np.all(np.isfinite(loss))
    assert loss[-1] < loss[0]


# ------------------------------------------------------------------ matrix-product precision
_MATMUL_SCRIPT = "import atlasnn, jax; print(jax.config.jax_default_matmul_precision)"


def _matmul_setting(**env_vars):
    env = {k: v for k, v in os.environ.items()
           if k not in ("ATLASNN_MATMUL_PRECISION", "JAX_DEFAULT_MATMUL_PRECISION")}
    env.update(env_vars, JAX_PLATFORMS="cpu")
    return subprocess.run([sys.executable, "-c", _MATMUL_SCRIPT], env=env, capture_output=True, text=True,
                          timeout=120)


@pytest.mark.long
def test_full_float32_products_by_default_and_the_switches():
    assert _matmul_setting().stdout.strip() == "highest"
    assert _matmul_setting(ATLASNN_MATMUL_PRECISION="default").stdout.strip() == "None"  # JAX's own
    assert _matmul_setting(ATLASNN_MATMUL_PRECISION="tensorfloat32").stdout.strip() == "tensorfloat32"
    # JAX's own flag, set by the user, is left alone
    assert _matmul_setting(JAX_DEFAULT_MATMUL_PRECISION="bfloat16").stdout.strip() == "bfloat16"


def test_a_bad_matmul_precision_is_one_line():
    proc = _matmul_setting(ATLASNN_MATMUL_PRECISION="fast")
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [
        "atlasnn: ATLASNN_MATMUL_PRECISION='fast' is not one of highest, high, default, float32, tensorfloat32, "
        "bfloat16"]


@pytest.mark.long
def test_a_program_traced_under_another_matmul_precision_is_compiled_again():
    from atlasnn.systems import builtin_system
    from atlasnn.training import TrainConfig, train

    system = builtin_system("harmonic_oscillator")
    cfg = TrainConfig(epochs=20, lr=1e-2, n_points=16, chunk=20, progress=False)
    model = make_model(system.z0, scaling="tanh", width=12, depth=1, seed=0)
    first = train(model, system, 1.0, cfg)
    again = train(model, system, 1.0, cfg)
    assert again.compile_time == 0.0  # the same program, from the in-process cache
    with jax.default_matmul_precision("bfloat16"):
        other = train(model, system, 1.0, cfg)
    assert other.compile_time > 0.0  # not the program traced under full float32
    np.testing.assert_array_equal(first.history.loss, again.history.loss)


@pytest.mark.long
def test_a_levenberg_marquardt_phase_traced_under_another_matmul_precision_is_compiled_again():
    from atlasnn.systems import builtin_system
    from atlasnn.training import LMConfig, levenberg_marquardt

    system = builtin_system("harmonic_oscillator")
    model = make_model(system.z0, scaling="tanh", width=6, depth=1, seed=1)
    cfg = LMConfig(steps=3, n_points=8)
    levenberg_marquardt(model, system, 1.0, cfg)
    assert levenberg_marquardt(model, system, 1.0, cfg).compile_time == 0.0
    with jax.default_matmul_precision("bfloat16"):
        assert levenberg_marquardt(model, system, 1.0, cfg).compile_time > 0.0

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
    assert not atlasnn.x64_enabled()
    assert default_float() == jnp.float32
    model = make_model((1.0, 0.0), scaling="rational_exp", width=16, depth=2)
    leaves = jax.tree_util.tree_leaves(model)
    assert leaves and all(x.dtype == jnp.float32 for x in leaves)


def test_enable_x64_toggles_and_restores():
    before = atlasnn.x64_enabled()
    try:
        atlasnn.enable_x64(True)
        assert atlasnn.x64_enabled() is True
        assert default_float() == jnp.float64
        assert jnp.zeros(2).dtype == jnp.float64
        model = make_model((1.0, 0.0), scaling="tanh", width=4, depth=1)
        assert model.net.weights[0].dtype == jnp.float64 and model.scaling.raw_m.dtype == jnp.float64
        atlasnn.enable_x64(False)
        assert atlasnn.x64_enabled() is False
        assert jnp.zeros(2).dtype == jnp.float32
    finally:
        atlasnn.enable_x64(before)
    assert atlasnn.x64_enabled() == before


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
        "x64": atlasnn.x64_enabled(),
        "dtypes": sorted({str(x.dtype) for x in jax.tree_util.tree_leaves(res.model)}),
        "out": str(res.model(np.linspace(0.0, 1.0, 5)).dtype),
        "loss": [float(v) for v in res.history.loss],
    }))
    """
)


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

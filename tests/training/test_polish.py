"""L-BFGS polishing: it lowers the physics loss of an Adam-trained model, never returns a worse
model (checked with the loss computed independently), keeps frozen γ, and validates its config.

All polishing runs share one system, one parameter structure and one PolishConfig shape, so the
L-BFGS step is compiled once for the file.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.training import physics_loss
from atlasnn.nn import make_model
from atlasnn.training import PolishConfig, polish
from atlasnn.systems import harmonic_exact
from atlasnn.training import TrainConfig, train

# the module's fixture trains for a quarter to half a minute: the long tier
pytestmark = pytest.mark.long

T_END = 2 * math.pi
PCFG = PolishConfig(steps=300, n_points=120, chunk=50, patience=300)


def _loss_on_grid(model, system, n_points, T=T_END, lam_reg=1.0):
    t = jnp.linspace(0.0, T, n_points, dtype=model.z0.dtype)
    e0 = system.energy(model.z0)
    return float(physics_loss(model, system, t, e0, jnp.asarray(lam_reg, model.z0.dtype))[0])


@pytest.fixture(scope="module")
def trained(ho):
    model = make_model((1.0, 0.0), scaling="rational_exp", width=32, depth=2, seed=1)
    cfg = TrainConfig(epochs=1500, lr=5e-3, n_points=60, sigma=0.5, progress=False, chunk=500)
    return train(model, ho, T_END, cfg).model


def test_lbfgs_lowers_the_loss_of_a_trained_model(trained, ho):
    res = polish(trained, ho, T_END, PCFG)
    before = _loss_on_grid(trained, ho, PCFG.n_points)
    after = _loss_on_grid(res.model, ho, PCFG.n_points)
    np.testing.assert_allclose(res.initial_loss, before, rtol=1e-4)
    np.testing.assert_allclose(res.final_loss, after, rtol=1e-4)
    assert after < 0.3 * before
    assert res.loss.shape == (res.steps,) and res.loss[0] == pytest.approx(before, rel=1e-4)
    assert np.all(np.diff(res.loss) <= 0)  # accepted steps only lower it; rejected ones hold it
    t = np.linspace(0, T_END, 200)
    err_before = np.abs(np.asarray(trained(jnp.asarray(t, jnp.float32))) - harmonic_exact(t)).max()
    err_after = np.abs(np.asarray(res.model(jnp.asarray(t, jnp.float32))) - harmonic_exact(t)).max()
    assert err_after < err_before


def test_polish_never_returns_a_worse_model(trained, ho):
    once = polish(trained, ho, T_END, PCFG)
    # a second pass starts at a point L-BFGS has already worked on; a one-step line search
    # makes failed or uphill steps likely: the result must still be no worse than its input
    again = polish(once.model, ho, T_END, PCFG.replace(linesearch_steps=1))
    assert _loss_on_grid(again.model, ho, PCFG.n_points) <= _loss_on_grid(once.model, ho, PCFG.n_points)
    assert again.final_loss <= again.initial_loss
    assert again.rejected_steps >= 1  # the safeguard was exercised (the path this test is for)
    assert again.stop_reason in ("no_improvement", "stalled", "budget")


def test_frozen_gamma_is_untouched_and_thawed_gamma_moves(trained, ho):
    res = polish(trained, ho, T_END, PCFG.replace(steps=20))
    assert np.array_equal(np.asarray(res.model.scaling.raw_alpha), np.asarray(trained.scaling.raw_alpha))
    assert np.array_equal(np.asarray(res.model.z0), np.asarray(trained.z0))
    thawed = polish(trained, ho, T_END, PCFG.replace(steps=20, freeze_gamma=False))
    assert not np.array_equal(np.asarray(thawed.model.scaling.raw_alpha), np.asarray(trained.scaling.raw_alpha))


def test_polish_stops_when_nothing_improves(trained, ho):
    res = polish(trained, ho, T_END, PCFG.replace(min_rel_improvement=0.99, patience=5))
    assert res.stop_reason == "no_improvement" and res.steps == 5


def test_polish_vmaps_over_seeds(ho):
    """The compiled part is a pure function: vmapped over two models it gives each one's result."""
    from jax.flatten_util import ravel_pytree

    from atlasnn.training._polish import make_lbfgs, polish_data, polish_init, polish_steps
    from atlasnn.training import trainable_filter

    cfg = PCFG.replace(steps=10, chunk=10)
    models = [make_model((1.0, 0.0), scaling="rational_exp", width=8, depth=1, seed=s) for s in (0, 1)]
    parts = [eqx.partition(m, trainable_filter(m, True)) for m in models]
    flats = [ravel_pytree(p)[0] for p, _ in parts]
    unravel = ravel_pytree(parts[0][0])[1]
    rest = parts[0][1]
    data = polish_data(cfg, 0.0, 1.0, 0.5, jnp.float32)
    opt = make_lbfgs(cfg)

    def run(x):
        c = polish_init(x, rest, unravel, ho, data, opt)
        return polish_steps(c, rest, unravel, ho, data, opt, cfg.chunk)[0].best_value

    batched = jax.jit(jax.vmap(run))(jnp.stack(flats))
    one = jax.jit(run)
    single = [one(x) for x in flats]
    np.testing.assert_allclose(np.asarray(batched), np.asarray(single), rtol=1e-4)


@pytest.mark.parametrize(
    "field, value",
    [("steps", 0), ("n_points", 1), ("memory", 0), ("patience", 0), ("min_rel_improvement", 1.0),
     ("lam_reg", -1.0), ("freeze_gamma", "yes"), ("chunk", 2.5), ("precision", "float16")],
)
def test_polish_config_errors_name_the_field(field, value):
    with pytest.raises(ConfigError, match=f"polish.{field}"):
        PolishConfig(**{field: value})


@pytest.mark.slow  # its own compile of the L-BFGS step in float64: 40 s
def test_float64_polishing_returns_a_float32_model_no_worse_than_its_input(trained, ho):
    res = polish(trained, ho, T_END, PCFG.replace(steps=30, precision="float64"))
    assert res.model.z0.dtype == jnp.float32
    assert all(x.dtype == jnp.float32 for x in jax.tree_util.tree_leaves(eqx.filter(res.model, eqx.is_inexact_array)))
    before = _loss_on_grid(trained, ho, PCFG.n_points)
    after = _loss_on_grid(res.model, ho, PCFG.n_points)
    np.testing.assert_allclose(res.initial_loss, before, rtol=1e-6)
    np.testing.assert_allclose(res.final_loss, after, rtol=1e-6)
    assert after < before  # 30 float64 steps from an Adam-trained model do lower the loss

"""Tests of transfer learning: source on [0, π], target on [0, 4π] with γ frozen (or thawed)."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.nn import make_model
from atlasnn.systems import henon_heiles
from atlasnn.training import TrainConfig, train
from atlasnn.training import check_same_architecture, restrict_opt_state, transfer

# the same model shape and K as in test_train.py, so that the compiled steps are shared
SOURCE_CFG = TrainConfig(epochs=1000, lr=5e-3, n_points=100, sigma=0.1, progress=False)
TARGET_CFG = TrainConfig(epochs=200, lr=5e-3, n_points=100, sigma=0.1, progress=False)
T_SOURCE, T_TARGET = math.pi, 4 * math.pi


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(eqx.filter(tree, eqx.is_inexact_array))]


def _trees_equal(a, b) -> bool:
    la, lb = _leaves(a), _leaves(b)
    return len(la) == len(lb) and all(np.array_equal(x, y) for x, y in zip(la, lb))


def _raw_gamma(model):
    return [np.asarray(model.scaling.raw_alpha), np.asarray(model.scaling.raw_beta)]


@pytest.fixture(scope="module")
def source(ho):
    model = make_model((1.0, 0.0), scaling="rational_exp", width=32, depth=2, seed=0)
    res = train(model, ho, T_SOURCE, SOURCE_CFG)
    # γ was learned in the source task
    assert np.max(np.abs(res.history.gamma[-1] - res.history.gamma[0])) > 1e-4
    return res


@pytest.fixture(scope="module")
def target(ho, source):
    return transfer(source, ho, T_TARGET, TARGET_CFG)


@pytest.mark.long
def test_target_starts_from_source(ho, source):
    # one epoch, release rule: the returned parameters are those of epoch 0, the starting ones
    start = transfer(source, ho, T_TARGET, TARGET_CFG.replace(epochs=1))
    assert start.best_epoch == 0 and start.interval == (0.0, T_TARGET)
    assert _trees_equal(start.model, source.model)
    t = jnp.linspace(0.0, T_SOURCE, 101)
    np.testing.assert_array_equal(np.asarray(start.model(t)), np.asarray(source.model(t)))
    np.testing.assert_array_equal(start.history.gamma[0], np.asarray(source.model.scaling.gamma_array()))


def test_gamma_frozen_theta_trained(source, target):
    assert target.config.freeze_gamma is True
    np.testing.assert_array_equal(target.history.gamma[0], np.asarray(source.model.scaling.gamma_array()))
    assert np.all(target.history.gamma == target.history.gamma[0])
    for m in (target.model, target.final_model):
        for a, b in zip(_raw_gamma(m), _raw_gamma(source.model)):
            assert np.array_equal(a, b)
        assert not np.array_equal(np.asarray(m.net.weights[1]), np.asarray(source.model.net.weights[1]))
    assert target.interval == (0.0, T_TARGET)
    assert len(target.history) == TARGET_CFG.epochs
    # learning continues on the long interval
    assert np.min(target.history.loss[-20:]) < target.history.loss[0]


def test_thaw_lets_gamma_move(ho, source):
    res = transfer(source, ho, T_TARGET, TARGET_CFG, thaw=True)
    assert res.config.freeze_gamma is False
    np.testing.assert_array_equal(res.history.gamma[0], np.asarray(source.model.scaling.gamma_array()))
    assert np.max(np.abs(res.history.gamma[-1] - res.history.gamma[0])) > 1e-5
    assert not all(np.array_equal(a, b) for a, b in zip(_raw_gamma(res.final_model), _raw_gamma(source.model)))


def test_carry_adam_changes_the_updates(ho, source, target):
    fresh = transfer(source, ho, T_TARGET, TARGET_CFG, carry_adam=False)
    carried = target  # carry_adam=True is the default
    # the same starting parameters and the same jitter: the first loss is the same
    assert fresh.history.loss[0] == carried.history.loss[0]
    # the first Adam update differs (carried moments), so later losses differ
    assert fresh.history.loss[1] != carried.history.loss[1]
    assert not np.array_equal(fresh.history.loss[1:], carried.history.loss[1:])


def test_restricted_adam_state_matches_trainable_leaves(source):
    state = restrict_opt_state(source.opt_state, source.model, freeze_gamma=True)
    mu = state.inner_state[0].mu
    assert mu.scaling.raw_alpha is None and mu.scaling.raw_beta is None
    # the network moments are the source's, not reset
    np.testing.assert_array_equal(
        np.asarray(mu.net.weights[0]), np.asarray(source.opt_state.inner_state[0].mu.net.weights[0])
    )
    assert np.any(np.asarray(mu.net.weights[0]) != 0)
    thawed = restrict_opt_state(source.opt_state, source.model, freeze_gamma=False)
    assert thawed.inner_state[0].mu.scaling.raw_alpha is not None


def test_architecture_mismatch_is_an_error(ho, source):
    with pytest.raises(ConfigError) as exc:
        transfer(source, ho, T_TARGET, TARGET_CFG, architecture={"width": 80, "depth": 2})
    assert "width" in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(ConfigError, match="scaling"):
        check_same_architecture(source.model, {"scaling": "tanh"})
    with pytest.raises(ConfigError, match="depth"):
        check_same_architecture(source.model, {"depth": 3})
    # the matching architecture passes
    check_same_architecture(source.model, {"width": 32, "depth": 2, "scaling": "rational_exp", "state_dim": 2})


def test_system_mismatch_is_an_error(source):
    with pytest.raises(ConfigError):
        transfer(source, henon_heiles(), T_TARGET, TARGET_CFG)

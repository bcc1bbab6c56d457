"""Trainer options beyond the paper's defaults: the release's exact parameter-return rule, learning-
rate schedules, causal weighting, the release's fixed collocation point and the E0 override.

Each is checked against an independent computation (a second run, Optax's schedule, the loss by
hand), not against stored numbers.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import optax
import pytest

from atlasnn.training._collocation import reflect_into, with_release_fixed_point
from atlasnn.errors import ConfigError
from atlasnn.training._loss import causal_physics_loss, causal_weights, physics_loss
from atlasnn.nn import make_model
from atlasnn.systems import nonlinear_oscillator
from atlasnn.training import TrainConfig, train

from support import T_END, _model, _trees_equal, epoch_loss

BASE = TrainConfig(epochs=60, lr=5e-3, n_points=100, sigma=0.1, progress=False, chunk=25)


# ------------------------------------------------------------------ release_exact best rule
@pytest.mark.long
def test_release_exact_returns_the_post_update_parameters_of_the_best_epoch(ho):
    cfg = BASE.replace(best_rule="release_exact")
    res = train(_model(), ho, T_END, cfg)
    loss = res.history.loss
    start = int(math.floor(0.8 * cfg.epochs)) + 1  # the release tests epoch > 0.8·budget
    window = np.where(loss[start:] < 1.0, loss[start:], np.inf)
    assert np.isfinite(window).any()
    assert res.best_epoch == start + int(np.argmin(window))
    # the parameters after the update of that epoch = the final ones of a run that stops there
    after = train(_model(), ho, T_END, cfg.replace(best_rule="last", epochs=res.best_epoch + 1))
    assert _trees_equal(res.model, after.final_model)
    before = train(_model(), ho, T_END, cfg.replace(best_rule="last", epochs=res.best_epoch))
    assert not _trees_equal(res.model, before.final_model)


def test_release_exact_window_is_strictly_after_the_fraction(ho):
    # with 5 epochs and fraction 0.8 only epoch 4 (> 4.0) is eligible; the rule "release"
    # (epoch >= floor(0.8·5) = 4) agrees here, so use fraction 0.6 (> 3.0: epoch 4 only;
    # "release" also allows epoch 3)
    cfg = BASE.replace(epochs=5, best_rule="release_exact", best_start_fraction=0.6)
    res = train(_model(), ho, T_END, cfg)
    assert res.best_epoch == 4


@pytest.mark.long
def test_release_exact_returns_the_initial_parameters_when_no_loss_falls_below_one():
    system = nonlinear_oscillator()
    model = make_model((3.0, 0.0), scaling="rational_exp", width=16, depth=2, seed=0)
    cfg = TrainConfig(epochs=20, lr=1e-9, n_points=50, progress=False, best_rule="release_exact")
    res = train(model, system, 4.0, cfg)
    assert res.history.loss.min() > 1.0
    assert res.best_epoch == -1
    assert _trees_equal(res.model, model)
    assert not _trees_equal(res.final_model, model)


@pytest.mark.long
def test_release_exact_tolerance_is_strict_and_keeps_the_update(ho):
    ref = train(_model(), ho, T_END, BASE.replace(best_rule="last"))
    loss = ref.history.loss
    k = 20
    assert loss[k] < loss[:k].min()  # epoch k reaches a new lowest loss
    tol = float(loss[k])
    lowest = train(_model(), ho, T_END, BASE.replace(tolerance=tol))  # loss <= tol
    assert lowest.stop_reason == "tolerance" and lowest.best_epoch == k
    exact = train(_model(), ho, T_END, BASE.replace(tolerance=tol, best_rule="release_exact"))
    j = k + 1 + int(np.argmax(loss[k + 1:] < tol))  # first epoch strictly below
    assert exact.stop_reason == "tolerance" and exact.best_epoch == j and exact.epochs_run == j + 1
    after = train(_model(), ho, T_END, BASE.replace(best_rule="last", epochs=j + 1))
    assert _trees_equal(exact.model, after.final_model)


# ------------------------------------------------------------------------------ schedules
@pytest.mark.long
@pytest.mark.parametrize("kind", ["cosine", "exponential"])
def test_lr_schedule_follows_optax_and_leaves_epoch_zero_alone(ho, kind):
    cfg = BASE.replace(epochs=40, lr_schedule=kind, lr_final_ratio=0.05)
    res = train(_model(), ho, T_END, cfg)
    last = cfg.epochs - 1
    if kind == "cosine":
        factor = optax.cosine_decay_schedule(1.0, decay_steps=cfg.epochs, alpha=0.05)(last)
    else:
        factor = optax.exponential_decay(1.0, transition_steps=cfg.epochs, decay_rate=0.05)(last)
    lr_used = float(res.opt_state.hyperparams["learning_rate"])
    assert lr_used == pytest.approx(cfg.lr * float(factor), rel=1e-5)
    const = train(_model(), ho, T_END, cfg.replace(lr_schedule="constant"))
    # the first update uses lr·1 in both, so the losses agree until the second update acts
    np.testing.assert_array_equal(res.history.loss[:2], const.history.loss[:2])
    assert not np.array_equal(res.history.loss, const.history.loss)


def test_constant_schedule_keeps_the_lr(ho):
    res = train(_model(), ho, T_END, BASE.replace(epochs=10))
    assert float(res.opt_state.hyperparams["learning_rate"]) == pytest.approx(BASE.lr)


# ------------------------------------------------------------------------------- causal
def test_causal_weights_are_one_where_every_earlier_loss_is_zero():
    point = jnp.asarray([0.0, 0.0, 0.0, 5.0, 1.0, 2.0])
    w = np.asarray(causal_weights(point, 0.5, 0.3))
    np.testing.assert_array_equal(w[:4], 1.0)
    np.testing.assert_allclose(w[4:], np.exp(-0.3 * 0.5 * np.array([5.0, 6.0])), rtol=1e-6)
    assert np.all(np.diff(w) <= 0)


@pytest.mark.long
def test_causal_loss_with_zero_eps_is_the_physics_loss(ho):
    model = _model()
    t = jnp.sort(jnp.linspace(0.0, T_END, 50))
    e0, lam = jnp.asarray(0.5), jnp.asarray(1.0)
    plain, (res, en) = physics_loss(model, ho, t, e0, lam)
    obj, (loss, res_c, en_c) = causal_physics_loss(model, ho, t, e0, lam, jnp.asarray(0.0), jnp.asarray(0.1))
    assert float(obj) == pytest.approx(float(plain), rel=1e-6)
    assert float(loss) == pytest.approx(float(plain), rel=1e-6)
    obj_w, (loss_w, _, _) = causal_physics_loss(model, ho, t, e0, lam, jnp.asarray(50.0), jnp.asarray(0.1))
    assert float(obj_w) < float(plain) and float(loss_w) == pytest.approx(float(plain), rel=1e-6)


def test_causal_training_records_the_unweighted_loss(ho):
    cfg = BASE.replace(epochs=30, causal_eps=100.0)
    res = train(_model(), ho, T_END, cfg)
    # epoch 0's recorded loss is the plain physics loss of the initial model at epoch 0's points
    assert res.history.loss[0] == pytest.approx(epoch_loss(_model(), ho, cfg, 0), rel=1e-5)
    plain = train(_model(), ho, T_END, cfg.replace(causal_eps=0.0))
    assert not np.array_equal(res.history.loss[1:], plain.history.loss[1:])  # other gradients


# ------------------------------------------------------------------ fixed point and E0
def test_release_fixed_point_pins_the_third_time_at_t0_plus_one():
    t = jnp.linspace(2.0, 9.0, 8)
    pinned = np.asarray(with_release_fixed_point(t, 2.0, 9.0))
    assert pinned[2] == pytest.approx(3.0)
    np.testing.assert_array_equal(np.delete(pinned, 2), np.delete(np.asarray(t), 2))
    assert float(reflect_into(jnp.asarray(-1.0), 0.0, 5.0)) == 1.0


def test_release_fixed_point_changes_training_and_needs_three_points(ho):
    a = train(_model(), ho, T_END, BASE.replace(epochs=5))
    b = train(_model(), ho, T_END, BASE.replace(epochs=5, release_fixed_point=True))
    assert a.history.loss[0] != b.history.loss[0]
    with pytest.raises(ConfigError, match="n_points"):
        BASE.replace(n_points=2, release_fixed_point=True)


def test_energy0_override_sets_the_penalty_target(ho):
    cfg = BASE.replace(epochs=1, lam_reg=1.0, sigma=0.0)
    model = _model()
    shifted = train(model, ho, T_END, cfg, energy0=0.5 + 0.25)
    plain = train(model, ho, T_END, cfg)
    t = jnp.linspace(0.0, T_END, cfg.n_points)
    energy = np.asarray(ho.energy(model(t)), np.float64)
    assert shifted.history.energy[0] == pytest.approx(np.mean((energy - 0.75) ** 2), rel=1e-4)
    assert plain.history.energy[0] == pytest.approx(np.mean((energy - 0.5) ** 2), rel=1e-4)


@pytest.mark.parametrize("field,value", [("lr_schedule", "linear"), ("lr_final_ratio", 0.0),
                                         ("lr_final_ratio", 1.5), ("causal_eps", -1.0),
                                         ("release_fixed_point", 1)])
def test_bad_option_values_name_the_field(field, value):
    with pytest.raises(ConfigError, match=f"train.{field}"):
        BASE.replace(**{field: value})

"""Tests of the training loop: convergence, γ freezing, stopping rules, determinism, config checks.

Compilation dominates the cost here, so the runs share one system object (the ``ho`` fixture),
one model shape and one collocation size; ``epochs``, ``lr``, ``seed`` and ``tolerance`` are
run-time values and do not trigger a new compilation.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.nn import make_model
from atlasnn.systems import harmonic_exact, henon_heiles
from atlasnn.training import TrainConfig, init_opt_state, train

from support import T_END, _leaves, _model, _trees_equal, epoch_loss  # noqa: F401

CFG = TrainConfig(epochs=3000, lr=5e-3, n_points=100, sigma=0.1, progress=False)


def _raw_gamma(model):
    return [np.asarray(model.scaling.raw_alpha), np.asarray(model.scaling.raw_beta)]


@pytest.fixture(scope="module")
def reference(ho):
    """ATLAS-NN (exp) on the harmonic oscillator over [0, 2π], 3000 epochs."""
    return train(_model(), ho, T_END, CFG)


# ------------------------------------------------------------------------------ accuracy
@pytest.mark.long
def test_converges_on_harmonic_oscillator(reference):
    res = reference
    assert res.stop_reason == "budget" and not res.tolerance_met
    assert res.epochs_run == 3000 and len(res.history) == 3000
    t = np.linspace(0.0, T_END, 2001)
    z = np.asarray(res.model(jnp.asarray(t, jnp.float32)), dtype=np.float64)
    err = np.max(np.abs(z - harmonic_exact(t)))
    assert err < 1e-2, err
    loss = res.history.loss
    assert np.all(np.isfinite(loss))
    assert loss[0] / loss.min() >= 100
    assert loss[0] / np.min(loss[-100:]) >= 100
    # the history's pieces add up: loss = residual + λ·energy penalty (λ = 1)
    np.testing.assert_allclose(loss, res.history.residual + res.history.energy, rtol=1e-5)


def test_gamma_moves_when_not_frozen(reference):
    g = reference.history.gamma
    assert g.shape == (3000, 2) and reference.history.gamma_names == ("alpha", "beta")
    np.testing.assert_allclose(g[0], [1.0, 1.0], rtol=1e-6)
    assert np.max(np.abs(g[-1] - g[0])) > 1e-3
    assert not any(np.array_equal(a, b) for a, b in zip(_raw_gamma(reference.model), _raw_gamma(_model())))


def test_freeze_gamma_keeps_it_bit_identical(ho):
    start = _model()
    res = train(start, ho, T_END, CFG.replace(epochs=300, freeze_gamma=True))
    for m in (res.model, res.final_model):
        for a, b in zip(_raw_gamma(m), _raw_gamma(start)):
            assert np.array_equal(a, b)
        # while θ moved
        assert not np.array_equal(np.asarray(m.net.weights[1]), np.asarray(start.net.weights[1]))
        # z0 is never trained
        assert np.array_equal(np.asarray(m.z0), np.asarray(start.z0))
    assert np.all(res.history.gamma == res.history.gamma[0])
    assert res.history.loss[-1] < res.history.loss[0]


# ---------------------------------------------------------------------------- tolerance
def test_tolerance_stops_at_first_epoch_below(ho, reference):
    ref_loss = reference.history.loss
    tol = float(np.sqrt(ref_loss[0] * ref_loss[-1]))  # between the first and the final loss
    assert ref_loss[-1] < tol < ref_loss[0]
    first = int(np.argmax(ref_loss <= tol))
    assert ref_loss[first] <= tol and np.all(ref_loss[:first] > tol) and 0 < first < 2999

    res = train(_model(), ho, T_END, CFG.replace(tolerance=tol))
    assert res.stop_reason == "tolerance" and res.tolerance_met
    assert res.epochs_run == first + 1 and len(res.history) == first + 1
    assert res.best_epoch == first
    # same seed, same config: the run is the reference run cut short
    np.testing.assert_array_equal(res.history.loss, ref_loss[: first + 1])
    # the returned parameters are the ones that produced the stopping loss (no update after it)
    assert _trees_equal(res.model, res.final_model)
    assert epoch_loss(res.model, ho, CFG, first) == pytest.approx(float(ref_loss[first]), rel=1e-5)
    # ... and not those of the epoch before
    assert epoch_loss(res.model, ho, CFG, first - 1) != pytest.approx(float(ref_loss[first - 1]), rel=1e-5)


# -------------------------------------------------------------------------- determinism
def test_same_seed_same_history_and_other_seed_differs(ho, reference):
    cfg = CFG.replace(epochs=300)
    a = train(_model(), ho, T_END, cfg)
    b = train(_model(), ho, T_END, cfg)
    for name in ("loss", "residual", "energy", "gamma"):
        assert np.array_equal(getattr(a.history, name), getattr(b.history, name)), name
    assert _trees_equal(a.model, b.model)
    # the epoch budget does not change the trajectory: a prefix of the 3000-epoch run
    np.testing.assert_array_equal(a.history.loss, reference.history.loss[:300])

    c = train(_model(), ho, T_END, cfg.replace(seed=1))
    assert not np.array_equal(a.history.loss, c.history.loss)
    assert c.history.loss[0] != a.history.loss[0]  # other jitter from the first epoch on


def test_chunk_size_does_not_change_results(ho):
    cfg = CFG.replace(epochs=600)
    a = train(_model(), ho, T_END, cfg)  # chunk 1000: one partial chunk
    b = train(_model(), ho, T_END, cfg.replace(chunk=250))  # 250 + 250 + 100
    assert a.epochs_run == b.epochs_run == 600
    for name in ("loss", "residual", "energy", "gamma"):
        assert np.array_equal(getattr(a.history, name), getattr(b.history, name)), name
    assert a.best_epoch == b.best_epoch
    assert _trees_equal(a.model, b.model) and _trees_equal(a.final_model, b.final_model)


# --------------------------------------------------------------------------- best rules
def test_best_rule_release(ho, reference):
    res = reference
    start = int(math.floor(0.8 * CFG.epochs))
    assert start <= res.best_epoch < CFG.epochs
    window = res.history.loss[start:]
    assert res.history.loss[res.best_epoch] == window.min()
    assert res.best_epoch == start + int(np.argmin(window))
    assert res.best_loss == pytest.approx(float(window.min()), rel=1e-7)
    assert epoch_loss(res.model, ho, CFG, res.best_epoch) == pytest.approx(float(window.min()), rel=1e-5)
    assert not _trees_equal(res.model, res.final_model)


def test_best_rules_lowest_and_last(ho):
    cfg = CFG.replace(epochs=600, best_rule="lowest")
    low = train(_model(), ho, T_END, cfg)
    assert low.best_epoch == int(np.argmin(low.history.loss))
    assert epoch_loss(low.model, ho, cfg, low.best_epoch) == pytest.approx(float(low.history.loss.min()), rel=1e-5)

    last = train(_model(), ho, T_END, cfg.replace(best_rule="last"))
    np.testing.assert_array_equal(last.history.loss, low.history.loss)
    assert last.best_epoch == -1 and last.stop_reason == "budget"
    assert _trees_equal(last.model, last.final_model)
    assert not _trees_equal(last.model, low.model)


# ---------------------------------------------------------------------------- divergence
def test_divergence_is_detected(ho):
    # γ frozen (so the scaling cannot collapse to f ≡ 0) and an absurd learning rate
    res = train(_model(), ho, T_END, CFG.replace(epochs=300, lr=1e5, freeze_gamma=True))
    loss = res.history.loss
    assert res.stop_reason == "diverged" and not res.tolerance_met
    assert res.diverged_epoch == len(loss) - 1 == res.epochs_run - 1
    assert res.epochs_run < 300
    assert not np.isfinite(loss[-1]) and np.all(np.isfinite(loss[:-1]))
    # the lowest finite-loss parameters come back, and they are finite
    assert res.best_epoch == int(np.argmin(loss[:-1]))
    assert all(np.all(np.isfinite(x)) for x in _leaves(res.model))
    z = np.asarray(res.model(jnp.linspace(0.0, T_END, 50)))
    assert np.all(np.isfinite(z))


# ------------------------------------------------------------------------------- config
@pytest.mark.parametrize(
    "field, value",
    [
        ("epochs", 0),
        ("epochs", 2.5),
        ("epochs", True),
        ("lr", -1.0),
        ("lr", 0.0),
        ("lr", float("nan")),
        ("betas", (1.0, 0.9)),
        ("betas", (0.9,)),
        ("betas", (0.9, -0.1)),
        ("n_points", 1),
        ("tolerance", -1.0),
        ("tolerance", float("inf")),
        ("best_rule", "x"),
        ("sigma", -0.1),
        ("lam_reg", -1.0),
        ("best_start_fraction", 1.5),
        ("seed", -1),
        ("chunk", 0),
    ],
)
def test_bad_config_names_the_field(field, value):
    with pytest.raises(ConfigError) as exc:
        TrainConfig(**{field: value})
    msg = str(exc.value)
    assert field in msg and "\n" not in msg


def test_good_config_and_replace():
    cfg = TrainConfig(betas=[0.999, 0.9999], tolerance=4e-5)
    assert cfg.betas == (0.999, 0.9999)
    assert cfg.replace(lr=0.1).lr == 0.1 and cfg.lr == 1e-3
    with pytest.raises(ConfigError):
        cfg.replace(n_points=0)


def test_train_rejects_bad_problem(ho):
    with pytest.raises(ConfigError):  # a d = 1 model for a d = 2 system
        train(_model(), henon_heiles(), 1.0, CFG)
    with pytest.raises(ConfigError):  # empty interval
        train(_model(), ho, 0.0, CFG)
    with pytest.raises(ConfigError):  # Adam state of another model shape
        other = make_model((1.0, 0.0), width=4, depth=1)
        foreign = init_opt_state(eqx.filter(other, eqx.is_inexact_array), CFG, jnp.float32)
        train(_model(), ho, T_END, CFG, opt_state=foreign)

"""Seed-batched training: S runs in one compiled program behave as S lone runs.

"As a lone run" means: the same stopping epoch, stop reason and returned epoch, and losses and
parameters equal to float32 rounding (the batched arithmetic may round differently in the last
bits, so bit-equality is not asked for; the tolerances below are a few hundred ulps after a few
hundred epochs).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.training import TrainConfig, train, train_batch

from support import T_END, _model, _trees_equal

CFG = TrainConfig(epochs=240, lr=5e-3, n_points=100, sigma=0.1, progress=False, chunk=80)


def _close(a, b, rtol=2e-5, atol=2e-6):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol)


def _same_as_alone(batched, alone):
    assert batched.stop_reason == alone.stop_reason
    assert batched.epochs_run == alone.epochs_run
    assert batched.best_epoch == alone.best_epoch
    assert len(batched.history) == len(alone.history)
    np.testing.assert_allclose(batched.history.loss, alone.history.loss, rtol=1e-4)
    _close(batched.model, alone.model)


@pytest.mark.long
def test_each_seed_of_a_batch_is_its_lone_run(ho):
    configs = [CFG.replace(seed=s) for s in range(3)]
    models = [_model(seed=s) for s in range(3)]
    batch = train_batch(models, ho, T_END, configs)
    for m, c, b in zip(models, configs, batch):
        _same_as_alone(b, train(m, ho, T_END, c))
    assert batch[0].info["batch_size"] == 3
    assert batch[0].wall_time == pytest.approx(batch[0].info["batch_wall_time"] / 3)
    assert not np.array_equal(batch[0].history.loss, batch[1].history.loss)


@pytest.mark.long
def test_runs_with_other_initial_states_keep_their_own_energy(ho):
    """H(z0) is computed once per distinct z0 of a batch and Adam's fresh state once per layout:
    runs that share neither must still train as they would alone."""
    from atlasnn.nn import make_model

    z0s = [(1.0, 0.0), (0.5, 0.5), (1.0, 0.0)]
    models = [make_model(z, scaling="rational_exp", width=32, depth=2, seed=s) for s, z in enumerate(z0s)]
    configs = [CFG.replace(seed=s, lr=lr) for s, lr in enumerate((5e-3, 2e-3, 5e-3))]
    batch = train_batch(models, ho, T_END, configs)
    for m, c, b in zip(models, configs, batch):
        _same_as_alone(b, train(m, ho, T_END, c))
    # the fresh Adam states are not one shared object's values after training
    assert float(batch[0].opt_state.hyperparams["learning_rate"]) == pytest.approx(5e-3)
    assert float(batch[1].opt_state.hyperparams["learning_rate"]) == pytest.approx(2e-3)


@pytest.mark.long
def test_a_seed_that_stops_or_diverges_leaves_the_others_alone(ho):
    base = CFG.replace(freeze_gamma=True)  # so that an absurd lr diverges (see test_train)
    good = base.replace(seed=0)
    ref = train(_model(1), ho, T_END, base.replace(seed=1))
    loss = ref.history.loss
    # an epoch after about a quarter of the budget that beats every earlier loss by a margin far
    # above rounding, and a tolerance just above its loss: the stop cannot move by rounding
    k = next(k for k in range(60, 200) if loss[k] < 0.999 * loss[:k].min())
    tol = float(loss[k]) * 1.0002
    stopping = base.replace(seed=1, tolerance=tol)
    diverging = base.replace(seed=2, lr=1e5)
    shorter = base.replace(seed=3, epochs=100)  # budgets may differ within a batch
    configs = [good, stopping, diverging, shorter]
    models = [_model(seed=s) for s in range(4)]
    batch = train_batch(models, ho, T_END, configs)
    assert [r.stop_reason for r in batch] == ["budget", "tolerance", "diverged", "budget"]
    for i, (m, c, b) in enumerate(zip(models, configs, batch)):
        alone = train(m, ho, T_END, c)
        if i != 2:
            _same_as_alone(b, alone)
            continue
        # lr = 1e5 amplifies last-bit differences at once: when it diverges is chaotic, that it
        # diverges and what it kept (finite, the lowest loss seen) are not
        assert alone.stop_reason == "diverged" and np.isfinite(b.history.loss[:-1]).all()
        np.testing.assert_allclose(b.history.loss[:1], alone.history.loss[:1], rtol=1e-5)
        assert b.best_epoch == int(np.argmin(b.history.loss[:-1]))
    assert batch[3].epochs_run == 100 and batch[0].epochs_run == CFG.epochs


@pytest.mark.long
def test_a_batch_interrupted_and_resumed_equals_the_uninterrupted_batch(ho):
    configs = [CFG.replace(seed=s) for s in range(2)]
    models = [_model(seed=s) for s in range(2)]
    full = train_batch(models, ho, T_END, configs)
    saved = []

    def stop_after_first_chunk(states):
        saved.append([jax.device_get(s) for s in states])
        raise KeyboardInterrupt

    first = train_batch(models, ho, T_END, configs, on_chunk=stop_after_first_chunk)
    assert [r.stop_reason for r in first] == ["interrupted"] * 2
    assert all(s.epoch == CFG.chunk for s in saved[0])
    rest = train_batch(models, ho, T_END, configs, resumes=[r.state for r in first])
    for a, b in zip(rest, full):
        np.testing.assert_array_equal(a.history.loss, b.history.loss)
        assert _trees_equal(a.model, b.model) and a.best_epoch == b.best_epoch


def test_a_batch_of_one_is_train(ho):
    a = train(_model(1), ho, T_END, CFG.replace(seed=1, epochs=50))
    (b,) = train_batch([_model(1)], ho, T_END, [CFG.replace(seed=1, epochs=50)])
    np.testing.assert_array_equal(a.history.loss, b.history.loss)
    assert _trees_equal(a.model, b.model) and "batch_size" not in b.info


@pytest.mark.long
def test_runs_with_gamma_frozen_and_learned_share_a_batch(ho):
    """γ frozen is a traced flag of the one program: a batch may mix it, each run as alone, its
    γ bit for bit its initial one when frozen and its saved state in its own layout."""
    configs = [CFG, CFG.replace(seed=1, freeze_gamma=True)]
    models = [_model(0), _model(1)]
    batch = train_batch(models, ho, T_END, configs)
    for m, c, b in zip(models, configs, batch):
        _same_as_alone(b, train(m, ho, T_END, c))
    np.testing.assert_array_equal(batch[1].model.scaling.gamma_array(), models[1].scaling.gamma_array())
    assert not np.array_equal(batch[0].model.scaling.gamma_array(), models[0].scaling.gamma_array())
    mu = [b.opt_state.inner_state[0].mu for b in batch]
    assert all(x is None for x in jax.tree_util.tree_leaves(mu[1].scaling, is_leaf=lambda x: x is None))
    assert any(x is not None for x in jax.tree_util.tree_leaves(mu[0].scaling, is_leaf=lambda x: x is None))


def test_gamma_frozen_and_learned_are_one_compiled_program(ho):
    """A march's first window (γ learned) and its later ones (γ frozen) compile one chunk."""
    cfg = CFG.replace(epochs=80, n_points=64, chunk=40)  # a shape no other test compiles
    learned = train(_model(0), ho, T_END, cfg)
    frozen = train(_model(0), ho, T_END, cfg.replace(freeze_gamma=True))
    assert learned.compile_time > 0.0 and frozen.compile_time == 0.0


@pytest.mark.parametrize("change,match", [({"n_points": 50}, "n_points"), ({"chunk": 40}, "chunk"),
                                          ({"best_rule": "lowest"}, "best_rule")])
def test_runs_that_cannot_share_a_program_are_refused(ho, change, match):
    with pytest.raises(ConfigError, match=match):
        train_batch([_model(0), _model(1)], ho, T_END, [CFG, CFG.replace(seed=1, **change)])


def test_batch_arguments_are_checked(ho):
    with pytest.raises(ConfigError, match="one config per model"):
        train_batch([_model(0), _model(1)], ho, T_END, [CFG])
    with pytest.raises(ConfigError, match="T has 3 entries"):
        train_batch([_model(0), _model(1)], ho, [1.0, 2.0, 3.0], [CFG, CFG])

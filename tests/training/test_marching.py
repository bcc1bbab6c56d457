"""Time-marching ATLAS-NN: the hard constraint between windows, the piecewise solution, γ across
windows, compile reuse, the one-file checkpoint, and accuracy against the exact solution.

One marching run on the harmonic oscillator (module fixture) serves most tests; its windows share
one compiled training step.
"""

from __future__ import annotations

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.checkpoint import load_checkpoint, load_piecewise, save_checkpoint, save_piecewise
from atlasnn.errors import CheckpointError, ConfigError
from atlasnn.training import MarchConfig, march, n_windows_for
from atlasnn.training._marching import end_state
from atlasnn.nn import make_model
from atlasnn.solutions import PiecewiseSolution, window_edges
from atlasnn.systems import harmonic_exact
from atlasnn.training import DEFAULT_WINDOW, TrainConfig

# the module's fixture trains for a quarter to half a minute: the long tier
pytestmark = pytest.mark.long

T_END = 4 * math.pi
N_WIN = 4
CFG = MarchConfig(
    n_windows=N_WIN,
    train=TrainConfig(epochs=2500, lr=5e-3, n_points=60, sigma=0.5, progress=False, chunk=500,
                      lr_schedule="cosine", best_rule="lowest"),
)


def _model(seed=0):
    return make_model((1.0, 0.0), scaling="rational_exp", width=32, depth=2, seed=seed)


@pytest.fixture(scope="module")
def marched(ho):
    return march(_model(), ho, T_END, CFG)


def test_each_window_starts_exactly_at_the_previous_window_end_state(marched):
    w = marched.window_length
    assert marched.n_windows == N_WIN and np.isclose(w, T_END / N_WIN)
    for k in range(1, N_WIN):
        handed_on = np.asarray(end_state(marched.models[k - 1], w))
        assert np.array_equal(np.asarray(marched.models[k].z0), handed_on)
        # the trial solution itself is exact at its start: ẑ_k(0) = z_k bit for bit
        at_start = np.asarray(marched.models[k](jnp.zeros(3)))
        assert np.array_equal(at_start, np.broadcast_to(handed_on, at_start.shape))
        assert marched.windows[k].z_start == [float(x) for x in handed_on]
    assert np.array_equal(np.asarray(marched.models[0].z0), np.asarray(_model().z0))


def test_piecewise_solution_is_continuous_at_window_edges(marched):
    edges = marched.edges
    for k in range(1, N_WIN):
        at_edge = marched(edges[k])
        assert np.array_equal(at_edge, np.asarray(marched.models[k].z0))  # served by window k
        left = marched(np.nextafter(edges[k], -np.inf))  # served by window k-1 at s ≈ w
        assert np.max(np.abs(left - at_edge)) < 1e-5
        assert marched.window_index(np.nextafter(edges[k], -np.inf)) == k - 1


def test_piecewise_solution_evaluates_at_any_times(marched):
    rng = np.random.default_rng(0)
    t = rng.uniform(0, T_END, 37)  # unsorted
    t[:N_WIN + 1] = marched.edges  # exactly at every edge, t0 and T included
    z = marched(t)
    assert z.shape == (37, 2)
    k = marched.window_index(t)
    assert k.min() == 0 and k.max() == N_WIN - 1 and k[N_WIN] == N_WIN - 1  # T: the last window
    for i in range(t.size):  # the same values as each window model evaluated on its own
        s = t[i] - marched.edges[k[i]]
        direct = np.asarray(marched.models[k[i]](jnp.asarray([s], jnp.float32)))[0]
        np.testing.assert_allclose(z[i], direct, rtol=0, atol=2e-6)
    assert marched(float(t[5])).shape == (2,)  # a scalar
    assert marched(t.reshape(37, 1)).shape == (37, 1, 2)
    np.testing.assert_array_equal(marched(t[::-1]), z[::-1])
    assert marched.derivative(t).shape == (37, 2) and marched.energy(t).shape == (37,)
    assert marched.residual(t).shape == (37, 2)
    with pytest.raises(ValueError):
        marched(np.array([0.0, np.nan]))


def test_solution_like_attributes(marched):
    assert marched.interval == (0.0, T_END) and marched.t0 == 0.0
    np.testing.assert_array_equal(marched.z0, np.asarray(_model().z0, np.float64))
    assert set(marched.gamma) == {"alpha", "beta"}
    assert len(marched.windows) == N_WIN and all(w.epochs == 2500 for w in marched.windows)
    assert all(w.stop_reason == "budget" and np.isfinite(w.best_loss) for w in marched.windows)


def test_marching_is_accurate_over_several_windows(marched):
    t = np.linspace(0, T_END, 400)
    err = np.abs(marched(t) - harmonic_exact(t))
    assert err.max() < 1e-2
    assert np.max(np.abs(marched.energy(t) - 0.5)) < 5e-3


def test_gamma_is_frozen_across_windows_by_default(marched):
    first = marched.models[0].scaling
    for m in marched.models[1:]:
        assert np.array_equal(np.asarray(m.scaling.raw_alpha), np.asarray(first.raw_alpha))
        assert np.array_equal(np.asarray(m.scaling.raw_beta), np.asarray(first.raw_beta))
    assert marched.gamma != {"alpha": 1.0, "beta": 1.0}  # learned in window 0


def test_gamma_thawed_on_request(ho):
    cfg = CFG.replace(n_windows=2, thaw=True, train=CFG.train.replace(epochs=300))
    sol = march(_model(), ho, T_END / 2, cfg)
    assert sol.gammas[1] != sol.gammas[0]


def test_no_window_after_the_second_recompiles(marched):
    # window 0 compiles the γ-trainable step, window 1 the frozen-γ one, later windows reuse it
    compile_times = [w.compile_time for w in marched.windows]
    assert all(c == 0.0 for c in compile_times[2:])


def test_save_load_predicts_bit_identically_and_refuses_damage(marched, ho, tmp_path):
    path = tmp_path / "march.npz"
    digest = save_piecewise(path, marched, extra={"seed": 0})
    loaded = load_piecewise(path)
    assert isinstance(loaded, PiecewiseSolution) and loaded.info["content_sha256"] == digest
    t = np.linspace(-0.5, T_END + 0.5, 501)
    np.testing.assert_array_equal(loaded(t), marched(t))
    np.testing.assert_array_equal(loaded.edges, marched.edges)
    same = json.dumps([w.summary() for w in loaded.windows]) == json.dumps([w.summary() for w in marched.windows])
    assert same  # (JSON text: NaN entries compare equal)
    np.testing.assert_array_equal(loaded.windows[2].history, marched.windows[2].history)
    assert loaded.system.name == ho.name
    with pytest.raises(CheckpointError, match="load_piecewise"):
        load_checkpoint(path)
    plain = tmp_path / "plain.npz"
    save_checkpoint(plain, marched.models[0], ho)
    with pytest.raises(CheckpointError, match="no piecewise solution"):
        load_piecewise(plain)
    data = bytearray(path.read_bytes())
    i = data.index(b"piecewise_edges")  # damage a byte after that member's name (its data)
    data[i + 200] ^= 0x01
    (tmp_path / "bad.npz").write_bytes(bytes(data))
    with pytest.raises(CheckpointError):
        load_piecewise(tmp_path / "bad.npz")


def test_window_count_and_config_errors():
    assert n_windows_for(0.0, 20 * math.pi, MarchConfig(window=4 * math.pi)) == 5
    assert n_windows_for(0.0, 10.0, MarchConfig(window=3.0)) == 4
    np.testing.assert_allclose(window_edges(1.0, 3.0, 4), [1.0, 1.5, 2.0, 2.5, 3.0])
    assert n_windows_for(0.0, 24 * math.pi, MarchConfig(window=DEFAULT_WINDOW)) == 6  # 4π
    assert MarchConfig().adaptive and not MarchConfig(window=1.0).adaptive  # the default: windows by the estimate
    with pytest.raises(ConfigError, match="not both"):
        MarchConfig(n_windows=2, window=1.0)
    with pytest.raises(ConfigError, match="n_windows"):
        MarchConfig(n_windows=0)
    with pytest.raises(ConfigError, match="window"):
        MarchConfig(window=-1.0)
    with pytest.raises(ConfigError, match="march.train"):
        MarchConfig(n_windows=2, train={"epochs": 3})


def test_first_layer_scale_multiplies_the_initial_first_layer_only():
    """The network option of the marching defaults (DEFAULT_NETWORK): c × the plain draw."""
    plain = make_model((1.0, 0.0), width=16, depth=2, seed=3)
    scaled = make_model((1.0, 0.0), width=16, depth=2, seed=3, first_layer_scale=4.0)
    np.testing.assert_array_equal(np.asarray(scaled.net.weights[0]), 4.0 * np.asarray(plain.net.weights[0]))
    for a, b in zip(scaled.net.weights[1:] + scaled.net.biases, plain.net.weights[1:] + plain.net.biases):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    for bad in (0.0, -1.0, float("nan"), True):
        with pytest.raises(ConfigError, match="first_layer_scale"):
            make_model((1.0, 0.0), width=16, depth=2, first_layer_scale=bad)


@pytest.mark.slow  # 40 s; tests/training/test_train_batch.py checks each seed of a batch against its lone run
def test_seeds_marched_together_are_their_lone_marches(ho):
    from atlasnn.training import march_batch

    cfgs = [CFG.replace(train=CFG.train.replace(seed=s)) for s in (0, 1)]
    together = march_batch([_model(0), _model(1)], ho, T_END, cfgs)
    t = np.linspace(0.0, T_END, 200)
    for s, sol in enumerate(together):
        alone = march(_model(s), ho, T_END, cfgs[s])
        assert [r.epochs for r in sol.windows] == [r.epochs for r in alone.windows]
        np.testing.assert_allclose(sol(t), alone(t), rtol=0, atol=2e-4)  # rounding, grown over windows
        assert sol.info["batch_size"] == 2
    assert not np.allclose(together[0](t), together[1](t), atol=1e-6)


def test_outside_the_interval_warns_once_or_raises(marched):
    import warnings as w

    from atlasnn.solutions import ExtrapolationError, ExtrapolationWarning

    sol = PiecewiseSolution(marched.models, marched.system, marched.edges)
    with pytest.warns(ExtrapolationWarning, match="outside its training interval"):
        sol(np.array([0.0, T_END + 1.0]))
    with w.catch_warnings():
        w.simplefilter("error")
        sol(np.array([T_END + 2.0]))  # once per solution
        sol(np.linspace(0.0, T_END, 7))  # inside: silent
    strict = PiecewiseSolution(marched.models, marched.system, marched.edges, outside="raise")
    with pytest.raises(ExtrapolationError, match="PiecewiseSolution"):
        strict(np.array([-1.0]))


def test_load_piecewise_refuses_another_problem(marched, ho, tmp_path):
    from atlasnn.checkpoint import load_piecewise, save_piecewise
    from atlasnn.errors import CheckpointError
    from atlasnn.systems import nonlinear_oscillator

    path = tmp_path / "pw.npz"
    save_piecewise(path, marched)
    load_piecewise(path, expect={"system": ho, "interval": [0.0, T_END]})  # its own problem
    with pytest.raises(CheckpointError, match="not a model of the run X"):
        load_piecewise(path, expect={"system": nonlinear_oscillator()}, owner="the run X")
    with pytest.raises(CheckpointError, match="not a model of"):
        load_piecewise(path, expect={"interval": [0.0, 2 * T_END]})

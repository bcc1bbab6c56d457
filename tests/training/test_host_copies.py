"""Small host-side steps of a run (flattening parameters, stacking a seed batch's runs and copying
windows or runs out of a stack, restoring a checkpoint, starting Adam, the reference on several
grids) give the values the JAX operations they replace gave, and compile no program of their own
— done eagerly, each leaf shape and operation compiled one (70 programs in the first-hour run, 22
now: docs/PERFORMANCE.md).

Every test uses a network width no other test uses, so that a program compiled earlier in this
process cannot hide one compiled here."""

from __future__ import annotations

import contextlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring
from jax.flatten_util import ravel_pytree

from atlasnn.checkpoint import load_checkpoint, save_checkpoint
from atlasnn.evaluation import reference_solution, reference_solutions
from atlasnn.nn import make_model
from atlasnn.precision import on_device
from atlasnn.solutions import stack_models, unstack_models
from atlasnn.systems import henon_heiles, nonlinear_oscillator
from atlasnn.training import init_opt_state, trainable_filter, TrainConfig
from atlasnn.training._flat import cast_floats, ravel, unravel_on_host

_COMPILES: list[str] = []
_LISTENING = [False]


def _listener(event: str, secs: float, **kwargs) -> None:
    if _LISTENING[0] and event.endswith("backend_compile_duration"):
        _COMPILES.append(kwargs.get("fun_name", "?"))


monitoring.register_event_duration_secs_listener(_listener)


@contextlib.contextmanager
def compiled_programs():
    """The names of the programs compiled (or loaded from the cache) inside the block."""
    _COMPILES.clear()
    _LISTENING[0] = True
    try:
        yield _COMPILES
    finally:
        _LISTENING[0] = False


def _model(width: int, seed: int = 0):
    return make_model([0.3, -0.3, 0.3, 0.15], width=width, depth=2, seed=seed)


def _params(model):
    import equinox as eqx

    return eqx.partition(model, trainable_filter(model, False))[0]


def _same_leaves(a, b):
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb):
        assert np.asarray(x).dtype == np.asarray(y).dtype and np.asarray(x).shape == np.asarray(y).shape
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_on_device_rounds_as_jnp_asarray():
    for value in (0.1, 1 / 3, 1e-8, np.pi, -2.5e30):
        a, b = on_device(value, jnp.float32), jnp.asarray(value, jnp.float32)
        assert a.dtype == b.dtype and not a.weak_type
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
    z = np.array([0.1, 0.2, 1 / 3, 7.0])
    assert np.asarray(on_device(z, jnp.float32)).tobytes() == np.asarray(jnp.asarray(z, jnp.float32)).tobytes()
    assert on_device(-1, jnp.int32).dtype == jnp.int32 and on_device(True, bool).dtype == jnp.bool_


def test_ravel_and_unravel_on_host_are_ravel_pytrees_and_compile_nothing():
    params = _params(_model(17))
    x_ref, unravel_ref = ravel_pytree(params)
    shifted = x_ref + 1
    with compiled_programs() as names:
        x, unravel = ravel(params)
        back = unravel_on_host(shifted, params)
    assert names == []
    assert x.dtype == x_ref.dtype and np.asarray(x).tobytes() == np.asarray(x_ref).tobytes()
    assert unravel == unravel_ref  # ravel_pytree's own function (a hashable partial of shapes and dtypes)
    _same_leaves(back, unravel_ref(shifted))


def test_cast_floats_matches_jnp_asarray_and_keeps_other_leaves():
    model = _model(19)
    with jax.enable_x64(True):
        up = cast_floats(model, jnp.float64)
        expected = jax.tree_util.tree_map(lambda v: jnp.asarray(v, jnp.float64) if hasattr(v, "dtype")
                                          and jnp.issubdtype(v.dtype, jnp.floating) else v, model)
        _same_leaves(up, expected)
    down = cast_floats(up, jnp.float32)
    _same_leaves(down, model)
    assert float(down.t0) == float(model.t0)


def test_unstack_models_copies_windows_out_exactly_without_compiling():
    models = [_model(23, seed=s) for s in range(3)]
    stacked = stack_models(models)
    with compiled_programs() as names:
        windows = unstack_models(stacked, 3)
    assert names == []
    for got, want in zip(windows, models):
        _same_leaves(got, want)


def test_stacking_runs_of_a_seed_batch_equals_jnp_stack_without_compiling():
    models = [_model(41, seed=s) for s in range(3)]
    params = [_params(m) for m in models]
    states = [init_opt_state(p, TrainConfig(epochs=10), jnp.float32) for p in params]
    with compiled_programs() as names:
        stacked = stack_models(states)
    assert names == []
    want = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *states)
    assert jax.tree_util.tree_structure(stacked) == jax.tree_util.tree_structure(want)
    _same_leaves(stacked, want)
    with compiled_programs() as names:
        back = unstack_models(stacked, 3)
    assert names == []
    _same_leaves(back[2], states[2])


def test_unstack_models_keeps_float64_windows_float64():
    with jax.enable_x64(True):
        models = [cast_floats(_model(29, seed=s), jnp.float64) for s in range(2)]
        stacked = stack_models(models)
    windows = unstack_models(stacked, 2)  # JAX's float64 mode is off again here
    assert windows[1].z0.dtype == jnp.float64
    _same_leaves(windows[1], models[1])


def test_restoring_a_checkpoint_compiles_nothing(tmp_path):
    model = _model(31, seed=4)
    path = tmp_path / "m.atlas"
    save_checkpoint(path, model, henon_heiles())
    with compiled_programs() as names:
        ck = load_checkpoint(path)
    assert names == []
    _same_leaves(ck.model, model)


def test_adam_starts_in_one_program():
    params = _params(_model(37))
    with compiled_programs() as names:
        state = init_opt_state(params, TrainConfig(epochs=10), jnp.float32)
    assert len(names) == 1
    mu = state.inner_state[0].mu
    _same_leaves(mu, jax.tree_util.tree_map(jnp.zeros_like, params))
    assert float(state.hyperparams["learning_rate"]) == pytest.approx(TrainConfig(epochs=10).lr)


@pytest.mark.parametrize("system, z0, T", [(henon_heiles(), [0.3, -0.3, 0.3, 0.15], 12.0),
                                           (nonlinear_oscillator(), [1.0, 0.0], 9.0)])
def test_reference_solutions_equal_one_solve_per_grid_bit_for_bit(system, z0, T):
    grids = [np.linspace(0.0, T, 200), np.linspace(0.0, T, 1991), np.linspace(0.0, T / 3, 50),
             np.linspace(0.0, T, 200)]
    together = reference_solutions(system, z0, grids)
    for grid, z in zip(grids, together):
        alone = reference_solution(system, z0, grid)
        assert z.shape == alone.shape
        assert z.tobytes() == alone.tobytes()

"""Tests of the trial solution ẑ(t) = z0 + f(t − t0; γ) N(t; θ) and of the physics loss."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.training import hamilton_residual, physics_loss
from atlasnn.nn import MLP, TrialSolution, make_model
from atlasnn.nn import ExpDecay, RationalExp, Tanh, make_scaling
from atlasnn.systems import henon_heiles, nonlinear_oscillator

SCALING_NAMES = ["exp_decay", "tanh", "rational_exp"]


@jax.jit
def _call(model, t):
    return model(t)


@jax.jit
def _value_and_rate(model, t):
    return model.value_and_rate(t)


# --------------------------------------------------------------------- ẑ(t0) = z0 exactly
@pytest.mark.parametrize(
    "scaling, z0, t0",
    [(name, (0.3, -0.3, 0.3, 0.15), 0.75) for name in SCALING_NAMES] + [("rational_exp", (1.3, 1.0), 0.0)],
)
@pytest.mark.long
def test_initial_condition_is_exact(scaling, z0, t0):
    gamma = {"tanh": {"m": 2.7}, "rational_exp": {"alpha": 0.3, "beta": 4.0}}.get(scaling)
    model = make_model(z0, scaling=scaling, width=16, depth=2, t0=t0, gamma=gamma, seed=3)
    z0_32 = np.asarray(z0, dtype=np.float32)
    t = jnp.asarray([t0, t0 + 0.5, t0 + 3.0], dtype=jnp.float32)
    out = np.asarray(_call(model, t))
    assert out.shape == (3, len(z0)) and out.dtype == np.float32
    np.testing.assert_array_equal(out[0], z0_32)
    value, _ = _value_and_rate(model, t)
    np.testing.assert_array_equal(np.asarray(value)[0], z0_32)
    # away from t0 the network does contribute (the equality above is not trivial)
    assert np.max(np.abs(out[1:] - z0_32)) > 1e-3
    # whatever the weights are: scale them up and t0 still returns z0
    big = eqx.tree_at(lambda m: m.net.weights[-1], model, model.net.weights[-1] * 1000.0)
    np.testing.assert_array_equal(np.asarray(_call(big, t))[0], z0_32)


# ---------------------------------------------------------------- dẑ/dt against differences
@pytest.mark.parametrize("scaling", SCALING_NAMES)
def test_rate_matches_central_difference_float64(scaling):
    with jax.enable_x64(True):
        model = make_model((0.3, -0.3, 0.3, 0.15), scaling=scaling, width=16, depth=2, t0=0.2, seed=1)
        assert model.net.weights[0].dtype == jnp.float64
        t = jnp.linspace(0.2, 6.0, 13)
        z, dz = map(np.asarray, _value_and_rate(model, t))
        assert dz.dtype == np.float64
        h = 1e-6
        fd = (np.asarray(_call(model, t + h)) - np.asarray(_call(model, t - h))) / (2 * h)
        np.testing.assert_allclose(dz, fd, rtol=1e-7, atol=1e-8)
        np.testing.assert_array_equal(z, np.asarray(_call(model, t)))
        assert np.max(np.abs(dz)) > 1e-2


def test_rate_at_t0_is_fdot_times_network():
    # at t0, f = 0, so dẑ/dt = ḟ(0) N(t0); for the rational exp, ḟ(0) = α/(1 + β)
    with jax.enable_x64(True):
        alpha, beta = 1.6, 0.6
        gamma = {"alpha": alpha, "beta": beta}
        model = make_model((0.3, -0.3, 0.3, 0.15), scaling="rational_exp", gamma=gamma, width=16, depth=2, seed=2)
        t = jnp.asarray([0.0])
        _, dz = _value_and_rate(model, t)
        n0 = np.asarray(model.net(t))[0]
        np.testing.assert_allclose(np.asarray(dz)[0], alpha / (1 + beta) * n0, rtol=1e-12, atol=1e-15)


# -------------------------------------------------------------------- the loss by hand
def _osc_field(z, lam):
    x, p = z
    return np.array([p, -x - lam * x**3])


def _osc_energy(z, lam):
    x, p = z
    return p**2 / 2 + x**2 / 2 + lam * x**4 / 4


def _hh_field(z, lam):
    x, y, px, py = z
    return np.array([px, py, -x - 2 * lam * x * y, -y - lam * (x**2 - y**2)])


def _hh_energy(z, lam):
    x, y, px, py = z
    return (px**2 + py**2) / 2 + (x**2 + y**2) / 2 + lam * (x**2 * y - y**3 / 3)


@pytest.mark.parametrize(
    "make_system, field, energy, scaling, lam_reg",
    [
        (nonlinear_oscillator, _osc_field, _osc_energy, "rational_exp", 1.0),
        (nonlinear_oscillator, _osc_field, _osc_energy, "tanh", 0.0),
        (henon_heiles, _hh_field, _hh_energy, "exp_decay", 0.5),
    ],
)
@pytest.mark.long
def test_loss_equals_hand_computation(make_system, field, energy, scaling, lam_reg):
    lam = 0.7
    with jax.enable_x64(True):
        system = make_system(lam=lam)
        model = make_model(system.z0, scaling=scaling, width=16, depth=2, seed=5)
        t = np.linspace(0.0, 3.0, 7) + 0.01 * np.arange(7) ** 2

        # per point: ẑ(t_n) and dẑ/dt(t_n) by jax.jacfwd of the scalar-input map
        def z_of(s):
            return model(jnp.reshape(s, (1,)))[0]

        z_fn, dz_fn = jax.jit(z_of), jax.jit(jax.jacfwd(z_of))
        Z = np.stack([np.asarray(z_fn(s)) for s in t])
        dZ = np.stack([np.asarray(dz_fn(s)) for s in t])
        E0 = energy(np.asarray(system.z0), lam)
        R = dZ - np.stack([field(z, lam) for z in Z])
        residual = np.mean(np.sum(R**2, axis=1))
        penalty = np.mean((np.array([energy(z, lam) for z in Z]) - E0) ** 2)
        want = residual + lam_reg * penalty

        loss_fn = jax.jit(physics_loss, static_argnums=1)
        loss, (res, pen) = loss_fn(model, system, jnp.asarray(t), jnp.asarray(E0), jnp.asarray(lam_reg))
        assert float(loss) == pytest.approx(want, rel=1e-11)
        assert float(res) == pytest.approx(residual, rel=1e-11)
        assert float(pen) == pytest.approx(penalty, rel=1e-11, abs=1e-300)
        # the release's form: the sum over components of per-component means
        assert float(res) == pytest.approx(sum(np.mean(R[:, c] ** 2) for c in range(R.shape[1])), rel=1e-11)
        assert penalty > 0 and residual > 0

        r, z = jax.jit(hamilton_residual, static_argnums=1)(model, system, jnp.asarray(t))
        np.testing.assert_allclose(np.asarray(r), R, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(np.asarray(z), Z, rtol=1e-13, atol=1e-14)


# ---------------------------------------------------------------------------- the network
def test_mlp_init_bounds_and_shapes():
    width, depth, out = 32, 2, 2  # the shape the training tests use
    net = MLP(out, width, depth, jax.random.PRNGKey(0))
    sizes = [1] + [width] * depth + [out]
    assert len(net.weights) == depth + 1 and len(net.biases) == depth + 1
    assert (net.width, net.depth, net.out_size) == (width, depth, out)
    for i, (w, b) in enumerate(zip(net.weights, net.biases)):
        fan_in, fan_out = sizes[i], sizes[i + 1]
        bound = 1 / np.sqrt(fan_in)
        w, b = np.asarray(w), np.asarray(b)
        assert w.shape == (fan_out, fan_in) and b.shape == (fan_out,)
        assert w.dtype == np.float32 and b.dtype == np.float32
        assert np.all(np.abs(w) <= bound) and np.all(np.abs(b) <= bound)
        # uniform over the whole range, not a narrower one
        assert np.max(np.abs(w)) > 0.9 * bound
        if b.size >= 32:
            assert np.max(np.abs(b)) > 0.8 * bound
            assert abs(np.mean(b)) < 0.25 * bound


def test_mlp_forward_matches_numpy():
    net = MLP(2, 16, 2, jax.random.PRNGKey(4))
    t = np.linspace(0, 2, 6)
    W = [np.asarray(w, np.float64) for w in net.weights]
    B = [np.asarray(b, np.float64) for b in net.biases]
    h = t[:, None]
    for w, b in zip(W[:-1], B[:-1]):
        h = np.sin(h @ w.T + b)  # sin is the default activation, as in the release
    want = h @ W[-1].T + B[-1]
    np.testing.assert_allclose(np.asarray(net(jnp.asarray(t, jnp.float32))), want, rtol=1e-5, atol=1e-6)


def test_seed_determinism():
    a = make_model((1.0, 0.0), width=16, depth=2, seed=7)
    b = make_model((1.0, 0.0), width=16, depth=2, seed=7)
    c = make_model((1.0, 0.0), width=16, depth=2, seed=8)
    for wa, wb in zip(a.net.weights, b.net.weights):
        np.testing.assert_array_equal(np.asarray(wa), np.asarray(wb))
    assert not np.array_equal(np.asarray(a.net.weights[1]), np.asarray(c.net.weights[1]))


def test_architecture_contents():
    model = make_model((0.3, -0.3, 0.3, 0.15), scaling="tanh", width=16, depth=2, t0=0.5, activation="tanh")
    assert model.architecture() == {
        "width": 16,
        "depth": 2,
        "activation": "tanh",
        "state_dim": 4,
        "scaling": "tanh",
        "t0": 0.5,
    }
    default = make_model((1.0, 0.0)).architecture()
    assert default == {
        "width": 50, "depth": 2, "activation": "sin", "state_dim": 2, "scaling": "rational_exp", "t0": 0.0,
    }


@pytest.mark.parametrize(
    "name, cls", [("hnn", ExpDecay), ("atlas_tanh", Tanh), ("atlas_exp", RationalExp), ("exp_decay", ExpDecay)]
)
def test_paper_model_names(name, cls):
    model = make_model((1.0, 0.0), scaling=name, width=16, depth=2)
    assert type(model.scaling) is cls


def test_gamma_and_scaling_instance():
    model = make_model((1.0, 0.0), scaling="atlas_tanh", gamma={"m": 3.0}, width=16, depth=2)
    assert float(model.scaling.gamma()["m"]) == pytest.approx(3.0, rel=1e-6)
    inst = make_scaling("rational_exp", {"alpha": 2.0})
    model = make_model((1.0, 0.0), scaling=inst, width=16, depth=2)
    assert model.scaling is inst
    assert isinstance(model, TrialSolution) and model.state_dim == 2


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(z0=(1.0,)),
        dict(z0=(1.0, 2.0, 3.0)),
        dict(z0=()),
        dict(z0=(1.0, float("nan"))),
        dict(z0=(1.0, 0.0), width=0),
        dict(z0=(1.0, 0.0), depth=0),
        dict(z0=(1.0, 0.0), width=2.5),
        dict(z0=(1.0, 0.0), depth=True),
        dict(z0=(1.0, 0.0), activation="relu"),
        dict(z0=(1.0, 0.0), scaling="sigmoid"),
        dict(z0=(1.0, 0.0), scaling="tanh", gamma={"m": -1.0}),
        dict(z0=(1.0, 0.0), scaling=Tanh(2.0), gamma={"m": 1.0}),
    ],
)
def test_bad_model_config(kwargs):
    z0 = kwargs.pop("z0")
    with pytest.raises(ConfigError) as exc:
        make_model(z0, **kwargs)
    assert "\n" not in str(exc.value)


def test_float32_sin_cos_matches_numpy_and_differentiates_as_sin_cos():
    """The network's fused sin/cos (own polynomial fit, shared range reduction) is float32-exact enough."""
    from atlasnn.nn import SINCOS_FAST_LIMIT, sin_cos

    x = jnp.linspace(-200.0, 200.0, 400_001, dtype=jnp.float32)
    s, c = sin_cos(x)
    xs = np.asarray(x, np.float64)
    assert np.abs(np.asarray(s, np.float64) - np.sin(xs)).max() < 6e-8
    assert np.abs(np.asarray(c, np.float64) - np.cos(xs)).max() < 6e-8
    ds = jax.vmap(jax.grad(lambda v: sin_cos(v)[0]))(x[:1000])
    np.testing.assert_array_equal(np.asarray(ds), np.asarray(sin_cos(x[:1000])[1]))
    big = jnp.asarray([SINCOS_FAST_LIMIT * 4, 1e6], jnp.float32)  # falls back to XLA's sin/cos
    np.testing.assert_allclose(np.asarray(sin_cos(big)[0]), np.sin(np.asarray(big, np.float64)), atol=1e-6)

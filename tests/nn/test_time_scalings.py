"""Tests of the time scalings f(t; γ): boundary value, monotonicity, limits, derivatives, γ."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.nn import MODELS, ExpDecay, RationalExp, Tanh, inverse_softplus, make_scaling, softplus

SCALINGS = {kind.scaling.name: kind.scaling for kind in MODELS.values()}

SEEDS = [0, 1, 2, 3, 4]
T_GRID = np.linspace(0.0, 30.0, 601)


@jax.jit
def _values_and_rates(f, t):
    """(f(t), ḟ(t)); jitted once per scaling class and dtype (faster than op-by-op)."""
    return f(t), f.derivative(t)


@jax.jit
def _autodiff_rates(f, t):
    return jax.vmap(jax.grad(lambda s: f(s)))(t)


def _random_scaling(name: str, seed: int):
    """A scaling with γ drawn log-uniformly from [0.05, 5]."""
    rng = np.random.default_rng(seed)
    draw = lambda: float(np.exp(rng.uniform(np.log(0.05), np.log(5.0))))  # noqa: E731
    if name == "exp_decay":
        return make_scaling(name)
    if name == "tanh":
        return make_scaling(name, {"m": draw()})
    return make_scaling(name, {"alpha": draw(), "beta": draw()})


# ------------------------------------------------------------------ f(0) = 0, ḟ > 0, f → 1
@pytest.mark.parametrize("name", sorted(SCALINGS))
@pytest.mark.parametrize("seed", SEEDS)
def test_zero_at_origin_and_strictly_increasing_float64(name, seed):
    with jax.enable_x64(True):
        f = _random_scaling(name, seed)
        t = jnp.asarray(T_GRID)
        values, rates = map(np.asarray, _values_and_rates(f, t))
        assert values.dtype == np.float64
        assert values[0] == 0.0  # exactly, so that ẑ(t0) = z0 exactly
        assert float(f(jnp.zeros(()))) == 0.0
        # the true ḟ is at least ~1e-129 on this grid: representable in float64
        assert np.all(rates > 0), (name, f.gamma(), rates.min())
        assert np.all(np.isfinite(rates))
        # non-decreasing up to a few ulps (XLA's tanh wobbles by an ulp next to 1)
        assert np.all(np.diff(values) >= -4 * np.finfo(np.float64).eps)
        assert np.all((values >= 0) & (values <= 1))


@pytest.mark.parametrize("name", sorted(SCALINGS))
@pytest.mark.parametrize("seed", SEEDS)
def test_zero_at_origin_and_nondecreasing_float32(name, seed):
    f = _random_scaling(name, seed)
    t = jnp.asarray(T_GRID, dtype=jnp.float32)
    values, rates = map(np.asarray, _values_and_rates(f, t))
    assert values.dtype == np.float32
    assert values[0] == 0.0
    # float32 underflows ḟ once it is below ~1e-45; it must never turn negative or NaN
    assert np.all(rates >= 0) and np.all(np.isfinite(rates))
    assert rates[0] > 0
    # where f has not saturated to 1 in float32, ḟ is strictly positive
    assert np.all(rates[values < 1.0] > 0)
    assert np.all(np.diff(values) >= -4 * np.finfo(np.float32).eps)


@pytest.mark.parametrize("name", sorted(SCALINGS))
@pytest.mark.parametrize("seed", SEEDS)
def test_tends_to_one(name, seed):
    with jax.enable_x64(True):
        f = _random_scaling(name, seed)
        # smallest rate is 0.05: at t = 1000, 1 − f ≲ e^{−50}
        far = np.asarray(f(jnp.asarray([1000.0, 5000.0])))
        assert np.allclose(far, 1.0, rtol=0, atol=1e-12)
        # and not already 1 at a small time (the limit is approached, not jumped to)
        assert float(f(jnp.asarray(0.01))) < 0.5


@pytest.mark.parametrize("name", sorted(SCALINGS))
@pytest.mark.parametrize("seed", SEEDS[:3])
def test_derivative_equals_autodiff(name, seed):
    with jax.enable_x64(True):
        f = _random_scaling(name, seed)
        t = jnp.asarray(T_GRID)
        auto = np.asarray(_autodiff_rates(f, t))
        closed = np.asarray(_values_and_rates(f, t)[1])
        # atol only covers the cancellation of autodiff's own 1 − tanh² near saturation
        np.testing.assert_allclose(closed, auto, rtol=1e-5, atol=1e-13)
        # and on the part of the grid where ḟ is not tiny, the relative agreement is tight
        big = auto > 1e-3
        assert big.sum() > 10
        np.testing.assert_allclose(closed[big], auto[big], rtol=1e-10)


def test_derivative_equals_autodiff_float32():
    f = make_scaling("rational_exp", {"alpha": 1.3, "beta": 0.4})
    t = jnp.linspace(0.0, 5.0, 51)
    auto = np.asarray(_autodiff_rates(f, t))
    np.testing.assert_allclose(np.asarray(_values_and_rates(f, t)[1]), auto, rtol=1e-5, atol=1e-7)


# --------------------------------------------------------------------------- closed forms
def test_exp_decay_formula():
    with jax.enable_x64(True):
        t = np.linspace(0, 10, 41)
        f = ExpDecay()
        np.testing.assert_allclose(np.asarray(f(jnp.asarray(t))), 1 - np.exp(-t), rtol=1e-14, atol=1e-16)
        np.testing.assert_allclose(np.asarray(f.derivative(jnp.asarray(t))), np.exp(-t), rtol=1e-14)
        assert f.gamma() == {}
        assert f.gamma_array().shape == (0,)


def test_tanh_formula():
    with jax.enable_x64(True):
        t = np.linspace(0, 10, 41)
        f = Tanh(m=0.7)
        np.testing.assert_allclose(np.asarray(f(jnp.asarray(t))), np.tanh(0.7 * t), rtol=1e-13)
        np.testing.assert_allclose(
            np.asarray(f.derivative(jnp.asarray(t))), 0.7 / np.cosh(0.7 * t) ** 2, rtol=1e-12
        )


@pytest.mark.parametrize("alpha", [0.05, 0.6, 1.0, 2.5, 5.0])
def test_rational_exp_beta_one_is_tanh(alpha):
    with jax.enable_x64(True):
        t = np.linspace(0, 30, 301)
        f = make_scaling("rational_exp", {"alpha": alpha, "beta": 1.0})
        np.testing.assert_allclose(np.asarray(f(jnp.asarray(t))), np.tanh(alpha * t / 2), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("alpha", [0.05, 0.6, 1.0, 2.5, 5.0])
def test_rational_exp_small_beta_is_exp_decay(alpha):
    with jax.enable_x64(True):
        t = np.linspace(0, 30, 301)
        beta = 1e-6
        f = make_scaling("rational_exp", {"alpha": alpha, "beta": beta})
        target = -np.expm1(-alpha * t)
        got = np.asarray(f(jnp.asarray(t)))
        # (1 − e)/(1 + βe) − (1 − e) = −βe(1 − e)/(1 + βe): at most β/4 in size
        assert np.max(np.abs(got - target)) <= beta / 4 * 1.01
        # β = 1 is far from it: the comparison is not vacuous
        g1 = np.asarray(make_scaling("rational_exp", {"alpha": alpha, "beta": 1.0})(jnp.asarray(t)))
        assert np.max(np.abs(g1 - target)) > 0.1


def test_rational_exp_derivative_closed_form():
    with jax.enable_x64(True):
        a, b = 1.7, 0.3
        t = np.linspace(0, 8, 33)
        f = RationalExp(alpha=a, beta=b)
        e = np.exp(-a * t)
        want = a * (1 + b) * e / (1 + b * e) ** 2
        np.testing.assert_allclose(np.asarray(f.derivative(jnp.asarray(t))), want, rtol=1e-12)


# -------------------------------------------------------------------------------- γ
def test_gamma_defaults_are_one():
    g = make_scaling("tanh").gamma()
    assert set(g) == {"m"} and float(g["m"]) == pytest.approx(1.0, rel=1e-6)
    g = make_scaling("rational_exp").gamma()
    assert set(g) == {"alpha", "beta"}
    assert float(g["alpha"]) == pytest.approx(1.0, rel=1e-6)
    assert float(g["beta"]) == pytest.approx(1.0, rel=1e-6)
    assert make_scaling("exp_decay").gamma() == {}


def test_gamma_configurable():
    assert float(make_scaling("tanh", {"m": 3.0}).gamma()["m"]) == pytest.approx(3.0, rel=1e-6)
    f = make_scaling("rational_exp", {"alpha": 2.0, "beta": 0.5})
    assert float(f.gamma()["alpha"]) == pytest.approx(2.0, rel=1e-6)
    assert float(f.gamma()["beta"]) == pytest.approx(0.5, rel=1e-6)
    # gamma_array follows gamma_names
    np.testing.assert_allclose(np.asarray(f.gamma_array()), [2.0, 0.5], rtol=1e-6)
    # only one given: the other keeps its default
    f = make_scaling("rational_exp", {"beta": 0.25})
    assert float(f.gamma()["alpha"]) == pytest.approx(1.0, rel=1e-6)
    assert float(f.gamma()["beta"]) == pytest.approx(0.25, rel=1e-6)


def test_only_raw_gamma_are_array_leaves():
    f = make_scaling("rational_exp", {"alpha": 2.0, "beta": 0.5})
    leaves = jax.tree_util.tree_leaves(eqx.filter(f, eqx.is_inexact_array))
    assert len(leaves) == 2
    np.testing.assert_allclose(np.asarray(softplus(jnp.stack(leaves))), [2.0, 0.5], rtol=1e-6)
    assert len(jax.tree_util.tree_leaves(make_scaling("tanh"))) == 1
    assert jax.tree_util.tree_leaves(make_scaling("exp_decay")) == []


@pytest.mark.parametrize(
    "alias, cls",
    [("hnn", ExpDecay), ("exp_decay", ExpDecay), ("atlas_tanh", Tanh), ("TANH", Tanh),
     ("exp", RationalExp), ("atlas-exp", RationalExp), ("rational_exp", RationalExp)],
)
def test_aliases(alias, cls):
    assert type(make_scaling(alias)) is cls


@pytest.mark.parametrize(
    "name, gamma",
    [
        ("sigmoid", None),
        ("", None),
        ("tanh", {"m": 0.0}),
        ("tanh", {"m": -1.0}),
        ("tanh", {"m": float("nan")}),
        ("tanh", {"m": float("inf")}),
        ("tanh", {"m": True}),
        ("tanh", {"m": "3"}),
        ("tanh", {"alpha": 1.0}),
        ("rational_exp", {"m": 1.0}),
        ("rational_exp", {"beta": -0.5}),
        ("exp_decay", {"m": 1.0}),
    ],
)
def test_bad_names_and_values(name, gamma):
    with pytest.raises(ConfigError) as exc:
        make_scaling(name, gamma)
    assert "\n" not in str(exc.value)


# ------------------------------------------------------------------------ inverse softplus
@pytest.mark.parametrize("y", [1e-6, 1e-3, 0.05, 0.5, 1.0, 3.0, 20.0, 60.0, 500.0])
def test_inverse_softplus_round_trip(y):
    x = inverse_softplus(y)
    assert math.isfinite(x)
    assert np.logaddexp(0.0, x) == pytest.approx(y, rel=1e-12)
    with jax.enable_x64(True):
        assert float(softplus(jnp.asarray(x))) == pytest.approx(y, rel=1e-12)


def test_inverse_softplus_known_value():
    # softplus(0) = log 2
    assert inverse_softplus(math.log(2.0)) == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("y", [0.0, -1.0, float("nan"), float("inf"), float("-inf")])
def test_inverse_softplus_rejects(y):
    with pytest.raises(ConfigError):
        inverse_softplus(y)

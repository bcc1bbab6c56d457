"""Tests of the error metrics on inputs whose answers are known in closed form or by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.evaluation import (
    energy_drift,
    error_table,
    improvement,
    interpolate_to,
    l2_discrete,
    l2_integral,
    max_abs_error,
    mse,
    state_metric_names,
)

# A tiny trajectory: err = pred − ref = [[0, 1], [2, 3], [4, 5]].
PRED = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
REF = np.ones((3, 2))
T3 = np.array([0.0, 1.0, 3.0])


def _one_line(exc_info) -> str:
    msg = str(exc_info.value)
    assert msg and "\n" not in msg
    return msg


# --------------------------------------------------------------------------- L2 integral
def test_l2_integral_of_sine_is_sqrt_pi():
    t = np.linspace(0.0, 2 * math.pi, 20001)
    err = np.sin(t)[:, None]
    val = l2_integral(t, err, np.zeros_like(err))
    assert val.shape == (1,)
    assert val[0] == pytest.approx(math.sqrt(math.pi), rel=1e-4)
    # 1-D input gives a float.
    assert l2_integral(t, np.sin(t), np.zeros_like(t)) == pytest.approx(math.sqrt(math.pi), rel=1e-4)


def test_l2_integral_whole_state():
    t = np.linspace(0.0, 2 * math.pi, 20001)
    z = np.stack([np.sin(t), np.cos(t)], axis=1)
    per = l2_integral(t, z, np.zeros_like(z))
    np.testing.assert_allclose(per, [math.sqrt(math.pi)] * 2, rtol=1e-4)
    # ∫ (sin² + cos²) dt = 2π.
    assert l2_integral(t, z, np.zeros_like(z), whole=True) == pytest.approx(math.sqrt(2 * math.pi), rel=1e-10)


def test_l2_integral_hand_trapezoid():
    # err² = [0,4,16] and [1,9,25] on t = [0,1,3]: trapezoid = (0+4)/2·1 + (4+16)/2·2 = 22,
    # and (1+9)/2·1 + (9+25)/2·2 = 39.
    val = l2_integral(T3, PRED, REF)
    np.testing.assert_allclose(val, [math.sqrt(22.0), math.sqrt(39.0)], rtol=1e-15)
    assert l2_integral(T3, PRED, REF, whole=True) == pytest.approx(math.sqrt(61.0), rel=1e-15)


def test_l2_integral_grid_checks():
    with pytest.raises(ConfigError) as ei:
        l2_integral(np.array([0.0, 1.0]), PRED, REF)
    assert "t" in _one_line(ei)
    with pytest.raises(ConfigError):
        l2_integral(np.array([0.0, 2.0, 1.0]), PRED, REF)


# --------------------------------------------------------------------- discrete metrics
def test_l2_discrete_by_hand():
    np.testing.assert_allclose(l2_discrete(PRED, REF), [math.sqrt(20.0), math.sqrt(35.0)], rtol=1e-15)
    assert l2_discrete(PRED, REF, whole=True) == pytest.approx(math.sqrt(55.0), rel=1e-15)
    # Not scaled by Δt: doubling the samples (same errors twice) multiplies it by √2.
    twice = l2_discrete(np.vstack([PRED, PRED]), np.vstack([REF, REF]))
    np.testing.assert_allclose(twice, np.sqrt(2.0) * l2_discrete(PRED, REF), rtol=1e-15)


def test_mse_by_hand():
    np.testing.assert_allclose(mse(PRED, REF), [20.0 / 3.0, 35.0 / 3.0], rtol=1e-15)
    assert mse(PRED, REF, whole=True) == pytest.approx(55.0 / 3.0, rel=1e-15)


def test_max_abs_by_hand():
    np.testing.assert_array_equal(max_abs_error(PRED, REF), [4.0, 5.0])
    np.testing.assert_array_equal(max_abs_error(REF, PRED), [4.0, 5.0])
    assert max_abs_error(PRED, REF, whole=True) == 5.0


@pytest.mark.parametrize(
    "fn",
    [
        lambda a, b: l2_integral(np.arange(a.shape[0], dtype=float), a, b),
        l2_discrete,
        mse,
        max_abs_error,
        lambda a, b: error_table(np.arange(a.shape[0], dtype=float), a, b, ["x", "p"]),
    ],
)
@pytest.mark.parametrize("other", [np.ones((4, 2)), np.ones((3, 3)), np.ones(3), np.ones((3, 2, 1))])
def test_shape_mismatch_raises(fn, other):
    with pytest.raises(ConfigError) as ei:
        fn(PRED, other)
    assert isinstance(ei.value, AtlasError)
    _one_line(ei)


def test_shape_mismatch_message_points_to_interpolate_to():
    with pytest.raises(ConfigError) as ei:
        l2_discrete(PRED, np.ones((4, 2)))
    msg = _one_line(ei)
    assert "(3, 2)" in msg and "(4, 2)" in msg and "interpolate_to" in msg


# ------------------------------------------------------------------------ energy, improvement
def test_energy_drift():
    assert energy_drift([2.0, 2.2, 1.9], 2.0) == pytest.approx(0.1, rel=1e-12)
    assert energy_drift([-2.0, -2.2, -1.9], -2.0) == pytest.approx(0.1, rel=1e-12)
    # E0 = 0: absolute drift.
    assert energy_drift([0.0, 0.3, -0.5], 0.0) == pytest.approx(0.5, rel=1e-15)
    assert energy_drift(np.full(5, 1.5), 1.5) == 0.0
    with pytest.raises(ConfigError):
        energy_drift([], 1.0)


def test_improvement_signed():
    assert improvement(2.0, 1.0) == 50.0
    assert improvement(1.0, 2.0) == -100.0
    assert improvement(1.0, 2.0) < 0
    assert improvement(4.0, 4.0) == 0.0
    out = improvement(np.array([2.0, 1.0, 10.0]), np.array([1.0, 2.0, 1.0]))
    np.testing.assert_allclose(out, [50.0, -100.0, 90.0], rtol=1e-15)
    # Broadcasting one baseline against several models.
    np.testing.assert_allclose(improvement(2.0, [1.0, 3.0]), [50.0, -50.0], rtol=1e-15)
    assert math.isnan(improvement(0.0, 1.0))
    with pytest.raises(ConfigError):
        improvement([1.0, 2.0], [1.0, 2.0, 3.0])


# ------------------------------------------------------------------------------ interpolation
def test_interpolate_smooth_function_accurately():
    ts = np.linspace(0.0, 2 * math.pi, 201)
    zs = np.stack([np.sin(ts), np.cos(2 * ts)], axis=1)
    td = np.linspace(0.0, 2 * math.pi, 1003)
    exact = np.stack([np.sin(td), np.cos(2 * td)], axis=1)
    cubic = interpolate_to(ts, zs, td)
    assert cubic.shape == (1003, 2) and cubic.dtype == np.float64
    assert np.max(np.abs(cubic - exact)) < 1e-6
    linear = interpolate_to(ts, zs, td, kind="linear")
    err_lin = np.max(np.abs(linear - exact))
    assert 1e-5 < err_lin < 1e-3  # second order: h²/8·max|f''| ≈ 5e-4
    # Endpoints and source nodes are reproduced exactly (up to round-off).
    np.testing.assert_allclose(interpolate_to(ts, zs, ts), zs, atol=1e-14)
    # 1-D input.
    one = interpolate_to(ts, np.sin(ts), td)
    assert one.shape == (1003,) and np.max(np.abs(one - np.sin(td))) < 1e-6


@pytest.mark.parametrize("t_dst", [[-0.1, 1.0], [0.5, 2 * math.pi + 1e-3], [7.0]])
def test_interpolate_outside_range_raises(t_dst):
    ts = np.linspace(0.0, 2 * math.pi, 50)
    with pytest.raises(ConfigError) as ei:
        interpolate_to(ts, np.sin(ts), np.asarray(t_dst))
    assert "extrapolate" in _one_line(ei)


def test_interpolate_argument_checks():
    ts = np.linspace(0.0, 1.0, 10)
    with pytest.raises(ConfigError):
        interpolate_to(ts, np.zeros((9, 2)), ts)
    with pytest.raises(ConfigError):
        interpolate_to(ts[::-1], np.zeros(10), ts)
    with pytest.raises(ConfigError) as ei:
        interpolate_to(ts, np.zeros(10), ts, kind="quintic")
    assert "quintic" in _one_line(ei)


# ----------------------------------------------------------------------------- error table
def test_error_table():
    table = error_table(T3, PRED, REF, ["x", "p"])
    assert set(table) == {"components", "whole", "n_points"}
    assert table["n_points"] == 3
    assert list(table["components"]) == ["x", "p"]
    for comp in ("x", "p"):
        assert set(table["components"][comp]) == set(state_metric_names())
        assert all(isinstance(v, float) for v in table["components"][comp].values())
    x, p, w = table["components"]["x"], table["components"]["p"], table["whole"]
    assert x["l2_integral"] == pytest.approx(math.sqrt(22.0))
    assert p["l2_discrete"] == pytest.approx(math.sqrt(35.0))
    assert x["mse"] == pytest.approx(20.0 / 3.0)
    assert p["max_abs"] == 5.0
    assert w["l2_integral"] == pytest.approx(math.sqrt(61.0))
    assert w["l2_discrete"] == pytest.approx(math.sqrt(55.0))
    assert w["mse"] == pytest.approx(55.0 / 3.0)
    assert w["max_abs"] == 5.0
    with pytest.raises(ConfigError):
        error_table(T3, PRED, REF, ["x"])
    with pytest.raises(ConfigError):
        error_table(T3, PRED, REF, ["x", "x"])

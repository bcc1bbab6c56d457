"""Tests of least-squares shooting (atlasnn.inverse): synthetic data, single and multiple
shooting fits, their standard errors, unidentifiable unknowns and the one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from atlasnn.compile_cache import jax_time
from atlasnn.errors import AtlasError, ConfigError
from atlasnn.evaluation import _parametric as parametric
from atlasnn.evaluation import reference_solution
from atlasnn.inverse import FitResult, fit_shooting, predict_fit, synthetic_observations
from atlasnn.observations import Observations, Unknown
from atlasnn.systems import HamiltonianSystem, builtin_system, expression_system

LAM = Unknown("lam", 0.6, 0.1, 3.0)


def _msg(exc_info) -> str:
    msg = str(exc_info.value)
    assert msg and "\n" not in msg
    return msg


@pytest.fixture(scope="module")
def osc():
    return builtin_system("nonlinear_oscillator")  # lam = 1 is the truth


@pytest.fixture(scope="module")
def hh():
    return builtin_system("henon_heiles")


# -------------------------------------------------------------------------- synthetic data
def test_synthetic_observations_are_the_reference_plus_scaled_noise(osc):
    t = np.linspace(0.5, 10.0, 400)
    clean = synthetic_observations(osc, None, t, ["p", "x"], 0.0, 0, t0=0.0)
    Z = reference_solution(osc, None, np.concatenate([[0.0], t]))[1:]
    np.testing.assert_allclose(clean.values, Z[:, [1, 0]], rtol=0, atol=1e-13)
    assert clean.names == ("p", "x") and clean.source == "synthetic"
    a = synthetic_observations(osc, None, t, ["p", "x"], 0.05, 7, t0=0.0)
    b = synthetic_observations(osc, None, t, ["p", "x"], 0.05, 7, t0=0.0)
    c = synthetic_observations(osc, None, t, ["p", "x"], 0.05, 8, t0=0.0)
    np.testing.assert_array_equal(a.values, b.values)
    assert not np.array_equal(a.values, c.values)
    # noise sd = noise × RMS of the component over the samples
    ratio = np.std(a.values - clean.values, axis=0) / np.sqrt(np.mean(clean.values**2, axis=0))
    np.testing.assert_allclose(ratio, 0.05, rtol=0.15)


def test_synthetic_observations_errors(osc):
    with pytest.raises(ConfigError) as ei:
        synthetic_observations(osc, None, [0.0, 1.0], ["q"], 0.01, 0)
    assert "'q'" in _msg(ei) and "['x', 'p']" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        synthetic_observations(osc, None, [0.0, 2.0, 1.0], ["x"], 0.01, 0)
    assert "strictly increasing" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        synthetic_observations(osc, None, [0.0, 1.0], ["x"], -0.1, 0)
    assert "noise" in _msg(ei) and "-0.1" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        synthetic_observations(osc, None, [0.0, 1.0], ["x"], 0.01, 0, t0=0.5)
    assert "t0=0.5" in _msg(ei)


# ------------------------------------------------------------------------- single shooting
@pytest.mark.long
def test_noise_free_oscillator_recovers_lam(osc):
    obs = synthetic_observations(osc, None, np.linspace(0.0, 4 * np.pi, 20), ["x"], 0.0, 0)
    fit = fit_shooting(osc, obs, [LAM])
    assert isinstance(fit, FitResult) and fit.success and fit.identifiable and not fit.notes
    assert fit.names == ("lam",) and fit.method == "shooting"
    assert abs(fit.value("lam") - 1.0) < 1e-6
    assert fit.residual_rms < 1e-8 and fit.n_rhs > 0 and fit.n_solves >= 2 and fit.wall_time > 0
    d = json.loads(json.dumps(fit.as_dict()))
    # n_data: the values an unknown can change (x at t0 = 0 is the known initial value: not counted)
    assert d["names"] == ["lam"] and d["n_data"] == 19 and d["method"] == "shooting"
    # the fitted trajectory is the true one
    t = np.linspace(0.0, 4 * np.pi, 7)
    np.testing.assert_allclose(predict_fit(osc, fit, None, t), reference_solution(osc, None, t), atol=1e-6)
    # one compiled program per system and shape: another fit, from another guess, compiles nothing new
    with jax_time() as jt:
        again = fit_shooting(osc, obs, [Unknown("lam", 2.0, 0.1, 3.0)])
    assert jt.programs == 0
    # the same through DOP853: one compiled right-hand side; from 2.0 both end in the same false minimum
    fit_shooting(osc, obs, [LAM], solver="dop853")
    size = parametric._compiled(osc)[1]._cache_size()
    other = fit_shooting(osc, obs, [Unknown("lam", 2.0, 0.1, 3.0)], solver="dop853")
    assert parametric._compiled(osc)[1]._cache_size() == size == 1
    assert abs(again.value("lam") - other.value("lam")) < 1e-6 * other.std[0] and again.value("lam") > 2.5


@pytest.mark.long
def test_one_percent_noise_is_within_three_standard_errors(osc):
    t = np.linspace(0.0, 4 * np.pi, 30)
    rms = np.sqrt(np.mean(reference_solution(osc, None, t)[:, 0] ** 2))
    for seed in range(5):
        obs = synthetic_observations(osc, None, t, ["x"], 0.01, seed)
        fit = fit_shooting(osc, obs, [LAM])
        assert fit.std[0] > 0 and np.isfinite(fit.std[0])
        assert abs(fit.estimate[0] - 1.0) <= 3 * fit.std[0]
        assert 0.5 < fit.noise_estimate / (0.01 * rms) < 2.0  # s estimates the noise sd


@pytest.mark.long
def test_pendulum_g_from_positions_only():
    pend = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], {"g": 1.0}, z0=[1.0, 0.0])
    obs = synthetic_observations(pend, None, np.linspace(0.0, 10.0, 25), ["x"], 0.0, 0)
    fit = fit_shooting(pend, obs, [Unknown("g", 0.5, 0.1, 5.0)])
    assert abs(fit.value("g") - 1.0) < 1e-6


@pytest.mark.long
def test_henon_heiles_lam_from_positions(hh):
    obs = synthetic_observations(hh, None, np.linspace(0.0, 20.0, 50), ["x", "y"], 0.01, 3)
    fit = fit_shooting(hh, obs, [LAM])
    assert fit.success and fit.identifiable
    assert abs(fit.estimate[0] - 1.0) <= 3 * fit.std[0] and fit.std[0] < 0.01


@pytest.mark.long
def test_unknown_initial_momentum_with_the_parameter(osc):
    obs = synthetic_observations(osc, None, np.linspace(0.0, 4 * np.pi, 20), ["x"], 0.0, 0)
    fit = fit_shooting(osc, obs, [LAM, Unknown("z0.p", 0.3, -2.0, 2.0)], z0=[1.3, 0.0])
    assert fit.names == ("lam", "z0.p") and fit.covariance.shape == (2, 2)
    np.testing.assert_allclose(fit.estimate, [1.0, 1.0], rtol=1e-6)
    z = predict_fit(osc, fit, [1.3, 0.0], [0.0, 3.0])
    np.testing.assert_allclose(z, reference_solution(osc, None, [0.0, 3.0]), atol=1e-6)


# ----------------------------------------------------------------------- multiple shooting
@pytest.mark.long
def test_multiple_shooting_where_single_shooting_is_trapped(hh):
    obs = synthetic_observations(hh, None, np.linspace(0.0, 60.0, 120), ["x", "y"], 0.01, 0)
    multi = fit_shooting(hh, obs, [LAM], segments=4)
    assert multi.method == "multiple shooting (4 segments)" and multi.names == ("lam",) and multi.segments == 4
    assert multi.std.shape == (1,) and 0 < multi.std[0] < 0.01
    assert abs(multi.estimate[0] - 1.0) <= 3 * multi.std[0]
    single = fit_shooting(hh, obs, [LAM], max_nfev=30)
    assert abs(single.estimate[0] - 1.0) > 0.1  # a local minimum on this long interval


# ------------------------------------------------------------------------- identifiability
def test_more_unknowns_than_data(osc):
    obs = Observations.from_arrays([0.5, 1.0], [[1.0], [0.8]], ["x"])
    with pytest.raises(ConfigError) as ei:
        fit_shooting(osc, obs, [LAM, Unknown("z0.x", 1.0, -2.0, 2.0)])
    assert "more unknowns than the data" in _msg(ei) and "2 unknowns" in _msg(ei) and "got 2" in _msg(ei)


@pytest.mark.long
def test_unidentifiable_unknowns_get_infinite_std():
    # a and b enter only as the product a·b: only the product is determined
    prod = expression_system("p**2/2 + a*b*x**2/2", ["x"], ["p"], {"a": 1.0, "b": 2.0}, z0=[1.0, 0.0])
    obs = synthetic_observations(prod, None, np.linspace(0.0, 5.0, 20), ["x"], 0.0, 0)
    fit = fit_shooting(prod, obs, [Unknown("a", 1.5, 0.1, 5.0), Unknown("b", 1.5, 0.1, 5.0)])
    assert not fit.identifiable and np.all(np.isinf(fit.std)) and fit.cond > 1e12
    assert any("a is not identifiable" in n for n in fit.notes)
    assert any("b is not identifiable" in n for n in fit.notes)
    assert abs(fit.estimate[0] * fit.estimate[1] - 2.0) < 1e-6
    # c acts on y only, which is neither observed nor coupled to x
    two = expression_system("px**2/2 + py**2/2 + x**2/2 + c*y**2/2", ["x", "y"], ["px", "py"], {"c": 1.0},
                            z0=[1.0, 0.5, 0.0, 0.0])
    obs = synthetic_observations(two, None, np.linspace(0.0, 5.0, 20), ["x"], 0.01, 0)
    fit = fit_shooting(two, obs, [Unknown("c", 2.0, 0.1, 5.0)])
    assert not fit.identifiable and np.isinf(fit.std[0]) and "c is not identifiable" in fit.notes[0]


# ---------------------------------------------------------------------------------- errors
@pytest.mark.long
def test_fit_errors_are_one_line(osc):
    obs = synthetic_observations(osc, None, np.linspace(0.0, 4.0, 10), ["x"], 0.0, 0)
    plain = HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + q[0] ** 2 / 2, 1, name="plain")
    with pytest.raises(AtlasError) as ei:
        fit_shooting(plain, obs, [LAM])
    assert "parameter identification" in _msg(ei) and "'plain'" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        fit_shooting(osc, obs, [LAM], t0=1.0)
    assert "outside [1.0, 4.0]" in _msg(ei) and "times are outside" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        fit_shooting(osc, obs, [Unknown("omega", 1.0, 0.0, 2.0)])
    assert "'omega'" in _msg(ei) and "valid names" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        fit_shooting(osc, Observations.from_arrays([0.0, 1.0], [[1.0], [2.0]], ["y"]), [LAM])
    assert "'y'" in _msg(ei) and "not a state" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        fit_shooting(osc, obs, [LAM], segments=6)
    assert "segments=6" in _msg(ei) and "12" in _msg(ei)
    for bad in ({"rtol": 0.0}, {"max_nfev": 0}, {"segments": 1.5}):
        with pytest.raises(ConfigError) as ei:
            fit_shooting(osc, obs, [LAM], **bad)
        assert next(iter(bad)) in _msg(ei)
    blow = expression_system("p**2/2 - a*x**4/4", ["x"], ["p"], {"a": 1.0}, z0=[1.0, 1.0])
    far = Observations.from_arrays(np.linspace(0.0, 10.0, 5), np.ones(5), ["x"])
    with pytest.raises(AtlasError) as ei:
        fit_shooting(blow, far, [Unknown("a", 1.0, 0.5, 2.0)])
    assert "initial guess" in _msg(ei)
    fit = fit_shooting(osc, obs, [LAM], max_nfev=2)
    with pytest.raises(ConfigError) as ei:
        predict_fit(osc, fit, None, [-1.0, 0.0])
    assert "before the fit's t0" in _msg(ei)


@pytest.mark.long
def test_a_fit_that_does_not_explain_the_data_is_flagged():
    """A Toda pair's coupling from a guess of 0.5 lands in a wrong valley (c ≈ 0.34, truth 0.8) with a
    small σ; its residual gives it away and the result says so. From 0.7 the fit is right and clean."""
    from atlasnn.systems import expression_system

    toda = expression_system("(p1**2+p2**2)/2 + exp(c*(q1-q2)) + exp(c*(q2-q1))", ["q1", "q2"], ["p1", "p2"],
                             {"c": 0.8}, z0=[0.5, -0.5, 0.0, 0.2], name="toda-pair")
    times = np.sort(np.random.default_rng(5).uniform(0.0, 8.0, 40))
    obs = synthetic_observations(toda, toda.z0, times, ["q1", "q2"], 0.01, 0, t0=0.0)
    wrong = fit_shooting(toda, obs, [Unknown("c", 0.5, 0.2, 2.0)])
    assert abs(wrong.value("c") - 0.8) > 0.3 and not wrong.success
    assert any("does not explain the data" in n for n in wrong.notes)
    right = fit_shooting(toda, obs, [Unknown("c", 0.7, 0.2, 2.0)])
    assert abs(right.value("c") - 0.8) < 3 * right.std[0] and right.success and not right.notes


def test_synthetic_data_starts_where_the_fits_start():
    """The fit how-to's example (docs/howto/FIT.md): observations from t = 0.2 on, z0 at t = 0 (the fits' default t0). The
    data used to start z0 at the first observation time and the fit landed 11σ off (g = 0.908)."""
    from atlasnn.systems import expression_system

    pendulum = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], {"g": 1.0}, z0=[1.0, 0.0], name="pendulum")
    obs = synthetic_observations(pendulum, pendulum.z0, np.linspace(0.2, 6, 30), ["x"], noise=0.01, seed=1)
    fit = fit_shooting(pendulum, obs, [Unknown("g", guess=0.6, low=0.2, high=3.0)])
    assert abs(fit.value("g") - 1.0) < 4 * fit.std[0]


@pytest.mark.slow  # 37 s; test_fit_door's auto-segments config and the multiple-shooting test cover the segments (CI stays under 30 min)
def test_auto_segments_start_from_the_data_where_the_orbit_from_the_guess_escapes():
    from atlasnn.inverse import auto_segments

    hh = expression_system("(px**2 + py**2)/2 + (x**2 + y**2)/2 + lam*(x**2*y - y**3/3)", ["x", "y"], ["px", "py"],
                           params={"lam": 1.0}, z0=[0.3, -0.3, 0.3, 0.15], name="hh")
    times = np.sort(np.random.default_rng(7).uniform(0.0, 10.0, 50))
    obs = synthetic_observations(hh, hh.initial_state(), times, ["x", "y"], 0.01, 0)
    start = [Unknown("lam", 1.83, 0.2, 2.0)]
    with pytest.raises(AtlasError, match="at the initial guess"):  # one orbit from the guess escapes
        fit_shooting(hh, obs, start)
    fit = fit_shooting(hh, obs, start, segments="auto")
    best = fit_shooting(hh, obs, [Unknown("lam", 1.0, 0.2, 2.0)])  # the data's global minimum
    assert abs(fit.value("lam") - best.value("lam")) <= 0.5 * best.std[0]
    assert fit.segments == auto_segments(hh, obs, start) > 1 and fit.method.endswith("(auto)")

"""The compiled parametric Gauss solve (atlasnn.solver.ParametricGauss) that shooting integrates
with: its values against the reference, its sensitivities against finite differences, one program
for every θ, the window length kept within a fit, and shooting's estimates through it against the
DOP853 path's."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.compile_cache import jax_time
from atlasnn.errors import ConfigError
from atlasnn.evaluation import reference_solution
from atlasnn.inverse import parametric_solver
from atlasnn.inverse import CollocationFit, Shooting, fit, fit_shooting, predict_fit, synthetic_observations
from atlasnn.observations import Unknown
from atlasnn.solver import ParametricGauss, ParametricSolveFailed
from atlasnn.systems import builtin_system, expression_system, with_params


@pytest.fixture(scope="module")
def hh():
    return builtin_system("henon_heiles")


@pytest.fixture(scope="module")
def pendulum():
    return expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], {"g": 1.0}, z0=[1.0, 0.0], name="pendulum")


def _msg(exc_info) -> str:
    msg = str(exc_info.value)
    assert msg and "\n" not in msg
    return msg


def _columns(system):
    """(S0, D): one column per parameter, then one per initial-state component."""
    n, P = system.state_dim, len(system.param_names)
    return (np.concatenate([np.zeros((n, P)), np.eye(n)], axis=1),
            np.concatenate([np.eye(P), np.zeros((P, n))], axis=1))


def test_values_are_the_reference_at_any_times(hh):
    times = np.array([3.0, 0.0, 7.5, 3.0, 10.0, 0.25])  # unsorted, repeated, t0 itself
    solve = ParametricGauss(hh, rtol=1e-12, atol=1e-12)
    Z, S = solve(hh.initial_state(), hh.param_vector(), 0.0, times)
    assert S is None and Z.shape == (6, 4)
    grid = np.unique(times)  # from t0 = 0, sorted
    ref = reference_solution(hh, None, grid)
    np.testing.assert_allclose(Z, ref[np.searchsorted(grid, times)], rtol=0, atol=1e-11)
    np.testing.assert_array_equal(Z[1], hh.initial_state())  # exactly z0 at t0
    np.testing.assert_array_equal(Z[0], Z[3])
    # every time at t0 or none after it: the start, with its directions
    S0, D = _columns(hh)
    Z, S = solve(hh.initial_state(), hh.param_vector(), 2.0, [2.0, 2.0], S0, D)
    np.testing.assert_array_equal(Z, [hh.initial_state()] * 2)
    np.testing.assert_array_equal(S, [S0] * 2)


@pytest.mark.long
@pytest.mark.parametrize("name", ["hh", "pendulum"])
def test_sensitivities_are_the_derivatives_of_the_values(name, request):
    system = request.getfixturevalue(name)
    times = np.sort(np.random.default_rng(3).uniform(0.0, 10.0, 30))
    theta, z0 = system.param_vector() * 1.03, system.initial_state()
    P = theta.size
    S0, D = _columns(system)
    solve = ParametricGauss(system, rtol=1e-12, atol=1e-12)
    Z, S = solve(z0, theta, 0.0, times, S0, D)
    h = solve.h
    x = np.concatenate([theta, z0])
    for j in range(x.size):
        step = np.zeros_like(x)
        step[j] = 1e-5 * max(1.0, abs(x[j]))
        plus, _ = solve(z0 + step[P:], theta + step[:P], 0.0, times)
        minus, _ = solve(z0 - step[P:], theta - step[:P], 0.0, times)
        fd = (plus - minus) / (2 * step[j])
        assert np.max(np.abs(fd - S[:, :, j])) <= 1e-6 * np.max(np.abs(S[:, :, j])), j
    assert solve.h == h  # the same windows for every call: FD of the same discrete map
    # the directions combine linearly: S along a sum of directions is the sum of the columns
    _, both = solve(z0, theta, 0.0, times, S0.sum(axis=1, keepdims=True), D.sum(axis=1, keepdims=True))
    np.testing.assert_allclose(both[:, :, 0], S.sum(axis=2), rtol=1e-12, atol=1e-13)


def test_a_new_theta_or_data_set_compiles_nothing(pendulum):
    times = np.sort(np.random.default_rng(1).uniform(0.0, 8.0, 40))
    S0, D = _columns(pendulum)
    ParametricGauss(pendulum)(pendulum.initial_state(), [1.0], 0.0, times, S0[:, :1], D[:, :1])
    ParametricGauss(pendulum)(pendulum.initial_state(), [1.0], 0.0, times)
    with jax_time() as jt:
        for g in (0.7, 1.3, 1.9):
            solve = ParametricGauss(pendulum)
            solve([0.5, 0.1], [g], 0.0, times, S0[:, :1], D[:, :1])
            solve([0.5, 0.1], [g], 0.0, times[:37] * 1.1)  # another data set of about that size
    assert jt.programs == 0


def test_the_window_length_is_kept_and_only_shortened(pendulum):
    times = np.linspace(0.0, 8.0, 20)
    solve = ParametricGauss(pendulum, rtol=1e-10, atol=1e-10)
    solve(pendulum.initial_state(), [1.0], 0.0, times)
    first = solve.h
    solve(pendulum.initial_state(), [0.6], 0.0, times)  # slower: the same windows serve
    assert solve.h == first
    Z, _ = solve(pendulum.initial_state(), [6.0], 0.0, times)  # faster: shorter windows, kept
    assert solve.h < first
    fast = with_params(pendulum, g=6.0)
    np.testing.assert_allclose(Z, reference_solution(fast, None, times), rtol=0, atol=1e-8)


def test_an_orbit_that_escapes_is_refused_with_where_it_stopped():
    blow = expression_system("p**2/2 - a*x**4/4", ["x"], ["p"], {"a": 1.0}, z0=[1.0, 1.0])
    solve = ParametricGauss(blow)
    with pytest.raises(ParametricSolveFailed) as ei:
        solve(blow.initial_state(), [1.0], 0.0, [1.0, 10.0])
    assert "did not reach t = 10" in _msg(ei) and "stopped at t = 1.3" in _msg(ei)
    Z, _ = solve(blow.initial_state(), [1.0], 0.0, [0.5, 1.0])  # before the blow-up it solves
    np.testing.assert_allclose(Z, reference_solution(blow, None, [0.0, 0.5, 1.0])[1:], atol=1e-8)


def test_bad_settings_are_one_line(pendulum, hh):
    obs = synthetic_observations(pendulum, None, np.linspace(0.0, 4.0, 10), ["x"], 0.0, 0)
    g = [Unknown("g", 0.8, 0.5, 2.0)]
    for call in (lambda: fit_shooting(pendulum, obs, g, solver="rk4"), lambda: parametric_solver(hh, 1e-8, 1e-8, "x"),
                 lambda: CollocationFit(polish_solver="euler"), lambda: fit(pendulum, obs, g, method=Shooting(
                     starts=1, solver="rk4"))):
        with pytest.raises(ConfigError) as ei:
            call()
        assert "solver must be one of ['gauss', 'dop853']" in _msg(ei)
    with pytest.raises(ConfigError) as ei:
        ParametricGauss(hh, rtol=0.0)
    assert "rtol must be a positive number" in _msg(ei)
    solve = ParametricGauss(hh)
    with pytest.raises(ConfigError) as ei:
        solve([0.1, 0.2], [1.0], 0.0, [1.0])
    assert "a state of 4 and 1 parameters, got 2 and 1" in _msg(ei)
    for times in ([1.0, -0.5], [1.0, np.nan]):
        with pytest.raises(ConfigError) as ei:
            solve(hh.initial_state(), [1.0], 0.0, times)
        assert "finite times from t0 = 0 on" in _msg(ei)


@pytest.mark.long
def test_shooting_estimates_are_the_dop853_paths(hh, pendulum):
    """The built-in Hénon–Heiles inverse problem's data (50 noisy positions on [0, 10], guess 0.6):
    single and multiple shooting by both solves end at the same estimate and σ (to 1e-5 σ), and
    the fitted trajectories agree."""
    times = np.sort(np.random.default_rng(5).uniform(0.0, 10.0, 50))
    obs = synthetic_observations(hh, None, times, ["x", "y"], 0.01, 2)
    lam = [Unknown("lam", 0.6, 0.2, 2.0)]
    for segments in (1, 2):
        gauss = fit_shooting(hh, obs, lam, segments=segments)
        dop = fit_shooting(hh, obs, lam, segments=segments, solver="dop853")
        assert gauss.success and gauss.trusted and abs(gauss.estimate[0] - 1.0) < 3 * gauss.std[0]
        assert abs(gauss.estimate[0] - dop.estimate[0]) <= 1e-5 * dop.std[0], segments
        np.testing.assert_allclose(gauss.std, dop.std, rtol=1e-5)
        assert gauss.n_solves > 0 and gauss.n_rhs > 0
    t = np.linspace(0.0, 10.0, 50)
    np.testing.assert_allclose(predict_fit(hh, gauss, None, t), predict_fit(hh, gauss, None, t, solver="dop853"),
                               rtol=0, atol=1e-9)
    # the collocation fit's polish, and an unknown initial state beside the parameter
    obs = synthetic_observations(pendulum, None, np.linspace(0.2, 8.0, 40), ["x"], 0.01, 1)
    two = [Unknown("g", 0.7, 0.5, 2.0), Unknown("z0.p", 0.1, -0.5, 0.5)]
    a = fit(pendulum, obs, two, method=CollocationFit())
    b = fit(pendulum, obs, two, method=CollocationFit(polish_solver="dop853"))
    assert np.all(np.abs(a.estimate - b.estimate) <= 1e-5 * b.std) and a.search["polish_seconds"] > 0

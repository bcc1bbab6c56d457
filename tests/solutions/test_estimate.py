"""The a-posteriori error estimate: exact on a linear system, carried across window edges, growing
when the error grows, and equal to the true error of real trainings (no reference used)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from atlasnn.evaluation import reference_solution
from atlasnn.nn import make_model
from atlasnn.solutions import (
    ErrorEstimate,
    PiecewiseSolution,
    Solution,
    propagate,
    residual_and_jacobian,
    residual_bound,
    state_range,
)
from atlasnn.solutions._linearised import dense_grid, residual_bandwidth, steps_for
from atlasnn.systems import builtin_system, harmonic_exact, harmonic_oscillator
from atlasnn.training import DEFAULT_NETWORK, DEFAULT_WINDOW_TRAIN, MarchConfig, TrainConfig, march, train

OMEGA, Z0, T, AMP = 2.0, (1.0, 0.3), 20.0, 1e-3
ROT = np.array([[0.0, 1.0], [-OMEGA**2, 0.0]])


def perturbation(t, phase=0.0):
    """A smooth p(t) with p(0) = 0 and its derivative: ẑ = exact + p has error e = −p."""
    s1, c1 = np.sin(3 * t + phase), np.cos(3 * t + phase)
    s7, c7, s5, c5 = np.sin(7.3 * t), np.cos(7.3 * t), np.sin(5 * t), np.cos(5 * t)
    x = AMP * (s1 * t / T + s7**2)
    dx = AMP * (3 * c1 * t / T + s1 / T + 2 * 7.3 * s7 * c7)
    p = -0.5 * AMP * s5 * (1 + t / T)
    dp = -0.5 * AMP * (5 * c5 * (1 + t / T) + s5 / T)
    return np.stack([x, p], -1), np.stack([dx, dp], -1)


def linear_error(t, z, dz):
    system = harmonic_oscillator(omega=OMEGA, z0=Z0)
    r, A = residual_and_jacobian(system, z, dz)
    cut = np.nonzero(np.diff(t) == 0)[0]
    return propagate(t, A, r, jumps=z[cut + 1] - z[cut])


def test_on_a_linear_system_the_estimate_is_the_true_error_to_fourth_order():
    errors = []
    for steps in (400, 800):
        t = dense_grid([0.0, T], steps)
        ex = harmonic_exact(t, Z0, OMEGA)
        p, dp = perturbation(t)
        tn, delta, idx = linear_error(t, ex + p, ex @ ROT.T + dp)
        errors.append(np.abs(delta - (-p)[idx]).max())
    assert errors[1] < 2e-8 * 10 and math.log2(errors[0] / errors[1]) == pytest.approx(4, abs=0.4)


def test_a_window_edge_carries_delta_and_subtracts_the_hand_over_jump():
    t = dense_grid([0.0, 7.0, T], 600)
    cut = int(np.nonzero(np.diff(t) == 0)[0][0])
    ex = harmonic_exact(t, Z0, OMEGA)
    p1, dp1 = perturbation(t)
    p2, dp2 = perturbation(t, phase=1.0)
    p2 = p2 + np.array([2e-4, -1e-4])  # window 2 does not start where window 1 ended
    right = (np.arange(t.size) > cut)[:, None]
    z = ex + np.where(right, p2, p1)
    dz = ex @ ROT.T + np.where(right, dp2, dp1)
    tn, delta, idx = linear_error(t, z, dz)
    assert np.abs(delta - (ex - z)[idx]).max() < 2e-8
    k = np.nonzero(tn == 7.0)[0]
    assert k.size == 2 and np.allclose(delta[k[1]] - delta[k[0]], -(z[cut + 1] - z[cut]), atol=1e-15)


def test_the_estimate_grows_with_a_phase_error():
    w2 = OMEGA * (1 + 1e-3)  # the exact solution of a slightly wrong frequency
    t = dense_grid([0.0, 60.0], 2000)
    zh = harmonic_exact(t, Z0, w2)
    tn, delta, idx = linear_error(t, zh, zh @ np.array([[0.0, 1.0], [-(w2**2), 0.0]]).T)
    norm = np.linalg.norm(delta, axis=1)
    q = norm.size // 4
    assert np.abs(delta - (harmonic_exact(t, Z0, OMEGA) - zh)[idx]).max() < 1e-5 * norm.max()
    assert norm[-q:].max() > 3 * norm[:q].max()


def test_grid_rule_and_bandwidth():
    g = dense_grid([0.0, 1.0, 3.0], [4, 8])
    assert g.size == 26 and g[8] == g[9] == 1.0
    t = dense_grid([0.0, 10.0, 20.0], 400)
    omega = residual_bandwidth(t, np.stack([np.sin(10 * t), 0.5 * np.cos(10 * t + 1)], -1))
    assert 9.0 <= omega <= 12.0 and steps_for(10.0, omega) == max(128, 640, math.ceil(10 * omega / 0.5))
    with pytest.raises(ValueError, match="odd number"):
        propagate(np.linspace(0, 1, 10), np.zeros((10, 2, 2)), np.zeros((10, 2)))


def test_trust_horizon_and_relative_error():
    t = np.linspace(0.0, 10.0, 51)
    z = np.stack([np.cos(t), np.sin(t)], -1)  # range 2
    delta = np.stack([0.02 * t, 0 * t], -1)  # crosses 5 % of 2 = 0.1 at t = 5
    est = ErrorEstimate(t, delta, z)
    assert est.trusted_until == pytest.approx(4.8) and not est.trusted
    assert est.relative_max == pytest.approx(0.2 / state_range(z)) and state_range(z) == pytest.approx(2.0, abs=1e-3)
    assert est.at([2.5])[0, 0] == pytest.approx(0.05)


@pytest.fixture(scope="module")
def oscillator():
    system = builtin_system("nonlinear_oscillator")
    model = make_model(system.z0, **DEFAULT_NETWORK, seed=0)
    res = train(model, system, 4 * math.pi, TrainConfig(epochs=2000, lr=5e-3, n_points=150, progress=False,
                                                         chunk=2000, lr_schedule="cosine"))
    return system, Solution(res.model, system, (0.0, 4 * math.pi))


@pytest.mark.long
def test_a_trained_solution_s_estimate_is_its_true_error(oscillator):
    system, sol = oscillator
    est = sol.estimate()
    assert sol.estimate() is est  # computed once
    true = reference_solution(system, system.z0, est.t) - sol(est.t)
    assert 1e-5 < np.abs(true).max() < 0.05 * state_range(true + sol(est.t))  # a realistic, small error
    assert est.max_abs / np.abs(true).max() == pytest.approx(1.0, abs=0.1)
    t = np.linspace(0, 4 * math.pi, 300)
    e = reference_solution(system, system.z0, t) - sol(t)
    assert np.abs(sol.error_estimate(t) - e).max() < 0.1 * np.abs(e).max()
    _, bound = residual_bound(system, sol.pieces(), est.steps)
    assert bound.max() >= np.linalg.norm(true, axis=1).max() * 0.999  # the bound is far above: a bound


@pytest.mark.long
def test_a_march_s_estimate_crosses_the_window_edges():
    system = builtin_system("harmonic_oscillator")
    cfg = MarchConfig(n_windows=3, train=DEFAULT_WINDOW_TRAIN.replace(epochs=600, n_points=40, chunk=600,
                                                                      progress=False))
    sol = march(make_model(system.z0, **DEFAULT_NETWORK, seed=1), system, 6.0, cfg)
    assert isinstance(sol, PiecewiseSolution)
    est = sol.estimate()
    assert np.count_nonzero(np.diff(est.t) == 0) == 2  # both interior edges, both sides
    keep = np.concatenate([np.diff(est.t) > 0, [True]])  # the reference takes each time once
    true = reference_solution(system, system.z0, est.t[keep]) - est.z[keep]
    assert np.abs(est.delta[keep] - true).max() < 0.05 * np.abs(true).max() + 1e-6  # H is quadratic: exact


def test_the_estimate_grid_stays_within_its_memory_budget(monkeypatch):
    """A solution of many windows whose residual is rough (an untrained network) asks for fine
    grids; past the budget the grid stays coarser and the estimate says it did not converge,
    instead of running out of memory (a Kepler e = 0.9 march once took 21 GB here)."""
    from atlasnn.solutions import _estimate, _linearised

    system = harmonic_oscillator()
    model = make_model(system.z0, scaling="atlas_exp", width=16, depth=2, first_layer_scale=30.0, seed=0)
    windows = [(model, float(k), 1.0, 0.0) for k in range(40)]
    free = _estimate.estimate_error(system, windows)
    monkeypatch.setattr(_linearised, "ESTIMATE_MEMORY_BYTES", 40 * 160 * 8 * (6 * 4 + 10 * 2))
    budget = _linearised.max_total_steps(system.state_dim)
    capped = _estimate.estimate_error(system, windows)
    assert sum(free.steps) > budget  # the unconstrained grid is larger than the budget
    assert sum(capped.steps) <= budget + 40 * 128 and not capped.converged
    assert np.all(np.isfinite(capped.delta))


def test_a_fast_window_does_not_refine_a_slow_one():
    """Bandwidth per window: the long, smooth window keeps a grid for its own residual."""
    system = harmonic_oscillator()
    smooth = make_model(system.z0, scaling="atlas_exp", width=8, depth=1, first_layer_scale=0.5, seed=0)
    rough = make_model(system.z0, scaling="atlas_exp", width=16, depth=2, first_layer_scale=60.0, seed=1)
    from atlasnn.solutions import estimate_error

    est = estimate_error(system, [(rough, 0.0, 1e-3, 0.0), (smooth, 1e-3, 10.0, 0.0)])
    alone = estimate_error(system, [(smooth, 0.0, 10.0, 0.0)])
    assert est.steps[1] <= 2 * alone.steps[0]

"""The random-feature collocation solver (atlasnn.solver.Collocation) through atlasnn.solve:
exactness at t0, linear and closed-form orbits to round-off level, convergence as features grow,
the error estimate against the true error, bad input refused in one line, and the solution's
save/load round trip. (The default solver, GaussCollocation: tests/solver/test_gauss.py.)"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn import AtlasError, solve
from atlasnn.checkpoint import load_piecewise, save_piecewise
from atlasnn.evaluation import reference_solution
from atlasnn.solver import SOLVERS, AdamMarch, Collocation, solver_from_name
from atlasnn.systems import HamiltonianSystem, expression_system, henon_heiles


#: the solver these tests are about, with its default settings
COLLOCATION = Collocation()


def _kepler_circular():
    return expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                             z0=[1.0, 0.0, 0.0, 1.0], separable=True, name="kepler-circular")


def _linear():
    # H = p²/2 + 4q²/2 + q p/2: a linear, non-separable flow with a closed form via the matrix exponential
    return HamiltonianSystem(lambda q, p: (p[0] ** 2 + 4.0 * q[0] ** 2 + q[0] * p[0]) / 2.0, 1, name="linear",
                             z0=np.array([1.0, -0.5]))


def test_exact_at_t0_and_continuous_at_window_edges(ho):
    sol = solve(ho, [1.0, 0.0], (0.0, 6.0), solver=COLLOCATION)
    assert np.array_equal(sol(0.0), np.array([1.0, 0.0]))
    assert sol.n_windows > 1
    inner = sol.edges[1:-1]
    left, right = sol(inner - 1e-13), sol(inner)
    assert np.max(np.abs(left - right)) < 1e-11


def test_harmonic_oscillator_to_round_off(ho):
    T = 20.0
    sol = solve(ho, [1.0, 0.0], (0.0, T), rtol=1e-13, atol=1e-14, solver=COLLOCATION)
    t = np.linspace(0.0, T, 777)
    exact = np.stack([np.cos(t), -np.sin(t)], axis=1)
    assert np.max(np.abs(sol(t) - exact)) < 1e-12
    dexact = np.stack([-np.sin(t), -np.cos(t)], axis=1)
    assert np.max(np.abs(sol.derivative(t) - dexact)) < 1e-11


@pytest.mark.long
def test_linear_non_separable_system_matches_the_matrix_exponential():
    from scipy.linalg import expm

    system = _linear()
    sol = solve(system, None, (0.0, 5.0), rtol=1e-13, atol=1e-14, solver=COLLOCATION)
    A = np.array([[0.5, 1.0], [-4.0, -0.5]])  # dq/dt = ∂H/∂p = p + q/2, dp/dt = −∂H/∂q = −4q − p/2
    t = np.linspace(0.0, 5.0, 101)
    exact = np.stack([expm(A * s) @ system.z0 for s in t])
    assert np.max(np.abs(sol(t) - exact)) < 1e-12


@pytest.mark.long
def test_circular_kepler_orbit_to_1e12():
    system = _kepler_circular()
    T = 4 * np.pi
    sol = solve(system, None, (0.0, T), rtol=1e-13, atol=1e-14, solver=COLLOCATION)
    t = np.linspace(0.0, T, 501)
    exact = np.stack([np.cos(t), np.sin(t), -np.sin(t), np.cos(t)], axis=1)
    assert np.max(np.abs(sol(t) - exact)) < 1e-12


@pytest.mark.slow  # 20 s; Collocation is deprecated (the other tests here keep its contract in CI)
def test_error_falls_as_features_grow(ho):
    """Fixed window (no control: one window of the whole interval, tolerance wide open): the
    error of the basis itself falls by orders of magnitude from 6 to 18 features."""
    t = np.linspace(0.0, 3.0, 301)
    exact = np.stack([np.cos(t), -np.sin(t)], axis=1)
    errors = []
    for m in (6, 10, 14, 18):
        solver = Collocation(features=m, first_window=3.0, growth=1.01)
        sol = solve(ho, [1.0, 0.0], (0.0, 3.0), solver=solver, rtol=1.0, atol=1.0)
        assert sol.n_windows == 1
        errors.append(np.max(np.abs(sol(t) - exact)))
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-3 * errors[0], errors


def _henon_heiles(T: float, points: int):
    """The paper's Hénon–Heiles problem on [0, T]: system, z0, times, DOP853 reference, range."""
    system, z0 = henon_heiles(), [0.3, -0.3, 0.3, 0.15]
    t = np.linspace(0.0, T, points)
    ref = reference_solution(system, z0, t, rtol=1e-13, atol=1e-13)
    return system, z0, t, ref, np.ptp(ref, axis=0).max()


@pytest.mark.long
def test_tolerance_controls_the_error_and_the_estimate_tracks_it():
    T = 6 * np.pi
    system, z0, t, ref, scale = _henon_heiles(T, 600)
    errs = []
    for rtol in (1e-7, 1e-10):
        sol = solve(system, z0, (0.0, T), rtol=rtol, atol=rtol / 100, solver=COLLOCATION)
        err = np.max(np.abs(sol(t) - ref))
        errs.append(err)
        # the a-posteriori estimate against the true error (the running in-program one is only a
        # rough figure, measured off by up to 30x: docs/SOLVER.md)
        est = sol.estimate(z0=z0).max_abs
        assert err / 3 <= est <= 3 * err, (rtol, err, est)
        # and δ(t) follows e(t) itself, not only its size
        corr = np.corrcoef(sol.error_estimate(t).ravel(), (ref - sol(t)).ravel())[0, 1]
        assert corr > 0.8, corr
    assert errs[1] < 1e-9 * scale
    assert errs[1] < 1e-2 * errs[0]


@pytest.mark.long
def test_every_seed_meets_the_target_on_henon_heiles():
    T = 24 * np.pi
    system, z0, t, ref, scale = _henon_heiles(T, 2000)
    for seed in range(3):
        sol = solve(system, z0, (0.0, T), solver=Collocation(seed=seed))
        assert np.max(np.abs(sol(t) - ref)) < 1e-9 * scale, seed


@pytest.mark.long
def test_scalings_tanh_and_rational_exp_solve_too(ho):
    t = np.linspace(0.0, 8.0, 200)
    exact = np.stack([np.cos(t), -np.sin(t)], axis=1)
    for name in ("tanh", "rational_exp"):
        sol = solve(ho, [1.0, 0.0], (0.0, 8.0), solver=Collocation(scaling=name))
        assert sol.scaling_name == name
        assert np.max(np.abs(sol(t) - exact)) < 1e-9, name
        assert sol.gammas[0] and all(v > 0 for v in sol.gammas[0].values())


def test_save_and_load_keep_float64_bit_for_bit(ho, tmp_path):
    sol = solve(ho, [1.0, 0.0], (0.0, 6.0), solver=Collocation(scaling="tanh"))
    path = tmp_path / "sol.npz"
    save_piecewise(path, sol)
    back = load_piecewise(path, ho)
    t = np.linspace(0.0, 6.0, 97)
    assert np.array_equal(back(t), sol(t))
    assert back(t).dtype == np.float64


@pytest.mark.parametrize("kwargs, needle", [
    ({"rtol": 0.0}, "rtol must be a finite number > 0"),
    ({"atol": -1e-9}, "atol must be a finite number >= 0"),
    ({"rtol": 1e-18}, "below what it can reach"),
    ({"interval": (1.0, 1.0)}, "t0 < T"),
    ({"z0": [1.0, 2.0, 3.0]}, "z0 must have 2 components"),
    ({"solver": "collocation"}, "solver must be a solver object"),
])
def test_bad_input_is_one_line(ho, kwargs, needle):
    args = {"z0": [1.0, 0.0], "interval": (0.0, 1.0), **kwargs}
    z0, interval = args.pop("z0"), args.pop("interval")
    with pytest.raises(AtlasError, match=needle) as info:
        solve(ho, z0, interval, **{"solver": COLLOCATION, **args})
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("settings, needle", [
    ({"features": 30, "points": 20}, "points \\(20\\) must be at least the features \\(30\\)"),
    ({"scaling": "sigmoid"}, "collocation scaling must be one of"),
    ({"growth": 1.0}, "growth must be > 1"),
    ({"features": 0}, "features must be an integer >= 1"),
])
def test_bad_solver_settings_are_one_line(settings, needle):
    with pytest.raises(AtlasError, match=needle):
        Collocation(**settings)


def test_building_one_warns_that_it_is_deprecated():
    with pytest.warns(FutureWarning, match=r"Collocation \(random features\) is deprecated.*GaussCollocation"):
        Collocation(features=8)


def test_solvers_registry_names_all_three():
    assert {"gauss", "collocation", "adam-march"} <= set(SOLVERS)
    assert isinstance(solver_from_name("collocation", features=12), Collocation)
    with pytest.raises(AtlasError, match="unknown solver"):
        solver_from_name("rk4")
    assert AdamMarch.name == "adam-march"


def test_a_march_that_cannot_meet_its_tolerance_says_so(ho):
    """Two features cannot reach 1e-14 on any window: the march gives up in one line."""
    with pytest.raises(AtlasError, match="collocation march stopped at t ="):
        solve(ho, [1.0, 0.0], (0.0, 1.0), solver=Collocation(features=2, max_rejects=5), rtol=1e-14, atol=1e-14)


def test_a_march_that_stops_keeps_its_windows():
    """q'' = q³ from (1, 0) blows up at t ≈ 1.854: the march stops there, and the error carries
    the windows it accepted before, which agree with a reference on [0, 1]."""
    blowup = expression_system("p**2/2 - q**4/4", ["q"], ["p"], z0=[1.0, 0.0], separable=True, name="blowup")
    with pytest.raises(AtlasError, match="collocation march stopped at t =.*error's .partial") as err:
        solve(blowup, None, (0.0, 3.0), solver=Collocation(max_rejects=5))
    part = err.value.partial
    assert part is not None and 1.0 < part.edges[-1] < 1.86
    t = np.linspace(0.0, 1.0, 11)
    assert np.max(np.abs(part(t) - reference_solution(blowup, [1.0, 0.0], t))) < 1e-9


def test_the_solution_is_float64_even_with_float32_default(ho):
    assert jnp.zeros(1).dtype == jnp.float32
    sol = solve(ho, [1.0, 0.0], (0.0, 2.0), solver=COLLOCATION)
    assert sol(np.array([0.5])).dtype == np.float64
    assert abs(sol(0.5)[0] - np.cos(0.5)) < 1e-12


def test_cli_solve_prints_the_estimate_and_the_true_error(tmp_path, capsys):
    from atlasnn.cli import main

    out = tmp_path / "hh.npz"
    assert main(["solve", "--solver", "collocation", "--system", "henon_heiles", "--T", "6*pi", "--rtol", "1e-9",
                 "--check", "--save", str(out)]) == 0
    text = capsys.readouterr().out
    assert "estimated max error" in text and "true max error" in text and out.exists()
    ratio = float(text.split("estimate / true = ")[1].split()[0])
    assert 1 / 3 <= ratio <= 3
    assert main(["solve", "--system", "henon_heiles", "--save", str(out)]) == 2  # never overwrites
    assert "the file exists" in capsys.readouterr().err
    # a folder that is not there is refused before solving (the solution would be lost after)
    assert main(["solve", "--system", "henon_heiles", "--save", str(tmp_path / "no" / "x.npz")]) == 2
    err = capsys.readouterr()
    assert "does not exist" in err.err and "estimated max error" not in err.out


@pytest.mark.long
def test_a_batch_of_initial_states_and_seeds_in_one_program(ho):
    """Members march with windows of their own; each equals the exact orbit of its own z0."""
    from atlasnn import solve_batch

    z0s = np.array([[1.0, 0.0], [0.0, 2.0], [0.5, -0.5]])
    sols = solve_batch(ho, z0s, (0.0, 8.0), seeds=[0, 1, 2], solver=COLLOCATION)
    with pytest.raises(AtlasError, match="z0s\\[1\\] must have 2 components"):
        solve_batch(ho, [[1.0, 0.0], [1.0]], (0.0, 8.0))
    t = np.linspace(0.0, 8.0, 300)
    for z0, sol, seed in zip(z0s, sols, (0, 1, 2)):
        exact = np.stack([z0[0] * np.cos(t) + z0[1] * np.sin(t), -z0[0] * np.sin(t) + z0[1] * np.cos(t)], axis=1)
        assert np.max(np.abs(sol(t) - exact)) < 1e-11
        assert sol.info["settings"]["seed"] == seed and sol.info["batch"] == 3
    alone = solve(ho, z0s[1], (0.0, 8.0), solver=Collocation(seed=1, rtol=1e-12, atol=1e-14))
    assert np.max(np.abs(alone(t) - sols[1](t))) < 1e-11  # as accurate as when solved alone


def test_error_estimate_outside_the_interval_is_nan_and_warned(ho):
    """Past T there is no estimate: NaN and the extrapolation warning (it used to return the end
    value silently)."""
    from atlasnn.solutions import ExtrapolationError, ExtrapolationWarning

    sol = solve(ho, [1.0, 0.0], (0.0, 4.0), solver=COLLOCATION)
    with pytest.warns(ExtrapolationWarning):
        est = sol.error_estimate(np.array([1.0, 4.0, 6.0]))
    assert np.all(np.isfinite(est[:2])) and np.all(np.isnan(est[2]))
    sol.outside = "raise"
    with pytest.raises(ExtrapolationError):
        sol.error_estimate(-1.0)


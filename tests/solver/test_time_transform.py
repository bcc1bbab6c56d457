"""The time-transformed Gauss collocation (GaussCollocation(time_scale=...)): one window is a
symplectic map of the extended phase space, the physical time is recovered (Kepler e = 0.9 and
0.99 against the exact orbit), the energy stays bounded where adaptive windows drift, the
Pythagorean three-body problem is marched through its near-collisions, and bad scales are refused
in one line."""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn import AtlasError, solve, solve_batch
from atlasnn.solutions import TimeTransformedSolution, gauss_tableau
from atlasnn.solver import GaussCollocation
from atlasnn.solver._base import monotone_progress
from atlasnn.solver._gauss_step import gauss_step, tableau_arrays
from atlasnn.solver._gauss_time import TimeTransform, poincare_system
from atlasnn.systems import expression_system, henon_heiles

from benchmarks.problems import kepler_exact, kepler_system, pythagorean_system

TT = GaussCollocation(time_scale="potential")


@pytest.mark.long
def test_one_window_is_a_symplectic_map_of_the_extended_space():
    """M, the Jacobian of one Gauss window of K = g·(H + p_t) (Kepler e = 0.9 at pericentre, g =
    r^(3/2), s = 8, a τ-window three times the march's, which turns the velocity by 39°), satisfies
    MᵀJM = J in 2d + 2 = 6 dimensions to round-off."""
    system = kepler_system(0.9)
    extended = poincare_system(system, "potential")
    Z0 = TimeTransform(system, "potential").lift(system.z0[None], 0.0)[0]
    tab = tableau_arrays(gauss_tableau(8))
    n = Z0.size
    J = np.block([[np.zeros((n // 2, n // 2)), np.eye(n // 2)], [-np.eye(n // 2), np.zeros((n // 2, n // 2))]])
    with jax.enable_x64(True):
        def step(z):
            Y0 = jnp.broadcast_to(z, (8, n))
            return gauss_step(extended.vector_field, None, tab, z, jnp.zeros(n), 1.0, Y0, implicit_gradients=True)

        M = np.asarray(jax.jit(jax.jacfwd(lambda z: step(z).z))(jnp.asarray(Z0)))
        done = jax.jit(step)(jnp.asarray(Z0))
        moved = np.asarray(done.z)
    assert bool(done.converged)
    assert np.abs(M.T @ J @ M - J).max() < 1e-12
    assert np.abs(M - np.eye(n)).max() > 1.0  # a map far from the identity
    assert moved[2] > 0.01 and abs(moved[5] - Z0[5]) == 0.0  # t advanced; p_t, a linear invariant, exact


@pytest.mark.long
@pytest.mark.parametrize("e, periods, bound", [(0.9, 3, 1e-10), (0.99, 3, 1e-7)])
def test_the_physical_time_is_recovered(e, periods, bound):
    """Kepler's orbit at physical times (t(τ) inverted), against Kepler's equation from the float64
    start; the derivative is J∇H there, and the time the inversion found is the query's to round-off.
    At e = 0.99 an energy error of 1e-13 alone moves the pericentre passage by ~1e-12 in time over
    a few periods, where the velocity turns at 1e4 per unit time (the bound)."""
    system = kepler_system(e)
    T = 2 * np.pi * periods
    sol = solve(system, None, (0.0, T), solver=TT)
    assert isinstance(sol, TimeTransformedSolution) and sol.interval == (0.0, T)
    t = np.sort(np.concatenate([np.linspace(0.0, T, 3001), 2 * np.pi * np.arange(periods + 1)]))
    z = sol(t)
    assert np.abs(z - kepler_exact(t, e)).max() < bound
    assert np.abs(sol.end_state - kepler_exact(np.asarray([T]), e)[0]).max() < bound
    tau, k = sol.tau(t)
    found = sol.extended.window_values(tau, k, system.dim)[0]
    assert np.abs(found - t).max() <= 4 * np.spacing(T)
    assert np.abs(sol.residual(t)).max() < 1e3 * bound
    estimate = np.abs(sol.error_estimate(t)).max()
    assert 0 < estimate < bound


def test_the_estimate_carries_the_rounding_of_the_energy_the_march_keeps():
    """Kepler e = 0.99 from pericentre, two periods, the default: the march in τ keeps H at −p_t =
    H(z0) as float64 computed it (99.5 − 100, some 40 ulps of −0.5 lost), and that energy's period
    puts the pericentre at T ~3e-9 off, at any tolerance. A companion from the same p_t shares the
    error (it read 3e-11); the estimate must cover it without a wild over-read."""
    e, T = 0.99, 4 * np.pi
    system = kepler_system(e)
    sol = solve(system, None, (0.0, T))
    assert isinstance(sol, TimeTransformedSolution)
    t = np.linspace(0.0, T, 2001)
    error = np.abs(sol(t) - kepler_exact(t, e)).max()
    estimate = sol.estimate().max_abs
    # the rounding of H(z0), and so the error, is the CPU's (3.5e-9 measured); the estimate, from a
    # bound of it, must cover it and stay of its order (2.5e-8 measured)
    assert error <= estimate < 1e-7
    shift = sol.companion().extended.z0[-1] - sol.extended.z0[-1]
    assert shift == pytest.approx(-sol.energy_rounding()) and 0 < sol.energy_rounding() < 1e-12


@pytest.mark.long
def test_the_estimate_finds_the_largest_error_inside_the_windows():
    """Kepler e = 0.97 from apocentre over one period at rtol 1e-8, in τ: the largest error falls
    inside windows, where an estimate at three points a window read 0.16 of it and said
    "accurate" (error 3.5e-9, 4e-10 of the range). Against Kepler's equation from the float64 start."""
    e, T = 0.97, 2 * np.pi
    start = [-(1 + e), 0.0, 0.0, -np.sqrt((1 - e) / (1 + e))]
    system = expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                               z0=start, separable=True)
    sol = solve(system, None, (0.0, T), solver=GaussCollocation(rtol=1e-8, atol=1e-10, time_scale="potential"))
    # the start is the orbit from pericentre half a period on (to its rounding: 1e-11 at the end,
    # far below the error): Kepler's equation for that orbit at t + π
    t = np.linspace(0.0, T, 4001)
    exact = kepler_exact(t + np.pi, e)
    assert np.abs(exact[0] - start).max() < 1e-12
    error = np.abs(sol(t) - exact).max()
    estimate = sol.estimate().max_abs
    assert error > 1e-9 and 0.5 * error <= estimate <= 10 * error


def test_windows_are_few_on_an_eccentric_orbit():
    """Ten periods of Kepler e = 0.99: tens of windows (constant lengths in t take tens of
    thousands: docs/SOLVER.md, 'Window lengths')."""
    sol = solve(kepler_system(0.99), None, (0.0, 20 * np.pi), solver=TT)
    assert sol.n_windows < 300
    assert sol.info["time_scale"] == "potential" and sol.info["settings"]["time_scale"] == "potential"


@pytest.mark.long
def test_the_energy_stays_bounded_where_adaptive_windows_drift():
    """Kepler e = 0.9 over 200 periods at rtol 1e-6, the energy at every window end: with windows of
    one τ-length (symplectic) its error is as large in the last quarter as in the first; with
    adaptive τ-lengths it grows with t."""
    system = kepler_system(0.9)
    T = 2 * np.pi * 200

    def quarters(steps):
        sol = solve(system, None, (0.0, T), solver=GaussCollocation(time_scale="potential", rtol=1e-6, atol=1e-8,
                                                                     steps=steps))
        Z = sol.extended.z + sol.extended.e
        t, z = Z[:, 2], Z[:, [0, 1, 3, 4]]
        error = np.abs(system.energy64(z) / system.energy64(system.z0) - 1)
        return [error[(t >= a * T / 4) & (t < (a + 1) * T / 4)].max() for a in range(4)]

    constant = quarters("constant")
    assert max(constant) < 1e-11 and constant[3] < 3 * constant[0] + 1e-13
    adaptive = quarters("adaptive")
    assert adaptive[3] > 2 * adaptive[0] and adaptive[3] > 10 * max(constant)


@pytest.mark.long
def test_the_pythagorean_problem_is_marched_through_its_near_collisions():
    """Masses 3, 4, 5 from rest to T = 20, past the closest approach (t ≈ 15.83, two bodies ~4e-4
    apart; a march of constant windows in t needs millions of windows for it): a few hundred
    windows, the relative energy error along the output within 1e-8 and at T near round-off, and
    the state at T = 10 that of a march of adaptive windows at a tight tolerance."""
    system = pythagorean_system()
    sol = solve(system, None, (0.0, 20.0), solver=TT)
    assert sol.n_windows < 1000
    t = np.linspace(0.0, 20.0, 20001)
    H0 = system.energy64(system.z0)
    assert np.abs(sol.energy(t) / H0 - 1).max() < 1e-8
    assert abs(sol.energy(np.asarray([20.0]))[0] / H0 - 1) < 1e-12
    reference = solve(system, None, (0.0, 10.0), solver=GaussCollocation(steps="adaptive", rtol=1e-13, atol=1e-15))
    assert np.abs(sol(np.asarray([10.0])) - reference(np.asarray([10.0]))).max() < 1e-7


def test_a_batch_is_marched_member_by_member():
    """solve_batch with a time scale: each member its own windows, each on its own orbit."""
    z0s = [kepler_system(e).z0 for e in (0.6, 0.9)]
    sols = solve_batch(kepler_system(0.9), z0s, (0.0, 4 * np.pi), solver=TT)
    t = np.linspace(0.0, 4 * np.pi, 501)
    for sol, e in zip(sols, (0.6, 0.9)):
        assert np.abs(sol(t) - kepler_exact(t, e)).max() < 1e-10


@pytest.mark.parametrize("scale, match", [
    (lambda q, p: -jnp.sum(q ** 2), r"time_scale \(g = .*\) must be finite and > 0 along the orbit, got g = -0\.0099"),
    (lambda q, p: jnp.log(-jnp.sum(q ** 2)), r"must be finite and > 0 along the orbit, got g = nan at z0"),
    (lambda q, p: 1.0 / q[1], r"must be finite and > 0 along the orbit, got g = inf at z0"),
])
def test_a_scale_not_positive_or_not_finite_at_z0_is_refused_in_one_line(scale, match):
    with pytest.raises(AtlasError, match=match) as caught:
        solve(kepler_system(0.9), None, (0.0, 1.0), solver=GaussCollocation(time_scale=scale))
    assert "\n" not in str(caught.value)


@pytest.mark.long
def test_a_scale_that_reaches_zero_on_the_way_is_refused_with_what_was_computed():
    """g = q1 + 0.5 on Kepler e = 0.9 (q1 falls from 0.1 to −1.9): the time stops at q1 = −0.5; the
    line says where, and the part before is kept."""
    with pytest.raises(AtlasError, match=r"got g = .* at t = 0\.33\d*[ ,(].*give a scale") as caught:
        solve(kepler_system(0.9), None, (0.0, 10.0), solver=GaussCollocation(time_scale=lambda q, p: q[0] + 0.5))
    assert "\n" not in str(caught.value)
    partial = caught.value.partial
    assert isinstance(partial, TimeTransformedSolution) and 0.3 < partial.interval[1] < 0.34


def test_bad_settings_are_refused_in_one_line():
    for value in (3, "n-body"):
        with pytest.raises(AtlasError, match=r"GaussCollocation time_scale must be None, 'auto', one of "
                                             r"\['potential'\] or a function g\(q, p\) > 0, got"):
            GaussCollocation(time_scale=value)
    with pytest.raises(AtlasError, match=r"time_scale \(potential\) .* got g = nan at z0 = .*: V\(q\) = H\(q, 0\) "
                                         r"must be < 0 there"):
        solve(henon_heiles(), None, (0.0, 1.0), solver=TT)
    kepler = expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                               z0=[0.5, 0.0, 0.0, 1.5], name="kepler-undeclared")
    with pytest.raises(AtlasError, match=r"time_scale 'potential' needs a separable H = T\(p\) \+ V\(q\); system "
                                         r"'kepler-undeclared' is not declared separable"):
        solve(kepler, None, (0.0, 1.0), solver=TT)


@pytest.mark.long
def test_an_interval_off_zero_and_windows_solved_again_read_alike():
    """From t0 = 1 (t starts at t0 in the extended state), with every window's polynomial kept and
    with only the window starts kept (solved again when read): the same orbit, the same values."""
    system = kepler_system(0.9)
    interval = (1.0, 1.0 + 4 * np.pi)
    kept = solve(system, None, interval, solver=TT)
    again = solve(system, None, interval, solver=GaussCollocation(time_scale="potential", keep=False))
    assert kept.extended.L is not None and again.extended.L is None
    t = np.linspace(*interval, 801)
    assert np.abs(kept(t) - kepler_exact(t - 1.0, 0.9)).max() < 1e-10
    assert np.abs(again(t) - kept(t)).max() < 1e-13
    assert kept.edges[0] == 1.0 and kept.edges[-1] == interval[1]


def test_a_solution_in_tau_saves_and_loads(tmp_path):
    from atlasnn import load, save

    sol = solve(kepler_system(0.9), None, (0.0, 1.0), solver=TT)
    save(tmp_path / "tt.atlas", sol)
    back = load(tmp_path / "tt.atlas")
    t = np.linspace(0.0, 1.0, 33)
    assert isinstance(back, TimeTransformedSolution) and np.array_equal(back(t), sol(t))


@pytest.mark.long
def test_the_scale_is_recommended_where_it_suits_the_system(monkeypatch):
    """``potential_applies`` recognises a negative potential homogeneous of degree −1 (Kepler, three
    bodies), not a positive, a periodic or a non-separable one; a march in t (``time_scale=None``)
    through an eccentric orbit says to use the scale (its g varies 83-fold at e = 0.9, 2.5-fold at
    e = 0.3: no advice), and one stopped by the windows' memory names it as the remedy."""
    import atlasnn.solver._gauss as gauss
    from atlasnn.solver._gauss_time import potential_applies
    from atlasnn.systems import harmonic_oscillator

    assert potential_applies(kepler_system(0.9), kepler_system(0.9).z0)
    assert potential_applies(pythagorean_system(), pythagorean_system().z0)
    for system in (harmonic_oscillator(), henon_heiles(),
                   expression_system("p**2/2 - cos(q)", ["q"], ["p"], z0=[0.5, 0.0], separable=True),
                   expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                                     z0=[1.0, 0.0, 0.0, 1.0])):
        assert not potential_applies(system, system.z0), system.name
    in_t = GaussCollocation(time_scale=None)
    eccentric = solve(kepler_system(0.9), None, (0.0, 4 * np.pi), solver=in_t)
    assert "time_scale='potential' would take fewer windows" in eccentric.info["advice"]
    assert "advice" not in solve(kepler_system(0.3), None, (0.0, 4 * np.pi), solver=in_t).info
    monkeypatch.setattr(gauss, "available_memory", lambda: 2**20)
    with pytest.raises(AtlasError, match="would need about .* windows .*; a close encounter shortened the windows: "
                                         "time_scale='potential'") as info:
        solve(kepler_system(0.99), None, (0.0, 20 * np.pi), solver=in_t)
    assert info.value.partial is not None


@pytest.mark.long
def test_the_default_marches_in_tau_where_the_scale_varies_and_in_t_elsewhere(monkeypatch):
    """The default (time_scale="auto"): Kepler e = 0.99 over ten periods from pericentre is marched
    in τ after its first 128 windows in t (g varies thousands-fold over them), in a few hundred windows
    rather than ~80 000, saying why, and as accurately as the scale chosen by hand; e = 0.3 (g varies
    2.5-fold) and a system the scale does not suit stay in t; a batch switches as a whole; and a march
    in t that the windows' memory stops is marched in τ instead of refused."""
    import atlasnn.solver._gauss as gauss
    import atlasnn.solver._gauss_time as gauss_time

    system, T = kepler_system(0.99), 20 * np.pi
    fractions = []
    sol = solve(system, None, (0.0, T), progress=fractions.append)
    assert isinstance(sol, TimeTransformedSolution) and sol.n_windows < 300
    assert sol.info["settings"]["time_scale"] == "auto" and sol.info["time_scale"] == "potential"
    assert "varied" in sol.info["time_scale_chosen"] and "-fold over the first" in sol.info["time_scale_chosen"]
    # the call's time counts both marches
    spent = float(re.search(r"that march took ([0-9.e+-]+) s", sol.info["time_scale_chosen"]).group(1))
    assert sol.info["solve_time"] >= spent and fractions[-1] == pytest.approx(1.0)
    t = np.linspace(0.0, T, 2001)
    by_hand = solve(system, None, (0.0, T), solver=TT)
    assert np.abs(sol(t) - by_hand(t)).max() < 1e-12
    assert not isinstance(solve(kepler_system(0.3), None, (0.0, 20 * np.pi)), TimeTransformedSolution)
    assert not isinstance(solve(henon_heiles(), None, (0.0, 200.0)), TimeTransformedSolution)
    sols = solve_batch(system, [kepler_system(e).z0 for e in (0.3, 0.99)], (0.0, 4 * np.pi))
    assert all(isinstance(s, TimeTransformedSolution) for s in sols)
    assert np.abs(sols[0](t[:200]) - kepler_exact(t[:200], 0.3)).max() < 1e-10
    monkeypatch.setattr(gauss_time, "SCALE_VARIATION", np.inf)  # the watch never fires: memory stops the march
    monkeypatch.setattr(gauss, "available_memory", lambda: 2**20)
    fractions = []
    stopped = solve(kepler_system(0.99), None, (0.0, 20 * np.pi), progress=fractions.append)
    assert "stopped at t = " in stopped.info["time_scale_chosen"]
    # the march in t reported progress before it stopped; the bar does not move back for the one in τ
    at = float(re.search(r"stopped at t = ([0-9.e+-]+)", stopped.info["time_scale_chosen"]).group(1))
    assert fractions[0] > 0 and fractions == sorted(fractions) and fractions[-1] == pytest.approx(1.0)
    assert max(fractions[:-1]) >= at / (20 * np.pi) * (1 - 1e-5)  # "t = " has 6 digits
    seen = []
    report = monotone_progress(seen.append)
    for f in (0.1, 0.4, 0.05, 0.3, 0.6, 1.0):  # a march in τ that starts again below the one in t's 0.4
        report(f)
    assert seen == [0.1, 0.4, 0.4, 0.4, 0.6, 1.0]


@pytest.mark.long
def test_atlasnn_solve_says_when_the_default_marched_in_tau_and_saves_it(tmp_path, capsys):
    """The command line on the built-in Kepler e = 0.9 experiment over ten periods: a note says the
    march was in τ and why; --save writes that solution, which loads back."""
    from atlasnn import load
    from atlasnn.cli import main

    target = tmp_path / "kepler.npz"
    assert main(["solve", "kepler-e09", "--T", "20*pi", "--save", str(target)]) == 0
    out = capsys.readouterr().out
    assert "note: marched in a fictitious time" in out and "-fold over the first" in out
    assert f"wrote {target}" in out and isinstance(load(target), TimeTransformedSolution)


def test_a_time_scale_that_fails_along_the_orbit_is_named_not_h():
    """The pendulum from (0, 1.8) reaches |q| > π/2, where V = −cos q turns positive and the
    'potential' scale (−V)^(−3/2) NaN: the line names the scale and V, not H; a g(q, p) = q² that
    falls to 0 at q = 0 stalls t there: stopped at once (it crawled for a minute), naming g."""
    from atlasnn.systems import HamiltonianSystem

    pendulum = HamiltonianSystem(lambda q, p: 0.5 * p[0] ** 2 - jnp.cos(q[0]), 1, z0=(0.0, 1.8), separable=True)
    with pytest.raises(AtlasError, match=r"time_scale \(potential\) must be finite and > 0.*V\(q\) = H\(q, 0\)") as info:
        solve(pendulum, None, (0.0, 10.0), solver=GaussCollocation(time_scale="potential"))
    assert "J∇H" not in str(info.value) and "\n" not in str(info.value)
    oscillator = HamiltonianSystem(lambda q, p: 0.5 * p[0] ** 2 + 0.5 * q[0] ** 2, 1, z0=(1.0, 0.0))
    with pytest.raises(AtlasError, match="t advanced .*-fold less per window.*stays positive") as info:
        solve(oscillator, None, (0.0, 10.0), solver=GaussCollocation(time_scale=lambda q, p: q[0] ** 2))
    assert "1.57" in str(info.value) and info.value.partial is not None

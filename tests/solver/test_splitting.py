"""The explicit splitting solver: its step from the tolerance against exact solutions, dense output,
the error estimate, symplecticity of every scheme's step, the default's choice, jit/grad/vmap,
batches, save and load, and its refusals."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn import builtin_system, expression_system, load, save, solve, solve_batch
from atlasnn.errors import AtlasError, ConfigError
from atlasnn.evaluation import reference_solution
from atlasnn.solutions import SPLITTING_SCHEMES, SplittingSolution, splitting_scheme
from atlasnn.solutions import split_step, start_state
from atlasnn.solver import GaussCollocation, SplittingComposition, default_solver
from atlasnn.systems import HamiltonianSystem

HH = builtin_system("henon_heiles")
HH_Z0 = np.array([0.3, -0.3, 0.3, 0.15])


def _pendulum() -> HamiltonianSystem:
    return expression_system("p**2/2 - cos(q)", ["q"], ["p"], separable=True, z0=[1.5, 0.0], name="pendulum")


def _kepler() -> HamiltonianSystem:
    e = 0.6
    return expression_system("(px**2 + py**2)/2 - 1/sqrt(qx**2 + qy**2)", ["qx", "qy"], ["px", "py"], separable=True,
                             z0=[1 - e, 0.0, 0.0, math.sqrt((1 + e) / (1 - e))], name="kepler")


@pytest.mark.parametrize("rtol", [1e-6, 1e-9])
def test_the_step_from_the_tolerance_meets_it_on_an_exact_solution(rtol):
    """Harmonic oscillator (exact) and a pendulum at large amplitude (DOP853 at 1e-13, far below the
    tolerance): the error over the interval within a few tolerances, not a thousand times below."""
    osc = builtin_system("harmonic_oscillator")
    T = 40.0
    t = np.linspace(0.0, T, 301)
    sol = solve(osc, [1.0, 0.0], (0.0, T), solver=SplittingComposition(rtol=rtol, atol=0.0))
    err = np.abs(sol(t) - np.stack([np.cos(t), -np.sin(t)], axis=1)).max()
    assert err <= 3 * rtol, (err, rtol)
    pend = _pendulum()
    sol = solve(pend, None, (0.0, T), solver=SplittingComposition(rtol=rtol, atol=0.0))
    ref = reference_solution(pend, pend.z0, t, rtol=1e-13, atol=1e-13)
    err = np.abs(sol(t) - ref).max() / np.abs(ref).max()
    assert 1e-3 * rtol < err <= 3 * rtol, (err, rtol, sol.info)


def test_dense_output_between_steps_is_as_accurate_as_at_the_steps_and_continuous():
    sol = solve(HH, HH_Z0, (0.0, 20.0), solver=SplittingComposition(scheme="yoshida4", h=0.1))
    steps = sol.t0 + sol.h * np.arange(1, sol.n_steps)
    mid = steps[:-1] + 0.37 * sol.h
    ref_steps = reference_solution(HH, HH_Z0, steps, rtol=1e-13, atol=1e-13)
    ref_mid = reference_solution(HH, HH_Z0, mid, rtol=1e-13, atol=1e-13)
    at_steps, between = np.abs(sol(steps) - ref_steps).max(), np.abs(sol(mid) - ref_mid).max()
    assert between < 3 * at_steps
    jump = np.abs(sol(steps - 1e-12) - sol(steps + 1e-12)).max()
    assert jump < 1e-10
    # the derivative is the rate of the dense output: close to the field, not equal to it
    res = np.abs(sol.residual(mid)).max()
    assert 0 < res < 100 * at_steps / sol.h


def test_a_large_states_dense_output_one_row_at_a_time_is_the_batched_ones(monkeypatch):
    """A state of 2 048 numbers or more is stepped one row at a time, the padding rows not stepped:
    the same values (and rates) as all rows at once, for a few times and for many."""
    from atlasnn.solutions import _splitting as dense_module

    chain = builtin_system("fput", particles=1024, alpha=0.0, beta=1.0)
    sol = solve(chain, chain.z0, (0.0, 5.0), solver=SplittingComposition(scheme="leapfrog", steps=20))
    times = np.random.default_rng(3).uniform(0.0, 5.0, 40)
    one_at_a_time = [sol(times[:3]), sol(times), sol.derivative(times)]
    monkeypatch.setattr(dense_module, "_EVAL_BATCH_NUMBERS", 10 ** 9)
    dense_module._dense.cache_clear()
    try:
        at_once = [sol(times[:3]), sol(times), sol.derivative(times)]
    finally:
        dense_module._dense.cache_clear()
    for a, b in zip(one_at_a_time, at_once):
        assert np.all(np.isfinite(a)) and np.abs(a - b).max() <= 1e-12 * (1.0 + np.abs(b).max())
    assert np.abs(one_at_a_time[1]).max(axis=1).min() > 0  # no row left as padding


@pytest.mark.parametrize("scheme", ["yoshida4", "kahan_li8"])
def test_the_estimate_is_the_true_error_within_a_factor_two(scheme):
    pend = _pendulum()
    T = 30.0
    sol = solve(pend, None, (0.0, T), solver=SplittingComposition(scheme=scheme, rtol=1e-7))
    t = np.linspace(0.0, T, 400)
    true = np.abs(sol(t) - reference_solution(pend, pend.z0, t, rtol=1e-13, atol=1e-13)).max()
    est = np.abs(sol.error_estimate(t)).max()
    assert 0.5 < est / true < 2.0, (est, true)
    assert 0.5 < sol.estimate().max_abs / true < 2.0


@pytest.mark.parametrize("name", sorted(SPLITTING_SCHEMES))
def test_every_schemes_step_is_symplectic(name):
    """M^T J M = J for the Jacobian M of one step, on Hénon–Heiles (a nonlinear force)."""
    scheme = splitting_scheme(name)
    with jax.enable_x64(True):
        def step(z):
            st = split_step(HH, scheme, start_state(HH, z), jnp.asarray(0.3))
            return jnp.concatenate([st.q + st.eq, st.p + st.ep])

        M = np.asarray(jax.jacfwd(step)(jnp.asarray(HH_Z0)))
    J = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.eye(2), np.zeros((2, 2))]])
    assert np.abs(M.T @ J @ M - J).max() < 1e-12


def test_the_default_chooses_by_what_it_knows_before_marching():
    pendulum2 = expression_system("(p1**2 + 2*p2**2 - 2*p1*p2*cos(q1 - q2)) / (2*(1 + sin(q1 - q2)**2)) - 2*cos(q1) "
                                  "- cos(q2)", ["q1", "q2"], ["p1", "p2"], z0=[1.0, 0.5, 0.0, 0.0])
    from atlasnn.solver import SPLITTING_AUTO_SIZE
    from atlasnn.systems import fput

    assert isinstance(default_solver(HH, HH_Z0), GaussCollocation)  # small: the Gauss solver's longer windows
    chain = fput(particles=SPLITTING_AUTO_SIZE // 2, beta=1.0)
    assert isinstance(default_solver(chain, chain.z0), SplittingComposition)
    assert isinstance(default_solver(pendulum2, pendulum2.z0), GaussCollocation)  # not separable
    kepler = _kepler()
    assert isinstance(default_solver(kepler, kepler.z0), GaussCollocation)  # gravitational: close encounters
    sol = solve(chain, chain.z0, (0.0, 5.0), rtol=1e-8)
    assert isinstance(sol, SplittingSolution) and sol.info["solver"] == "splitting"
    assert sol.info["scheme"] in SPLITTING_SCHEMES


def test_jit_grad_and_vmap_through_a_splitting_solve():
    solver = SplittingComposition(scheme="yoshida4", steps=200)
    T = 5.0

    def q_end(z):
        return solve(HH, z, (0.0, T), solver=solver)(jnp.asarray(T))[0]

    with jax.enable_x64(True):
        z = jnp.asarray(HH_Z0)
        g = np.asarray(jax.jit(jax.grad(q_end))(z))
        eps = 1e-6
        fd = np.array([(q_end(z + eps * e) - q_end(z - eps * e)) / (2 * eps) for e in jnp.eye(4)])
        assert np.abs(g - fd).max() < 1e-7
        host = solve(HH, HH_Z0, (0.0, T), solver=solver)
        assert abs(float(q_end(z)) - host(np.array([T]))[0, 0]) < 1e-14
        ends = jax.vmap(lambda z: solve(HH, z, (0.0, T), solver=solver).end_state)(jnp.stack([z, 0.9 * z]))
        assert np.abs(np.asarray(ends[0]) - host.end_state).max() < 1e-14
    with pytest.raises(ConfigError, match="steps=N"):
        jax.jit(lambda z: solve(HH, z, (0.0, T), solver=SplittingComposition()).end_state)(jnp.asarray(HH_Z0))


def test_a_batch_shares_one_step_and_saves_and_loads(tmp_path):
    sols = solve_batch(HH, [HH_Z0, 0.8 * HH_Z0], (0.0, 10.0), solver=SplittingComposition(rtol=1e-8))
    t = np.linspace(0.0, 10.0, 50)
    assert sols[0].h == sols[1].h
    for sol, z0 in zip(sols, (HH_Z0, 0.8 * HH_Z0)):  # the shared step meets each member's tolerance
        ref = reference_solution(HH, z0, t, rtol=1e-13, atol=1e-13)
        assert np.abs(sol(t) - ref).max() <= 3e-8 * np.abs(ref).max()
    path = tmp_path / "s.npz"
    save(path, sols[1])
    back = load(path)
    assert isinstance(back, SplittingSolution)
    assert np.array_equal(back(t), sols[1](t))
    assert back.estimate().max_abs == pytest.approx(sols[1].estimate().max_abs, rel=1e-12)


def test_refusals_are_one_line():
    pendulum2 = expression_system("p1**2/2 + p2**2/2 + p1*p2*cos(q1 - q2) - cos(q1)", ["q1", "q2"], ["p1", "p2"],
                                  z0=[1.0, 0.5, 0.0, 0.0])
    for bad, match in ((lambda: SplittingComposition(scheme="nope"), "unknown splitting scheme"),
                       (lambda: SplittingComposition(h=0.1, steps=3), "h or steps"),
                       (lambda: SplittingComposition(steps=0), "steps must be an integer"),
                       (lambda: solve(pendulum2, None, (0.0, 1.0), solver=SplittingComposition()), "separable")):
        with pytest.raises(AtlasError, match=match) as info:
            bad()
        assert "\n" not in str(info.value)


def test_the_cli_says_which_method_ran(capsys):
    from atlasnn.cli import main

    assert main(["solve", "--system", "henon_heiles", "--T", "6*pi", "--rtol", "1e-8", "--solver", "splitting"]) == 0
    out = capsys.readouterr().out
    assert "splitting scheme" in out and "estimated max error" in out


def test_the_linear_parts_flow_is_the_matrix_exponential():
    from scipy.linalg import expm

    from atlasnn.systems import DenseLinearPart, FourierLinearPart, fourier_wavenumbers

    k2 = fourier_wavenumbers(16, 10.0) ** 2
    z = np.random.default_rng(0).standard_normal(32)
    J = np.block([[np.zeros((16, 16)), np.eye(16)], [-np.eye(16), np.zeros((16, 16))]])
    S = np.random.default_rng(1).standard_normal((32, 32))
    # elliptic modes, a wave equation's, and hyperbolic ones (K_q K_p < 0 at small k)
    for part in (FourierLinearPart(0.5 * k2, 0.5 * k2), FourierLinearPart(1 + k2, np.ones(16)),
                 FourierLinearPart(k2 - 3.0, np.ones(16)), DenseLinearPart(S + S.T)):
        with jax.enable_x64(True):
            got = np.asarray(part.flow(jnp.asarray(z), -0.37))
        assert np.abs(got - expm(-0.37 * J @ part.matrix()) @ z).max() < 1e-11


def test_a_pde_with_its_declared_flows_is_split_step_solved_to_its_tolerance():
    """NLS: the linear part's flow and the phase rotation, composed; against the exact soliton,
    mass to round-off; the declared rotation's rate is J∇H − JSz (the split is exact)."""
    from atlasnn.systems import nls, nls_mass, sine_gordon

    wave = nls(points=64, length=32.0)
    with jax.enable_x64(True):
        z = jnp.asarray(wave.z0)
        rest = wave.vector_field(z[None])[0] - wave.linear_part.field(z)
        eps = 1e-6
        rate = (wave.nonlinear_flow(z, eps) - wave.nonlinear_flow(z, -eps)) / (2 * eps)
    assert np.abs(np.asarray(rest - rate)).max() < 1e-8
    assert isinstance(default_solver(wave, wave.z0), GaussCollocation)  # measured faster on the soliton
    T = 3.0
    sol = solve(wave, None, (0.0, T), solver=SplittingComposition(rtol=1e-8, atol=0.0))
    # the semi-discrete solution (the exact soliton is 1e-4 off it on this coarse grid): Gauss at 1e-13
    exact = solve(wave, None, (0.0, T), solver=GaussCollocation(rtol=1e-13)).end_state
    err = np.abs(sol(np.asarray([T]))[0] - exact).max()
    assert 1e-12 < err <= 3e-8
    assert abs(nls_mass(sol.end_state) / nls_mass(wave.z0) - 1) < 1e-13
    sg = sine_gordon(points=64, length=40.0)
    sol = solve(sg, None, (0.0, 5.0), solver=SplittingComposition(rtol=1e-7, atol=0.0))
    ref = solve(sg, None, (0.0, 5.0), solver=GaussCollocation(rtol=1e-13)).end_state
    assert np.abs(sol.end_state - ref).max() <= 3e-7 * np.abs(ref).max()


def test_a_pilot_over_the_whole_interval_is_the_march_where_its_steps_suffice():
    """On a short interval the pilot's two marches (16 steps and 32) cover it: where 32 steps meet
    the tolerance, that march is the solution — the same numbers as a march of 32 steps — and its
    check is the pilot's 16-step march, as a check with twice the step would read it (recomputed
    here from two separate solves); over a longer interval, a march of its own."""
    from atlasnn.systems import nls

    wave = nls(points=64, length=32.0)
    T, rtol = 3.0, 1e-6
    sol = solve(wave, None, (0.0, T), solver=SplittingComposition(rtol=rtol, atol=0.0))
    info = sol.info
    assert info["march_from_pilot"] is True and info["steps"] == 32 and info["tries"] == 1
    scheme = info["scheme"]
    fine = solve(wave, None, (0.0, T), solver=SplittingComposition(scheme=scheme, steps=32))
    coarse = solve(wave, None, (0.0, T), solver=SplittingComposition(scheme=scheme, steps=16))
    assert np.array_equal(fine.end_state, sol.end_state)
    t = np.linspace(0.0, T, 17)
    mine = fine(t)
    p = 2.0 ** splitting_scheme(scheme).order
    check = np.abs(coarse(t) - mine).max() / (p - 1.0) / (rtol * np.abs(mine).max())
    assert info["check"] == pytest.approx(check, rel=1e-6) and info["check"] <= 1.0
    exact = solve(wave, None, (0.0, T), solver=GaussCollocation(rtol=1e-13)).end_state
    assert np.abs(sol.end_state - exact).max() <= 3 * rtol * np.abs(exact).max()
    longer = solve(wave, None, (0.0, 10 * T), solver=SplittingComposition(rtol=rtol, atol=0.0)).info
    assert "march_from_pilot" not in longer and longer["steps"] > 32


def test_a_linear_part_without_the_rests_flow_is_refused_in_one_line():
    import dataclasses

    from atlasnn.systems import nls

    wave = dataclasses.replace(nls(points=16, length=16.0), nonlinear_flow=None)
    assert isinstance(default_solver(wave, wave.z0), GaussCollocation)
    with pytest.raises(ConfigError, match="nonlinear_flow") as info:
        solve(wave, None, (0.0, 1.0), solver=SplittingComposition())
    assert "\n" not in str(info.value)


def _slow_mode_chain(n: int):
    from atlasnn.systems import fput

    return fput(particles=n, beta=1.0), np.concatenate([np.zeros(n), np.sin(np.pi * np.arange(1, n + 1) / (n + 1))])


@pytest.mark.parametrize("rtol, scheme", [(1e-8, "mclachlan4"), (1e-11, "blanes_moan6")])
def test_a_stability_bound_step_takes_the_cheapest_scheme_that_meets_the_tolerance_at_its_limit(rtol, scheme):
    """FPUT-β of 128 particles excited in its slowest mode: the step is held by the fastest mode's
    stability, not by accuracy; the default probes the schemes at their stability limits, the
    cheapest there first (McLachlan's order 4, then Blanes–Moan's order 6), and takes the first
    that meets the tolerance there: at 1e-8 McLachlan's, at 1e-11 Blanes–Moan's (not the
    tolerance's Sofroniou–Spaletta 10, 3.5 times the force evaluations at its limit). The check
    compares with steps 7/8 as long — a longer step than one held at the limit is not stable —
    and the tolerance is met."""
    chain, z0 = _slow_mode_chain(128)
    sol = solve(chain, z0, (0.0, 50.0), rtol=rtol)
    assert sol.info["limited_by"] == "stability" and sol.info["scheme"] == scheme
    assert list(sol.info["scheme_choice"])[-1] == scheme and "sofspa10" not in sol.info["scheme_choice"]
    assert sol.info["check_steps"] * 7 == sol.info["steps"] * 8 and sol.info["check"] <= 1.0
    t = np.linspace(0.0, 50.0, 40)
    ref = reference_solution(chain, z0, t, rtol=1e-13, atol=1e-13)
    assert np.abs(sol(t) - ref).max() <= 3 * rtol * np.abs(ref).max() + 1e-13


@pytest.mark.parametrize("modes", ["slowest", "all"])
def test_where_the_reach_scheme_misses_the_tolerance_the_schemes_are_weighed_by_their_cost(modes):
    """Where the reach schemes at their stability limits miss the tolerance (a chain of 32 in its
    slowest mode at 1e-8; energy in every mode at 1e-9), the tolerance's scheme is piloted too,
    the one of fewer force evaluations over the interval taken, and the tolerance met; the check
    compares with steps twice as long unless stability holds the step."""
    n, T, rtol = (32, 50.0, 1e-8) if modes == "slowest" else (32, 100.0, 1e-9)
    chain, z0 = _slow_mode_chain(n)
    if modes == "all":
        p = np.random.default_rng(0).standard_normal(n)
        z0 = np.concatenate([np.zeros(n), p / np.linalg.norm(p)])
    sol = solve(chain, z0, (0.0, T), rtol=rtol)
    costs = sol.info["scheme_choice"]
    assert len(costs) >= 2 and sol.info["scheme"] == min(costs, key=costs.get)
    a, b = (7, 8) if sol.info.get("limited_by") == "stability" else (2, 1)
    assert sol.info["check_steps"] * a == sol.info["steps"] * b and sol.info["check"] <= 1.0
    t = np.linspace(0.0, T, 50)
    ref = reference_solution(chain, z0, t, rtol=1e-13, atol=1e-13)
    assert np.abs(sol(t) - ref).max() <= 3 * rtol * np.abs(ref).max()


def test_a_reach_scheme_whose_check_fails_gives_way_to_the_tolerances_scheme():
    """FPUT-β of 64 particles in its slowest mode over [0, 200]: the pilots, 16 steps from z0, see
    McLachlan's scheme meet 1e-7 at its stability limit, but the energy then spreads into faster
    modes and the check finds the error far above the tolerance. The retry grows the order-6
    pilot's error as a frequency the pilots missed would (the check's factor to the power 6/4)
    and takes the tolerance's scheme, cheaper than McLachlan's at the step accuracy now asks; the
    tolerance is met at that step, with no third march (read as many times too low as
    McLachlan's, the order-6 pilot asked for too few steps and a third march was needed)."""
    chain, z0 = _slow_mode_chain(64)
    sol = solve(chain, z0, (0.0, 200.0), rtol=1e-7, atol=1e-9)
    costs = sol.info["retry_choice"]
    assert sol.info["first_scheme"] == "mclachlan4" and sol.info["first_check"] > 10
    assert sol.info["scheme"] == "blanes_moan6" == min(costs, key=costs.get) and sol.info["check"] <= 1.0
    assert sol.info["tries"] == 2
    t = np.linspace(0.0, 200.0, 60)
    ref = reference_solution(chain, z0, t, rtol=1e-13, atol=1e-13)
    assert np.abs(sol(t) - ref).max() <= 3e-7 * np.abs(ref).max()


def test_a_float32_state_inside_jit_is_told_what_to_do():
    """With 64-bit mode on, a float32 z0 is refused with the remedy that applies (a float64 z0), not
    the advice to turn on the mode that is on; by either solver."""
    with jax.enable_x64(True):
        z32 = jnp.asarray(HH_Z0, jnp.float32)
        for solver in (SplittingComposition(steps=10), GaussCollocation()):
            with pytest.raises(ConfigError, match="pass z0 as float64") as info:
                jax.jit(lambda z, s=solver: solve(HH, z, (0.0, 1.0), solver=s).end_state)(z32)
            assert "64-bit mode" not in str(info.value)


def test_the_looped_step_takes_the_written_out_steps_numbers():
    """The dense output's step (its stages in a loop) and the march's (written out) are one method:
    the same state to round-off for every scheme, kick-first and drift-first."""
    from atlasnn.solutions._splitting_step import looped_step

    with jax.enable_x64(True):
        for name in SPLITTING_SCHEMES:
            scheme = splitting_scheme(name)
            st = start_state(HH, jnp.asarray(HH_Z0))
            a, b = (split_step(HH, scheme, st, jnp.asarray(0.2)), looped_step(HH, scheme, st, jnp.asarray(0.2)))
            gap = max(float(jnp.abs((x + ex) - (y + ey)).max()) for x, ex, y, ey in
                      ((a.q, a.eq, b.q, b.eq), (a.p, a.ep, b.p, b.ep)))
            assert gap < 1e-15, (name, gap)


def test_a_nystrom_scheme_is_refused_where_T_is_not_quadratic():
    """The Nyström schemes keep their order only for T quadratic in p: on T = Σ cosh p_i the check
    after the march, which assumes the order, would pass an error above the tolerance; refused."""
    cosh = HamiltonianSystem(lambda q, p: jnp.sum(jnp.cosh(p)) + jnp.sum(q ** 4) / 4, 2, separable=True,
                             z0=[0.5, -0.3, 0.2, 0.1])
    with pytest.raises(ConfigError, match="quadratic in p") as info:
        solve(cosh, None, (0.0, 1.0), solver=SplittingComposition(scheme="bce_rkn8"))
    assert "\n" not in str(info.value)
    sol = solve(HH, HH_Z0, (0.0, 1.0), solver=SplittingComposition(scheme="bce_rkn8", rtol=1e-8))  # T = p²/2
    assert sol.info["scheme"] == "bce_rkn8"


def test_a_mislabelled_non_separable_h_is_stopped_in_one_line_with_what_was_marched():
    """H declared separable that is not: the check after the march keeps finding the error above
    the tolerance; after its last try the march stops in one line that asks whether H is separable."""
    def H(q, p):
        return 0.5 * jnp.sum(p ** 2) * (1 + 0.1 * jnp.sum(q ** 2)) + 0.5 * jnp.sum(q ** 2)

    wrong = HamiltonianSystem(H, 32, separable=True, z0=np.full(64, 0.1))
    with pytest.raises(ConfigError, match="is H = T\\(p\\) \\+ V\\(q\\) as declared") as info:
        solve(wrong, None, (0.0, 1.0), rtol=1e-8)
    assert "\n" not in str(info.value) and isinstance(info.value.partial, SplittingSolution)

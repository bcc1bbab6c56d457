"""The Gauss collocation (atlasnn.solver.GaussCollocation, the default of atlasnn.solve): the
method's properties (order 2s, symplectic map, quadratic invariants exact, the collocation
conditions and the dense output), its error estimate against the true error, step modes, the
Newton fallback, batches, save/load, and bad input in one line."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn import AtlasError, solve, solve_batch
from atlasnn.checkpoint import load_piecewise, save_piecewise
from atlasnn.solutions import PolynomialSolution, gauss_tableau
from atlasnn.solver import GaussCollocation
from atlasnn.solver import _gauss_march
from atlasnn.solver._gauss_step import STAGE_SHARE, gauss_step, stage_share, tableau_arrays
from atlasnn.systems import expression_system, harmonic_oscillator, henon_heiles


def kepler(e: float):
    return expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                             z0=[1 - e, 0.0, 0.0, float(np.sqrt((1 + e) / (1 - e)))], separable=True,
                             name=f"kepler-{e}")


def kepler_exact(t, e):
    """Kepler's orbit from pericentre at t = 0 (a = 1, period 2π), by Kepler's equation."""
    M = np.mod(np.asarray(t, np.float64), 2 * np.pi)
    E = M + e * np.sin(M)
    for _ in range(50):
        E = E - (E - e * np.sin(E) - M) / (1 - e * np.cos(E))
    c, s, w = np.cos(E), np.sin(E), np.sqrt(1 - e * e)
    return np.stack([c - e, w * s, -s / (1 - e * c), w * c / (1 - e * c)], axis=-1)


def ho_exact(t):
    return np.stack([np.cos(t), -np.sin(t)], axis=-1)


@pytest.mark.long
@pytest.mark.parametrize("stages", [2, 3])
def test_order_2s_at_the_window_ends(stages):
    """Fixed steps on Kepler e = 0.3 over one period: halving h divides the end error by ~2^(2s)."""
    e, T = 0.3, 2 * np.pi
    system = kepler(e)
    errors = []
    for windows in (40, 80, 160):
        sol = solve(system, None, (0.0, T), solver=GaussCollocation(stages=stages, h=T / windows))
        assert sol.n_windows == windows
        errors.append(np.abs(sol.end_state - kepler_exact(T, e)).max())
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(slopes - 2 * stages) < 0.6), (errors, slopes)


def test_dense_output_is_of_order_s_plus_1():
    """Between the window ends the polynomial is of order s + 1 (its stage order), far below 2s."""
    T, s = 4.0, 4
    t = np.linspace(0.0, T, 1001)
    errors = []
    for h in (0.4, 0.2, 0.1):
        sol = solve(harmonic_oscillator(), [1.0, 0.0], (0.0, T), solver=GaussCollocation(stages=s, h=h))
        errors.append(np.abs(sol(t) - ho_exact(t)).max())
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(slopes - (s + 1)) < 0.7), (errors, slopes)


@pytest.mark.long
def test_the_polynomial_meets_the_equations_at_the_gauss_nodes():
    system = henon_heiles()
    sol = solve(system, None, (0.0, 6.0), solver=GaussCollocation(stages=5))
    c = gauss_tableau(5).c
    starts, lengths = sol.edges[:-1], np.diff(sol.edges)
    t = (starts[:, None] + lengths[:, None] * c[None, :]).reshape(-1)
    z, dz = sol(t), sol.derivative(t)
    with jax.enable_x64(True):
        field = np.asarray(system.vector_field(jnp.asarray(z)))
    assert np.abs(dz - field).max() < 1e-12 * np.abs(field).max()
    assert np.array_equal(sol(0.0), np.asarray(system.z0))  # exact at t0, whatever the polynomial
    inner = sol.edges[1:-1]
    assert np.abs(sol(inner - 1e-12) - sol(inner)).max() < 1e-11  # continuous at every window edge


def test_one_window_is_a_symplectic_map():
    """The Jacobian M of z_n -> z_{n+1} (a nonlinear system, a long window) satisfies MᵀJM = J to round-off."""
    system = henon_heiles()
    tab = tableau_arrays(gauss_tableau(8))
    J = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.eye(2), np.zeros((2, 2))]])
    with jax.enable_x64(True):
        def step(z):
            Y0 = jnp.broadcast_to(z, (8, 4))
            return gauss_step(system.vector_field, None, tab, z, jnp.zeros(4), 0.6, Y0).z

        z = jnp.asarray([0.3, -0.3, 0.3, 0.15])
        M = np.asarray(jax.jit(jax.jacfwd(step))(z))
    assert np.abs(M.T @ J @ M - J).max() < 1e-13
    assert np.abs(M - np.eye(4)).max() > 0.1  # a map far from the identity


def test_angular_momentum_is_kept_to_round_off():
    """Kepler e = 0.6 over 20 periods: L = q1 p2 − q2 p1 (a quadratic invariant) stays to round-off,
    the energy (not quadratic) to the method's accuracy."""
    system = kepler(0.6)
    sol = solve(system, None, (0.0, 40 * np.pi), solver=GaussCollocation(stages=8, h=2 * np.pi / 60))
    z = sol.z + sol.e
    L = z[:, 0] * z[:, 3] - z[:, 1] * z[:, 2]
    assert np.abs(L - L[0]).max() < 2e-14 * np.sqrt(sol.n_windows)
    energy = system.energy64(z)
    assert np.abs(energy - energy[0]).max() < 1e-10


@pytest.mark.long
@pytest.mark.parametrize("rtol", [1e-6, 1e-9])
def test_the_estimate_tracks_the_true_error_on_kepler(rtol):
    """Against the exact orbit (e = 0.9: pericentre passages; tolerances it was not tuned on)."""
    e, T = 0.9, 4 * np.pi
    sol = solve(kepler(e), None, (0.0, T), solver=GaussCollocation(rtol=rtol, atol=rtol / 100))
    t = np.linspace(0.0, T, 4001)
    true = np.abs(sol(t) - kepler_exact(t, e)).max()
    est = sol.estimate().max_abs
    assert true / 3 <= est <= 3 * true, (true, est)
    pointwise = sol.error_estimate(t)
    assert np.corrcoef(pointwise.ravel(), (kepler_exact(t, e) - sol(t)).ravel())[0, 1] > 0.9


def test_the_tolerance_controls_the_error():
    system = harmonic_oscillator()
    t = np.linspace(0.0, 20.0, 2001)
    errors = [np.abs(solve(system, [1.0, 0.0], (0.0, 20.0), solver=GaussCollocation(stages=6, rtol=r, atol=r / 100))(t)
                     - ho_exact(t)).max() for r in (1e-6, 1e-9, 1e-12)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-11


@pytest.mark.parametrize("H, names, z0, omega", [
    ("p**2/2 + 9*q**2/2", (["q"], ["p"]), [1.0, 0.0], 3.0),
    ("(p1**2 + p2**2)/2 + q1**2/2 + 25*q2**2/2 + q1**4/4", (["q1", "q2"], ["p1", "p2"]), [1.0, 0.1, 0.0, 0.0], 5.0),
])
def test_the_first_window_is_one_over_the_fastest_frequency(H, names, z0, omega):
    """The first length is 1/ω, ω² the spectral radius of A² at z0 by power iterations of central
    differences of the field: 3 for an oscillator of frequency 3, 5 for two modes of 2 and 5."""
    sol = solve(expression_system(H, *names, z0=z0), None, (0.0, 10.0))
    assert sol.edges[1] - sol.edges[0] == pytest.approx(1 / omega, rel=1e-6)


def test_at_a_loose_tolerance_the_stage_equations_stop_at_their_share():
    """rtol 1e-5 over 51 windows: each window's stages solved to about 0.01·rtol/51, not round-off —
    the gap to the same windows solved to round-off is above round-off (the saving is taken) and,
    added over every window, within a few hundredths of rtol (the budget kept)."""
    system, z0, rtol = henon_heiles(), np.array([0.3, -0.3, 0.3, 0.15]), 1e-5
    sol = solve(system, z0, (0.0, 24 * np.pi), solver=GaussCollocation(rtol=rtol, atol=rtol / 100))
    n = sol.n_windows
    again = _gauss_march.compiled_gauss_windows(system, stages=sol.stages, max_iterations=100, newton=False)
    with jax.enable_x64(True):
        L = np.asarray(again(sol.z[:-1], sol.e[:-1], np.diff(sol.edges)[:-1]))
    ends = sol.z[:-1] + (sol.e[:-1] + L.sum(axis=1))
    gap = np.abs(ends - (sol.z[1:] + sol.e[1:])).max(axis=1) / np.abs(sol.z).max()
    assert gap.max() > 1e-12  # round-off's rule leaves a few 1e-15 here (at rtol 1e-11)
    assert gap.sum() < 5 * STAGE_SHARE * rtol
    with jax.enable_x64(True):
        assert float(stage_share(1e-11, 50.0)) == 0.0  # the default: round-off's rule alone
        assert float(stage_share(rtol, float(n))) == pytest.approx(STAGE_SHARE * rtol / n)


@pytest.mark.long
def test_constant_steps_keep_one_length_and_adaptive_ones_follow_the_orbit():
    system = kepler(0.9)
    T = 4 * np.pi
    const = solve(system, None, (0.0, T), solver=GaussCollocation(rtol=1e-10, atol=1e-12, time_scale=None))
    lengths = np.diff(const.edges)[8:-1]  # after the warm-up, before the last (clipped) window
    assert len(np.unique(np.round(lengths / lengths[0], 9))) <= 8  # a handful of shortenings at most
    assert "advice" in const.info  # its time scale varies 83-fold: time_scale='potential' would take fewer windows
    adaptive = solve(system, None, (0.0, T), solver=GaussCollocation(rtol=1e-10, atol=1e-12, steps="adaptive"))
    assert adaptive.n_windows < const.n_windows / 3  # long windows at apocentre
    t = np.linspace(0.0, T, 2001)
    for sol in (const, adaptive):
        assert np.abs(sol(t) - kepler_exact(t, 0.9)).max() < 1e-9


def test_a_kink_in_h_stops_the_constant_march_in_one_line():
    # H = p²/2 + |q| from (1, 0): q = 1 − t²/2 until the kink at t = √2, where constant windows would
    # shrink 10¹⁰-fold and crawl to T; the march stops at once, naming the cause, keeping the part done
    from atlasnn.systems import HamiltonianSystem

    system = HamiltonianSystem(lambda q, p: 0.5 * p[0] ** 2 + jnp.abs(q[0]), 1, z0=(1.0, 0.0), name="kink")
    with pytest.raises(AtlasError, match="not smooth there") as info:
        solve(system, None, (0.0, 10.0))
    line = str(info.value)
    assert "\n" not in line and "steps='adaptive'" in line and "1.414" in line
    part = info.value.partial
    t = np.linspace(0.0, 1.4, 50)
    assert np.abs(part(t)[:, 0] - (1 - t ** 2 / 2)).max() < 1e-10
    # adaptive windows pass the kinks, but not to the tolerance (docs/SOLVER.md, "Non-smooth Hamiltonians"):
    # whether a kink falls where the check cannot see it depends on the last bits of the lengths (an
    # energy drift of 5e-5 on an AVX2 machine, 2e-11 on an AVX-512 one), so only its bound is asserted
    period = 4 * np.sqrt(2.0)
    adaptive = solve(system, None, (0.0, 2.5 * period), solver=GaussCollocation(steps="adaptive"))
    assert np.abs(adaptive(period) - [1.0, 0.0]).max() < 1e-8
    drift = np.abs(adaptive.energy(np.linspace(0.0, 2.5 * period, 1001)) - 1.0).max()
    assert drift < 1e-3
    # inside jax.jit the traced core spends its window budget at the kink, and says why
    traced = jax.jit(lambda z: solve(system, z, (0.0, 10.0), solver=GaussCollocation(max_windows=512))(10.0))
    with jax.enable_x64(True), pytest.raises(Exception, match="spent on windows that shrank .* not smooth there"):
        jax.block_until_ready(traced(jnp.asarray([1.0, 0.0], jnp.float64)))


@pytest.mark.long
def test_newton_takes_over_where_the_fixed_point_iteration_diverges():
    """A stiff oscillator (ω = 50) with h = 0.2 (hω = 10): the fixed-point iteration cannot contract,
    the simplified Newton iteration solves the (linear) window; the energy, quadratic, is exact."""
    system = harmonic_oscillator(omega=50.0)
    sol = solve(system, [1.0, 0.0], (0.0, 4.0), solver=GaussCollocation(stages=4, h=0.2))
    assert sol.info["newton_windows"] >= sol.n_windows - 1
    energy = system.energy64(sol.z + sol.e)
    assert np.abs(energy / energy[0] - 1).max() < 1e-13
    with pytest.raises(AtlasError, match="did not converge") as info:
        solve(system, [1.0, 0.0], (0.0, 4.0), solver=GaussCollocation(stages=4, h=0.2, newton=False))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("mode", ["sequential", "lockstep"])
def test_a_batch_equals_its_members_solved_alone(mode, monkeypatch):
    # both ways of marching members: one after the other (a CPU's) and in lock step (an accelerator's)
    monkeypatch.setattr(_gauss_march, "batch_mode", lambda: mode)
    system = henon_heiles()
    z0s = np.array([[0.3, -0.3, 0.3, 0.15], [0.1, 0.2, -0.2, 0.1], [0.0, 0.4, 0.2, 0.0]])
    sols = solve_batch(system, z0s, (0.0, 10.0))
    t = np.linspace(0.0, 10.0, 301)
    for z0, sol in zip(z0s, sols):
        alone = solve(system, z0, (0.0, 10.0))
        assert sol.info["batch"] == 3
        # each member has windows of its own (its first lengths grow from round-off-level checks,
        # which differ in the last bits between the batched and the lone program): equal to accuracy
        assert np.abs(sol(t) - alone(t)).max() < 1e-12


def test_save_and_load_evaluate_bit_for_bit_and_keep_the_estimate(tmp_path):
    system = henon_heiles()
    sol = solve(system, None, (0.0, 12.0))
    path = tmp_path / "hh.npz"
    save_piecewise(path, sol)
    back = load_piecewise(path)
    assert isinstance(back, PolynomialSolution)
    t = np.linspace(0.0, 12.0, 333)
    assert np.array_equal(back(t), sol(t)) and np.array_equal(back.derivative(t), sol.derivative(t))
    assert back.estimate().max_abs == pytest.approx(sol.estimate().max_abs, rel=1e-6)


def test_a_solution_without_its_polynomials_solves_windows_again():
    system = henon_heiles()
    kept = solve(system, None, (0.0, 12.0))
    bare = solve(system, None, (0.0, 12.0), solver=GaussCollocation(keep=False))
    assert bare.L is None and kept.L is not None
    t = np.linspace(0.0, 12.0, 257)
    assert np.abs(bare(t) - kept(t)).max() < 1e-14


def test_windows_solved_again_are_padded_to_few_not_to_the_block(monkeypatch):
    # a call that needs five windows solves eight, not a block of thousands (50 s a call on a wide NLS)
    from atlasnn.solver import _gauss

    sizes, real = [], _gauss.compiled_gauss_windows

    def recording(*args, **kwargs):
        program = real(*args, **kwargs)
        return lambda z, e, h: sizes.append(len(h)) or program(z, e, h)

    monkeypatch.setattr(_gauss, "compiled_gauss_windows", recording)
    system = henon_heiles()
    bare = solve(system, None, (0.0, 12.0), solver=GaussCollocation(keep=False))
    kept = solve(system, None, (0.0, 12.0))
    t = np.linspace(0.0, bare.edges[5], 40, endpoint=False)
    assert np.abs(bare(t) - kept(t)).max() < 1e-14
    assert sizes == [8]


def test_many_times_per_window_are_evaluated_window_by_window_alike(monkeypatch):
    # above a size of gathered polynomials, times are evaluated one window at a time (one product
    # per window): the same values and derivatives as gathering each time's polynomial, in and out of order
    from atlasnn.solutions import _polynomial

    sol = solve(henon_heiles(), None, (0.0, 12.0))
    t = np.random.default_rng(0).uniform(0.0, 12.0, 997)
    gathered = sol(t), sol.derivative(t), sol.window_values(t, sol.window_index(t), 2)
    monkeypatch.setattr(_polynomial, "_GATHER_BYTES", 0)
    assert 4 * sol.n_windows <= t.size  # the window-by-window path is taken
    windowed = sol(t), sol.derivative(t), sol.window_values(t, sol.window_index(t), 2)
    for a, b in zip(gathered[:2], windowed[:2]):
        assert np.abs(a - b).max() <= 1e-15 * np.abs(a).max()
    for a, b in zip(gathered[2], windowed[2]):
        assert a.shape == b.shape == t.shape and np.abs(a - b).max() <= 1e-15 * np.abs(a).max()


@pytest.mark.parametrize("settings, needle", [
    ({"stages": 0}, "stages must be an integer from 1 to 16"),
    ({"stages": 40}, "stages must be an integer from 1 to 16"),
    ({"steps": "variable"}, "steps must be one of"),
    ({"h": -1.0}, "h must be a finite number > 0"),
    ({"rtol": float("nan")}, "rtol must be a finite number > 0"),
    ({"rtol": 1e-20}, "below what it can reach"),
    ({"rtol": 10.0}, "larger than the solution itself; give a relative tolerance of at most 1"),
    ({"growth": 1.0}, "growth must be > 1"),
    ({"keep": "yes"}, "keep must be true or false"),
])
def test_bad_settings_are_one_line(settings, needle):
    with pytest.raises(AtlasError, match=needle) as info:
        GaussCollocation(**settings)
    assert "\n" not in str(info.value)


def test_numpy_tolerances_are_numbers():
    solver = GaussCollocation(rtol=np.float32(1e-8), atol=np.float64(1e-12))
    assert solver.rtol == pytest.approx(1e-8) and isinstance(solver.rtol, float)

"""Tests of the fixed-step symplectic integrators and the DOP853 reference solution."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.evaluation import _integrators as integ
from atlasnn.errors import AtlasError, ConfigError, SystemError_
from atlasnn.evaluation import (
    INTEGRATORS,
    REFERENCE_DESCRIPTION,
    integrate,
    reference_solution,
    stormer_verlet,
    symplectic_euler,
    yoshida4,
)
from atlasnn.systems import (
    HamiltonianSystem,
    harmonic_exact,
    harmonic_oscillator,
    henon_heiles,
    nonlinear_oscillator,
)

METHODS = sorted(INTEGRATORS)


def _energy64(system, Z):
    with jax.enable_x64(True):
        return np.asarray(system.energy(jnp.asarray(Z, dtype=jnp.float64)), dtype=np.float64)


def _one_line(exc_info) -> str:
    msg = str(exc_info.value)
    assert msg and "\n" not in msg
    return msg


# ------------------------------------------------------------------ hand-computed steps
def _se_by_hand(x, p, dt, lam=1.0):
    """One symplectic Euler step of H = p²/2 + x²/2 + lam x⁴/4 with plain floats."""
    x_new = x + dt * p  # ∂H/∂p = p, with the old p
    p_new = p - dt * (x_new + lam * x_new**3)  # ∂H/∂x at the new x
    return x_new, p_new


@pytest.mark.parametrize("x64_global", [False, True])
def test_symplectic_euler_two_hand_steps(x64_global):
    sys_ = nonlinear_oscillator()
    x1, p1 = _se_by_hand(1.3, 1.0, 0.1)
    x2, p2 = _se_by_hand(x1, p1, 0.1)
    # The numbers written out: x1 = 1.4, p1 = 1 − 0.1 (1.4 + 1.4³) = 0.5856.
    assert x1 == pytest.approx(1.4, abs=1e-15)
    assert p1 == pytest.approx(0.5856, abs=1e-15)
    with jax.enable_x64(x64_global):
        t, Z = symplectic_euler(sys_, [1.3, 1.0], 0.0, 0.2, 2)
    assert t.dtype == np.float64 and Z.dtype == np.float64
    assert t.shape == (3,) and Z.shape == (3, 2)
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(Z[0], [1.3, 1.0])
    np.testing.assert_allclose(Z[1], [x1, p1], rtol=1e-14, atol=0)
    np.testing.assert_allclose(Z[2], [x2, p2], rtol=1e-14, atol=0)
    # The other ordering (p first with the old q) gives visibly different numbers.
    p1_wrong = 1.0 - 0.1 * (1.3 + 1.3**3)
    assert abs(Z[1, 1] - p1_wrong) > 1e-2


def test_stormer_verlet_one_hand_step():
    sys_ = nonlinear_oscillator()
    dt, x, p = 0.1, 1.3, 1.0
    force = lambda x: x + x**3  # noqa: E731
    p_half = p - dt / 2 * force(x)
    x_new = x + dt * p_half
    p_new = p_half - dt / 2 * force(x_new)
    t, Z = stormer_verlet(sys_, [x, p], 0.0, dt, 1)
    np.testing.assert_allclose(Z[1], [x_new, p_new], rtol=1e-14, atol=0)


def test_yoshida_weights():
    w1, w0 = integ._YOSHIDA_W1, integ._YOSHIDA_W0
    assert 2 * w1 + w0 == pytest.approx(1.0, abs=1e-15)
    assert 2 * w1**3 + w0**3 == pytest.approx(0.0, abs=1e-14)


# ------------------------------------------------------------------------ convergence order
@pytest.mark.parametrize(
    "method, order, n_coarse",
    [("symplectic_euler", 1, 1000), ("stormer_verlet", 2, 100), ("yoshida4", 4, 50)],
)
def test_convergence_order_harmonic(method, order, n_coarse):
    ho = harmonic_oscillator()
    z0 = (1.0, 0.0)
    errs = []
    for n in (n_coarse, 2 * n_coarse):
        t, Z = integrate(method, ho, z0, 0.0, 10.0, n)
        errs.append(np.max(np.abs(Z - harmonic_exact(t, z0))))
    observed = math.log2(errs[0] / errs[1])
    assert abs(observed - order) < 0.3, (method, errs, observed)


# ------------------------------------------------------------------ long-time energy behaviour
@pytest.mark.parametrize(
    "method, bound", [("symplectic_euler", 0.06), ("stormer_verlet", 3e-3), ("yoshida4", 1e-5)]
)
def test_energy_bounded_over_1000_periods(method, bound):
    ho = harmonic_oscillator()
    per_period = 64
    n_periods = 1000
    n = per_period * n_periods
    t, Z = integrate(method, ho, (1.0, 0.0), 0.0, 2 * math.pi * n_periods, n)
    assert Z.shape == (n + 1, 2)
    E = 0.5 * (Z[:, 0] ** 2 + Z[:, 1] ** 2)
    rel = np.abs(E - 0.5) / 0.5
    first = rel[: 10 * per_period + 1].max()
    last = rel[-(10 * per_period + 1) :].max()
    assert first > 0  # the method is not exact, so the test can see a change
    assert last <= 1.05 * first, (first, last)  # no secular drift
    assert rel.max() <= bound


def test_henon_heiles_integrators_d2():
    """d = 2: the q/p split is right, and yoshida4 converges to the reference."""
    hh = henon_heiles()
    T, n = 6 * math.pi, 3000
    t, Zy = yoshida4(hh, None, 0.0, T, n)
    Zref = reference_solution(hh, None, t)
    assert np.max(np.abs(Zy - Zref)) < 1e-8
    E0 = float(_energy64(hh, hh.z0[None])[0])
    assert E0 == pytest.approx(0.12825, abs=1e-12)
    for m in METHODS:
        _, Z = integrate(m, hh, None, 0.0, T, 1000)
        drift = np.max(np.abs(_energy64(hh, Z) - E0)) / E0
        assert drift < 0.05, (m, drift)


# ------------------------------------------------------------------------- reference solver
def test_reference_matches_harmonic_exact():
    ho = harmonic_oscillator()
    t = np.linspace(0.0, 20 * math.pi, 2001)
    z0 = (1.0, 0.0)
    Z = reference_solution(ho, z0, t)
    assert Z.dtype == np.float64 and Z.shape == (2001, 2)
    assert np.max(np.abs(Z - harmonic_exact(t, z0))) < 1e-10


def test_reference_conserves_henon_heiles_energy():
    hh = henon_heiles()
    t = np.linspace(0.0, 24 * math.pi, 1001)
    Z = reference_solution(hh, None, t)
    E = _energy64(hh, Z)
    assert E.dtype == np.float64
    assert E[0] == pytest.approx(0.12825, abs=1e-14)
    assert np.max(np.abs(E - E[0])) < 1e-10


def test_reference_nonzero_start_time():
    ho = harmonic_oscillator()
    t = np.linspace(1.0, 5.0, 41)
    z0 = harmonic_exact(np.array([1.0]))[0]
    Z = reference_solution(ho, z0, t)
    assert np.max(np.abs(Z - harmonic_exact(t))) < 1e-10


def test_reference_description():
    assert "DOP853" in REFERENCE_DESCRIPTION and "1e-12" in REFERENCE_DESCRIPTION


@pytest.mark.parametrize(
    "t_eval", [[0.0, 2.0, 1.0], [0.0, 1.0, 1.0], [0.0, float("nan"), 2.0], [0.0, float("inf")], [], [[0.0, 1.0]]]
)
def test_reference_rejects_bad_t_eval(t_eval):
    with pytest.raises(ConfigError) as ei:
        reference_solution(harmonic_oscillator(), None, t_eval)
    assert "t_eval" in _one_line(ei)


def test_reference_solver_failure_is_one_line():
    # H = -q⁴/4 ... blows up in finite time from q=1 (q' = p, p' = q³): the solver cannot finish.
    blowup = HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 - q[0] ** 4 / 4, 1, name="blowup", separable=True)
    with pytest.raises(AtlasError) as ei:
        reference_solution(blowup, [1.0, 1.0], np.linspace(0.0, 10.0, 11))
    msg = _one_line(ei)
    assert "DOP853" in msg and "blowup" in msg


# -------------------------------------------------------------------- non-separable systems
def _quartic_rotor():
    # H = (q² + p²)² / 4 is not separable; its flow is a rotation at angular speed ω = q0² + p0².
    return HamiltonianSystem(
        lambda q, p: (q[0] ** 2 + p[0] ** 2) ** 2 / 4, 1, name="rotor", separable=False, z0=[1.0, 0.5]
    )


@pytest.mark.parametrize("method", METHODS)
def test_non_separable_refused(method):
    with pytest.raises(SystemError_) as ei:
        integrate(method, _quartic_rotor(), None, 0.0, 1.0, 10)
    msg = _one_line(ei)
    assert "separable" in msg and "rotor" in msg


def test_reference_works_on_non_separable():
    rotor = _quartic_rotor()
    t = np.linspace(0.0, 10.0, 501)
    Z = reference_solution(rotor, None, t)
    omega = 1.0**2 + 0.5**2
    exact = harmonic_exact(omega * t, (1.0, 0.5))  # q0 cos ωt + p0 sin ωt, p0 cos ωt − q0 sin ωt
    assert np.max(np.abs(Z - exact)) < 1e-9


# ---------------------------------------------------------------------- user-defined pendulum
def test_user_pendulum_end_to_end():
    pend = HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 - jnp.cos(q[0]), 1, separable=True, z0=[1.0, 0.0])
    T, n = 20.0, 2000
    t = np.linspace(0.0, T, n + 1)
    Zref = reference_solution(pend, None, t)
    E0 = -math.cos(1.0)
    Eref = _energy64(pend, Zref)
    assert np.max(np.abs(Eref - E0)) < 1e-10
    # Small-angle-ish check that this really is a pendulum: it swings back past zero to -1.
    assert Zref[:, 0].min() == pytest.approx(-1.0, abs=1e-6)

    ty, Zy = yoshida4(pend, None, 0.0, T, n)
    np.testing.assert_array_equal(ty, t)
    assert np.max(np.abs(Zy - Zref)) < 1e-6
    assert np.max(np.abs(_energy64(pend, Zy) - E0)) < 1e-8

    _, Zv = stormer_verlet(pend, None, 0.0, T, 20 * n)
    assert np.max(np.abs(Zv[::20] - Zref)) < 1e-5
    _, Zs = symplectic_euler(pend, None, 0.0, T, 20 * n)
    assert np.max(np.abs(Zs[::20] - Zref)) < 1e-2
    for Z, tol in ((Zv, 1e-5), (Zs, 1e-3)):
        assert np.max(np.abs(_energy64(pend, Z) - E0)) < tol


# ------------------------------------------------------------------------ precision & cache
@pytest.mark.parametrize("method", METHODS)
def test_float64_regardless_of_global_precision(method):
    sys_ = nonlinear_oscillator()
    with jax.enable_x64(False):
        assert jnp.zeros(1).dtype == jnp.float32
        t32, Z32 = integrate(method, sys_, None, 0.0, 5.0, 500)
    with jax.enable_x64(True):
        t64, Z64 = integrate(method, sys_, None, 0.0, 5.0, 500)
    assert t32.dtype == np.float64 and Z32.dtype == np.float64
    np.testing.assert_array_equal(Z32, Z64)
    # Agrees with a plain-NumPy float64 loop to round-off (float32 would be off by ~1e-6).
    np.testing.assert_allclose(Z32, _numpy_oscillator(method, sys_.z0, 5.0 / 500, 500), rtol=0, atol=1e-12)


def _numpy_oscillator(method, z0, dt, n):
    """The three methods for H = p²/2 + x²/2 + x⁴/4, in float64 NumPy, step by step."""
    force = lambda x: x + x**3  # noqa: E731

    def verlet(x, p, h):
        p = p - h / 2 * force(x)
        x = x + h * p
        return x, p - h / 2 * force(x)

    x, p = float(z0[0]), float(z0[1])
    out = [(x, p)]
    for _ in range(n):
        if method == "symplectic_euler":
            x = x + dt * p
            p = p - dt * force(x)
        elif method == "stormer_verlet":
            x, p = verlet(x, p, dt)
        else:
            for w in (integ._YOSHIDA_W1, integ._YOSHIDA_W0, integ._YOSHIDA_W1):
                x, p = verlet(x, p, w * dt)
        out.append((x, p))
    return np.array(out)


def test_reference_float64_regardless_of_global_precision():
    hh = henon_heiles()
    t = np.linspace(0.0, 2.0, 21)
    with jax.enable_x64(False):
        Z32 = reference_solution(hh, None, t)
    with jax.enable_x64(True):
        Z64 = reference_solution(hh, None, t)
    assert Z32.dtype == np.float64
    np.testing.assert_array_equal(Z32, Z64)
    E = _energy64(hh, Z32)
    assert np.max(np.abs(E - E[0])) < 1e-10  # float32 evaluation would give ~1e-8


def test_compiled_stepper_cached():
    sys_ = nonlinear_oscillator()
    integ._compiled_stepper.cache_clear()
    stormer_verlet(sys_, None, 0.0, 1.0, 37)
    fn = integ._compiled_stepper(sys_, "stormer_verlet", 37)
    before = fn._cache_size()
    info0 = integ._compiled_stepper.cache_info()
    # Different interval and initial state, same system and step count: no new compile.
    stormer_verlet(sys_, [0.5, -0.2], 2.0, 7.0, 37)
    with jax.enable_x64(False):
        stormer_verlet(sys_, [0.1, 0.1], 0.0, 3.0, 37)
    info1 = integ._compiled_stepper.cache_info()
    assert info1.misses == info0.misses
    assert info1.hits == info0.hits + 2
    assert fn._cache_size() == before == 1


# --------------------------------------------------------------------------- argument checks
@pytest.mark.parametrize("n_steps", [0, -3, 2.5, True, "10", None])
def test_bad_n_steps(n_steps):
    with pytest.raises(ConfigError) as ei:
        symplectic_euler(nonlinear_oscillator(), None, 0.0, 1.0, n_steps)
    assert "n_steps" in _one_line(ei)


@pytest.mark.parametrize("t0, T", [(1.0, 1.0), (2.0, 1.0), (0.0, float("nan")), (0.0, "x")])
def test_bad_interval(t0, T):
    with pytest.raises(ConfigError) as ei:
        yoshida4(nonlinear_oscillator(), None, t0, T, 10)
    msg = _one_line(ei)
    assert "T" in msg


def test_numpy_int_steps_and_bad_method():
    t, Z = integrate("stormer_verlet", nonlinear_oscillator(), None, 0.0, 1.0, np.int64(4))
    assert Z.shape == (5, 2) and t[-1] == 1.0
    with pytest.raises(ConfigError) as ei:
        integrate("rk4", nonlinear_oscillator(), None, 0.0, 1.0, 4)
    assert "rk4" in _one_line(ei)


def test_bad_z0():
    with pytest.raises(SystemError_) as ei:
        yoshida4(henon_heiles(), [1.0, 2.0], 0.0, 1.0, 4)
    _one_line(ei)


def test_reference_stops_with_one_line_error_when_the_field_becomes_non_finite():
    """sqrt(q) has no gradient once q < 0: the solver must stop, not shrink its step for ever."""
    from atlasnn.errors import AtlasError
    from atlasnn.systems import expression_system

    system = expression_system("p**2/2 + sqrt(q)", coordinates=["q"], momenta=["p"], z0=[1.0, -1.0])
    with pytest.raises(AtlasError) as info:
        reference_solution(system, system.z0, np.linspace(0.0, 10.0, 50))
    assert "not finite" in str(info.value) and "\n" not in str(info.value)

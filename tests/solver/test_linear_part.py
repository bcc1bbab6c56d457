"""A declared linear part H = ½ zᵀ S z + N(z): its solves against dense ones, the PDE built-ins
against their exact solutions and invariants, and one-line refusals."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import atlasnn
from atlasnn.errors import SystemError_
from atlasnn.solver import GaussCollocation
from atlasnn.systems import (DenseLinearPart, FourierLinearPart, HamiltonianSystem, fourier_wavenumbers, fput, nls,
                             nls_mass, nls_soliton, sine_gordon, sine_gordon_breather)


@pytest.fixture(autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


def _j(n):
    d = n // 2
    return np.block([[np.zeros((d, d)), np.eye(d)], [-np.eye(d), np.zeros((d, d))]])


@pytest.mark.long
@pytest.mark.parametrize("kind", ["fourier", "dense"])
def test_the_shifted_solves_match_a_dense_solve(kind):
    rng = np.random.default_rng(3)
    k = fourier_wavenumbers(16, 7.0)
    part = FourierLinearPart(0.5 * k ** 2, 1.0 + k ** 2)
    if kind == "dense":
        part = DenseLinearPart(part.matrix())
    S = part.matrix()
    shifts = np.array([0.4 + 0.9j, 2.0 + 0.1j, 0.05 + 0.0j])
    r = rng.normal(size=(3, 32)) + 1j * rng.normal(size=(3, 32))
    x = np.asarray(part.factor(jnp.asarray(shifts))(jnp.asarray(r)))
    for c, xj, rj in zip(shifts, x, r):
        np.testing.assert_allclose(np.linalg.solve(np.eye(32) - c * _j(32) @ S, rj), xj, rtol=0, atol=1e-12)
    z = rng.normal(size=32)
    np.testing.assert_allclose(np.asarray(part.field(jnp.asarray(z))), _j(32) @ S @ z, atol=1e-12)


@pytest.mark.long
@pytest.mark.parametrize("points", [32, 31])  # the real FFT's weights differ for odd M
def test_the_nls_field_is_its_linear_part_plus_the_cubic_term(points):
    system = nls(points=points, length=20.0)
    z = np.random.default_rng(0).normal(size=2 * points)
    q, p = z[:points], z[points:]
    cubic = np.concatenate([-(q * q + p * p) * p, (q * q + p * p) * q])
    field = np.asarray(system.vector_field(jnp.asarray(z)[None])[0])
    np.testing.assert_allclose(field, np.asarray(system.linear_part.field(jnp.asarray(z))) + cubic, atol=1e-12)


@pytest.mark.long
def test_the_nls_soliton_with_its_invariants_and_without_the_linear_part():
    system = nls(points=128, length=40.0)
    T = 1.0
    sol = atlasnn.solve(system, system.z0, (0.0, T), solver=GaussCollocation(), rtol=1e-10, atol=1e-10)
    exact = nls_soliton(T, 128, 40.0)
    assert np.max(np.abs(sol(T) - exact)) < 1e-6  # the grid's own error (its top mode ~1e-7)
    assert sol.info["newton_windows"] >= sol.info["windows"]  # every window tried with the linear part
    ends = sol(np.linspace(0.0, T, 5))
    mass = nls_mass(ends)
    assert np.max(np.abs(mass / mass[0] - 1.0)) < 1e-14  # a quadratic invariant: exact to round-off
    energy = system.energy64(sol(np.array([0.0, T])))
    assert abs(energy[1] / energy[0] - 1.0) < 1e-12
    plain = atlasnn.solve(dataclasses.replace(system, linear_part=None, nonlinear_flow=None), system.z0, (0.0, T), rtol=1e-10, atol=1e-10)
    # two ways of solving one set of equations: the same solution to within their tolerance
    assert np.max(np.abs(plain(T) - sol(T))) < 1e-8


def test_the_sine_gordon_breather():
    system = sine_gordon(points=128, length=40.0, omega=0.5)
    T = 2.0
    sol = atlasnn.solve(system, system.z0, (0.0, T), solver=GaussCollocation(), rtol=1e-10, atol=1e-10)
    assert np.max(np.abs(sol(T) - sine_gordon_breather(T, 128, 40.0, 0.5))) < 1e-6
    energy = system.energy64(sol(np.array([0.0, T])))
    assert abs(energy[1] / energy[0] - 1.0) < 1e-12


def test_a_linear_part_that_does_not_fit_is_refused_in_one_line():
    h = lambda q, p: jnp.sum(p * p + q * q) / 2  # noqa: E731
    with pytest.raises(SystemError_, match="linear_part has 4 components, the state 6"):
        HamiltonianSystem(h, 3, linear_part=DenseLinearPart(np.eye(4)))
    with pytest.raises(SystemError_, match="symmetric"):
        DenseLinearPart(np.array([[1.0, 2.0], [0.0, 1.0]]))
    with pytest.raises(SystemError_, match="even"):
        FourierLinearPart(np.arange(8.0), np.ones(8))
    with pytest.raises(SystemError_, match="one length"):
        FourierLinearPart(np.ones(8), np.ones(6))
    with pytest.raises(SystemError_, match="must be a LinearPart"):
        HamiltonianSystem(h, 2, linear_part=np.eye(4))
    with pytest.raises(SystemError_, match="must be real"):
        FourierLinearPart(1j * fourier_wavenumbers(8, 1.0), np.ones(8))
    with pytest.raises(SystemError_, match="1 dimension"):
        FourierLinearPart(np.ones((2, 4)), np.ones(8))
    with pytest.raises(SystemError_, match="finite numbers"):
        DenseLinearPart(np.zeros((0, 0)))
    for bad in ("many", "16"):
        with pytest.raises(SystemError_, match="points must be an integer"):
            nls(points=bad)
    with pytest.raises(SystemError_, match="length = 1e-300 is too short for 512 grid points"):
        nls(length=1e-300)
    with pytest.raises(SystemError_, match="length must be a positive number"):
        nls(length="64")
    with pytest.raises(SystemError_, match="length must be a positive number"):
        nls_soliton(0.0, 64, 0.0)
    for settings, message in ((dict(particles=float("inf")), "particles must be an integer"),
                              (dict(particles="8"), "particles must be an integer"),
                              (dict(alpha="x"), "alpha must be a finite number"),
                              (dict(beta=float("nan")), "beta must be a finite number")):
        with pytest.raises(SystemError_, match=message):
            fput(**settings)


@pytest.mark.long
def test_a_stiff_pair_solved_with_a_dense_linear_part_and_differentiated():
    # a fast oscillator (ω = 300) weakly coupled to a slow one: S is H's quadratic part
    omega = 300.0

    def h(q, p):
        return (jnp.sum(p * p) + omega ** 2 * q[0] ** 2 + q[1] ** 2) / 2 + 0.1 * q[0] ** 2 * q[1] ** 2

    S = np.diag([omega ** 2, 1.0, 1.0, 1.0])
    stiff = HamiltonianSystem(h, 2, z0=[1e-3, 1.0, 0.0, 0.0], linear_part=DenseLinearPart(S))
    T = 3.0
    sol = atlasnn.solve(stiff, stiff.z0, (0.0, T), rtol=1e-10, atol=1e-12)
    # the same equations by the solver's own iterations (fixed-point, dense Newton) on short windows
    plain = atlasnn.solve(dataclasses.replace(stiff, linear_part=None), stiff.z0, (0.0, T), rtol=1e-12, atol=1e-14)
    assert np.max(np.abs(sol(T) - plain(T))) < 1e-8
    energy = stiff.energy64(sol(np.array([0.0, T])))
    assert abs(energy[1] / energy[0] - 1.0) < 1e-11
    # the gradient through the same windows (h fixed) against central differences of the host solve
    fixed = GaussCollocation(h=0.05, stages=6)
    grad = jax.jit(jax.grad(lambda z0: atlasnn.solve(stiff, z0, (0.0, 1.0), solver=fixed)(1.0)[1]))(
        jnp.asarray(stiff.z0))
    eps, direction = 1e-6, np.array([0.3, -0.2, 0.5, 0.1])

    def end(z0):
        return atlasnn.solve(stiff, z0, (0.0, 1.0), solver=fixed)(1.0)[1]

    central = (end(stiff.z0 + eps * direction) - end(stiff.z0 - eps * direction)) / (2 * eps)
    assert float(np.asarray(grad) @ direction) == pytest.approx(central, rel=1e-7)


@pytest.mark.long
def test_the_gradient_through_an_nls_grid_by_the_preconditioned_tangent_solve():
    # 128 points, s = 6: 1 536 unknowns a window, above the dense fallback's limit, so the transposed
    # tangent solve must converge preconditioned by the linear part (else the gradient is NaN)
    system = nls(points=128, length=32.0)
    fixed = GaussCollocation(h=0.125, stages=6)
    T = 0.25
    w = np.random.default_rng(0).normal(size=system.state_dim)

    def functional(z0):
        return jnp.dot(jnp.asarray(w), atlasnn.solve(system, z0, (0.0, T), solver=fixed)(T))

    value, grad = jax.jit(jax.value_and_grad(functional))(jnp.asarray(system.z0))
    host = w @ atlasnn.solve(system, system.z0, (0.0, T), solver=fixed)(T)
    assert float(value) == pytest.approx(host, rel=1e-12)
    direction = np.random.default_rng(1).normal(size=system.state_dim)
    eps = 1e-5
    plus, minus = (w @ atlasnn.solve(system, system.z0 + sign * eps * direction, (0.0, T), solver=fixed)(T)
                   for sign in (1, -1))
    assert np.all(np.isfinite(np.asarray(grad)))
    assert float(np.asarray(grad) @ direction) == pytest.approx((plus - minus) / (2 * eps), rel=1e-8)


def test_the_fput_modes_sum_to_h_for_the_linear_chain():
    from atlasnn.systems import fput, fput_modes, with_params

    linear = fput(particles=8, alpha=0.0)
    z = np.random.default_rng(1).normal(size=16)
    assert np.sum(fput_modes(z, 8)) == pytest.approx(float(linear.energy64(z)), rel=1e-13)
    system = with_params(fput(particles=8, alpha=0.25), alpha=0.5)
    assert system.dim == 8 and system.params["alpha"] == 0.5
    start = fput_modes(system.z0, 8)
    assert start[0] > 0 and np.all(start[1:] < 1e-25 * start[0])  # Fermi's start: mode 1 alone


def _inexact(system):
    part = system.linear_part
    return dataclasses.replace(system, linear_part=FourierLinearPart(2 * part.q_symbol, 2 * part.p_symbol),
                               nonlinear_flow=None)


@pytest.mark.long
def test_the_gradient_with_an_inexact_linear_part_is_right_or_raises(monkeypatch):
    # a declared S twice H's own: the forward march converges (on shorter windows); the transposed tangent
    # solve preconditioned by that S does not contract, and 4 096 unknowns are past the dense fallback:
    # restarted GMRES gives the gradient; where it cannot, the gradient raises in one line, never NaN
    from atlasnn.solver import _gauss_step

    system = _inexact(nls(points=128, length=32.0))
    solver, T = GaussCollocation(), 0.25  # 16 stages: 4 096 unknowns a window
    w = np.random.default_rng(0).normal(size=system.state_dim)

    def gradient(system):
        return jax.grad(lambda z0: jnp.dot(jnp.asarray(w), atlasnn.solve(system, z0, (0.0, T), solver=solver)(T)))(
            jnp.asarray(system.z0))

    got = np.asarray(gradient(system))
    direction, eps = np.random.default_rng(1).normal(size=system.state_dim), 1e-5
    plus, minus = (w @ atlasnn.solve(system, system.z0 + sign * eps * direction, (0.0, T), solver=solver)(T)
                   for sign in (1, -1))
    assert np.all(np.isfinite(got))
    assert float(got @ direction) == pytest.approx((plus - minus) / (2 * eps), rel=1e-7)
    monkeypatch.setattr(_gauss_step, "TANGENT_RESIDUAL", -1.0)  # no Krylov solve accepted
    with pytest.raises(Exception, match="derivative of a window's stage equations did not converge"):
        np.asarray(gradient(dataclasses.replace(system, name="retraced")))

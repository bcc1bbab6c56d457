"""Tests of Hamiltonian systems: the built-in vector fields, energies, validation, user systems."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import AtlasError, SystemError_
from atlasnn.systems import (
    BUILTIN_SYSTEMS,
    HamiltonianSystem,
    builtin_system,
    harmonic_exact,
    harmonic_oscillator,
    henon_heiles,
    nonlinear_oscillator,
    system_from_spec,
)

LAMS = [0.0, 0.5, 1.0, 2.3]


# jit each evaluation: one compilation is much faster than eager op-by-op dispatch
def vf(system, Z):
    return jax.jit(system.vector_field)(jnp.asarray(Z))


def en(system, Z):
    return jax.jit(system.energy)(jnp.asarray(Z))


def _states(n: int, dim: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.5, 1.5, size=(n, 2 * dim))


# ----------------------------------------------------------------- equations of motion
@pytest.mark.parametrize("lam", LAMS)
def test_oscillator_vector_field_is_papers(lam):
    Z = _states(64, 1, seed=int(lam * 10))
    x, p = Z[:, 0], Z[:, 1]
    want = np.stack([p, -x - lam * x**3], axis=-1)  # ẋ = p, ṗ = −x − λx³
    with jax.enable_x64(True):
        sys = nonlinear_oscillator(lam=lam)
        got = np.asarray(vf(sys, jnp.asarray(Z)))
        H = np.asarray(en(sys, jnp.asarray(Z)))
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(H, p**2 / 2 + x**2 / 2 + lam * x**4 / 4, rtol=1e-13)


@pytest.mark.parametrize("lam", LAMS)
def test_henon_heiles_vector_field_is_papers(lam):
    Z = _states(64, 2, seed=100 + int(lam * 10))
    x, y, px, py = Z.T
    want = np.stack(
        [px, py, -x - 2 * lam * x * y, -y - lam * (x**2 - y**2)], axis=-1
    )
    with jax.enable_x64(True):
        sys = henon_heiles(lam=lam)
        got = np.asarray(vf(sys, jnp.asarray(Z)))
        H = np.asarray(en(sys, jnp.asarray(Z)))
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(
        H, (px**2 + py**2) / 2 + (x**2 + y**2) / 2 + lam * (x**2 * y - y**3 / 3), rtol=1e-13, atol=1e-15
    )


def test_vector_field_float32_default():
    sys = henon_heiles()
    Z = _states(16, 2, seed=7).astype(np.float32)
    got = vf(sys, jnp.asarray(Z))
    assert got.dtype == jnp.float32
    x, y, px, py = Z.astype(np.float64).T
    want = np.stack([px, py, -x - 2 * x * y, -y - (x**2 - y**2)], axis=-1)
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-5, atol=1e-6)


def test_harmonic_vector_field_and_exact_solution():
    omega = 1.7
    with jax.enable_x64(True):
        sys = harmonic_oscillator(omega=omega, z0=(0.4, -0.9))
        t = np.linspace(0, 5, 11)
        Z = harmonic_exact(t, sys.z0, omega)
        np.testing.assert_allclose(Z[0], [0.4, -0.9])
        # the exact solution satisfies ż = J∇H(z): compare with its time derivative
        dZ = np.stack([Z[:, 1], -(omega**2) * Z[:, 0]], axis=-1)
        np.testing.assert_allclose(np.asarray(vf(sys, jnp.asarray(Z))), dZ, rtol=1e-13, atol=1e-13)
        # and conserves H
        H = np.asarray(en(sys, jnp.asarray(Z)))
        np.testing.assert_allclose(H, H[0], rtol=1e-13)


def test_grad_and_partial_derivatives():
    with jax.enable_x64(True):
        sys = henon_heiles(lam=1.0)
        z = jnp.asarray([0.2, -0.1, 0.5, 0.7])
        g = np.asarray(jax.jit(sys.grad)(z))
        x, y, px, py = np.asarray(z)
        np.testing.assert_allclose(g, [x + 2 * x * y, y + x**2 - y**2, px, py], rtol=1e-14)
        np.testing.assert_allclose(np.asarray(jax.jit(sys.dH_dq)(z[:2], z[2:])), g[:2], rtol=1e-14)
        np.testing.assert_allclose(np.asarray(jax.jit(sys.dH_dp)(z[:2], z[2:])), g[2:], rtol=1e-14)


def test_energy_shapes():
    sys = henon_heiles()
    Z = jnp.zeros((5, 3, 4))
    assert en(sys, Z).shape == (5, 3)
    assert vf(sys, Z).shape == (5, 3, 4)
    assert en(sys, jnp.zeros(4)).shape == ()
    q, p = sys.split(jnp.arange(8.0).reshape(2, 4))
    np.testing.assert_array_equal(np.asarray(q), [[0, 1], [4, 5]])
    np.testing.assert_array_equal(np.asarray(p), [[2, 3], [6, 7]])


def test_henon_heiles_paper_energy():
    sys = henon_heiles()
    np.testing.assert_allclose(sys.z0, [0.3, -0.3, 0.3, 0.15])
    with jax.enable_x64(True):
        E = float(en(sys, jnp.asarray(sys.z0)))
    assert E == pytest.approx(0.12825, abs=1e-12)
    # float32 default as well
    assert float(en(sys, jnp.asarray(sys.z0, dtype=jnp.float32))) == pytest.approx(0.12825, rel=1e-6)


def test_oscillator_paper_defaults():
    sys = nonlinear_oscillator()
    np.testing.assert_allclose(sys.z0, [1.3, 1.0])
    assert sys.params == {"lam": 1.0}
    assert sys.dim == 1 and sys.state_dim == 2
    assert sys.state_names == ("x", "p")
    assert sys.separable
    assert henon_heiles().state_names == ("x", "y", "px", "py")


# ------------------------------------------------------------------------ by name / spec
@pytest.mark.parametrize("name", sorted(BUILTIN_SYSTEMS))
def test_builtin_by_name_and_spec_round_trip(name):
    sys = builtin_system(name)
    again = system_from_spec(sys.spec)
    assert again.name == sys.name and again.dim == sys.dim
    Z = jnp.asarray(_states(8, sys.dim, seed=3), dtype=jnp.float32)
    np.testing.assert_array_equal(np.asarray(en(again, Z)), np.asarray(en(sys, Z)))
    d = sys.describe()
    assert d["name"] == sys.name and d["dim"] == sys.dim and d["separable"] is sys.separable
    assert d["z0"] == [float(v) for v in sys.z0]


def test_builtin_params_and_hyphen_name():
    sys = builtin_system("henon-heiles", lam=0.5)
    assert sys.params == {"lam": 0.5}
    with jax.enable_x64(True):
        z = jnp.asarray([0.0, 1.0, 0.0, 0.0])
        # H = y²/2 − lam·y³/3 at y = 1
        assert float(en(sys, z)) == pytest.approx(0.5 - 0.5 / 3, abs=1e-14)


@pytest.mark.parametrize(
    "call",
    [
        lambda: builtin_system("duffing"),
        lambda: builtin_system("henon_heiles", mu=2.0),
        lambda: system_from_spec({"kind": "pickle"}),
    ],
)
def test_bad_names(call):
    with pytest.raises(SystemError_) as exc:
        call()
    assert "\n" not in str(exc.value)


def _h1(q, p):
    return p[0] ** 2 / 2 + q[0] ** 2 / 2


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(dim=0),
        dict(dim=-2),
        dict(dim=1.5),
        dict(dim=True),
        dict(dim="1"),
        dict(dim=1, q_names=("x", "y")),
        dict(dim=1, q_names=("x",), p_names=("x",)),
        dict(dim=1, z0=[1.0]),
        dict(dim=1, z0=[1.0, 2.0, 3.0]),
        dict(dim=1, z0=[1.0, float("nan")]),
        dict(dim=1, z0=[1.0, float("inf")]),
        dict(dim=1, z0="ab"),
        dict(dim=1, z0=[[1.0], ["x"]]),
    ],
)
def test_bad_system_definitions(kwargs):
    with pytest.raises(SystemError_) as exc:
        HamiltonianSystem(_h1, **kwargs)
    assert "\n" not in str(exc.value)
    assert isinstance(exc.value, AtlasError) and isinstance(exc.value, ValueError)


def test_not_callable_hamiltonian():
    with pytest.raises(SystemError_):
        HamiltonianSystem("p**2/2", 1)


def test_initial_state_rules():
    sys = HamiltonianSystem(_h1, 1)
    with pytest.raises(SystemError_):
        sys.initial_state()
    np.testing.assert_array_equal(sys.initial_state([0.5, 0.25]), [0.5, 0.25])
    with pytest.raises(SystemError_):
        sys.initial_state([0.5])
    with pytest.raises(SystemError_):
        henon_heiles().initial_state([0.1, 0.2])
    np.testing.assert_array_equal(henon_heiles().initial_state(), [0.3, -0.3, 0.3, 0.15])


def test_require_separable():
    sys = HamiltonianSystem(lambda q, p: (p[0] * q[0]) ** 2, 1, name="mixed")
    with pytest.raises(SystemError_) as exc:
        sys.require_separable("symplectic Euler")
    assert "mixed" in str(exc.value)
    harmonic_oscillator().require_separable("symplectic Euler")  # no error


def test_default_names():
    assert HamiltonianSystem(_h1, 1).state_names == ("q", "p")
    three = HamiltonianSystem(lambda q, p: jnp.sum(p**2 + q**2) / 2, 3)
    assert three.state_names == ("q1", "q2", "q3", "p1", "p2", "p3")
    assert three.state_dim == 6


# --------------------------------------------------------------------- user-defined H
def test_user_defined_pendulum_needs_no_package_change():
    from atlasnn.training import physics_loss
    from atlasnn.nn import make_model

    def pendulum(q, p):
        return p[0] ** 2 / 2 - jnp.cos(q[0])

    sys = HamiltonianSystem(pendulum, 1, name="pendulum", q_names=("theta",), z0=(1.0, 0.0), separable=True)
    assert sys.spec is None and sys.state_names == ("theta", "p")
    Z = _states(32, 1, seed=11)
    with jax.enable_x64(True):
        field = np.asarray(vf(sys, jnp.asarray(Z)))
        np.testing.assert_allclose(field, np.stack([Z[:, 1], -np.sin(Z[:, 0])], axis=-1), rtol=1e-13, atol=1e-14)
        assert float(en(sys, jnp.asarray(sys.z0))) == pytest.approx(-np.cos(1.0), abs=1e-15)
    # the rest of the package takes it as it is: the physics loss evaluates to a finite number
    model = make_model(sys.z0, scaling="rational_exp", width=16, depth=2, seed=0)
    t = jnp.linspace(0.0, 2.0, 9)
    loss, (res, pen) = jax.jit(physics_loss, static_argnums=1)(model, sys, t, en(sys, model.z0), 1.0)
    assert np.isfinite(float(loss)) and float(loss) > 0
    assert float(loss) == pytest.approx(float(res) + float(pen), rel=1e-6)


def test_user_defined_non_separable_two_dof():
    # H = (p1² + p2²)/2 + q1 q2 p1 (not separable), any d works
    def H(q, p):
        return jnp.sum(p**2) / 2 + q[0] * q[1] * p[0]

    sys = HamiltonianSystem(H, 2)
    with jax.enable_x64(True):
        z = jnp.asarray([0.3, -0.7, 1.1, 0.4])
        q1, q2, p1, p2 = np.asarray(z)
        want = [p1 + q1 * q2, p2, -q2 * p1, -q1 * p1]
        np.testing.assert_allclose(np.asarray(vf(sys, z)), want, rtol=1e-14)

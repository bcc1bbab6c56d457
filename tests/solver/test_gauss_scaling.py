"""The Gauss collocation at size: the decoupled simplified Newton iteration (one complex system of
size n per eigenvalue pair of the Gauss matrix) against the dense one of size s·n it replaces, the
work of a window linear in the dimension (iterations per window that do not grow with it, no
n × n array in the fixed-point march), and the window lengths held where the fixed-point
iteration contracts."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn import HamiltonianSystem, solve, solve_batch
from atlasnn.solutions import gauss_tableau
from atlasnn.solver import GaussCollocation, _gauss
from atlasnn.solver._gauss_march import NEWTON_LATER
from atlasnn.solver._gauss_step import _dense_factor, _newton, small_matmul, tableau_arrays


def stiff_chain(n: int = 3) -> HamiltonianSystem:
    """Oscillators of frequencies 1, 40, 1600 … coupled by a quartic term: stiff for the
    fixed-point iteration at any step that resolves the slow one."""
    omega = jnp.asarray(40.0 ** np.arange(n))

    def hamiltonian(q, p):
        return jnp.sum(p ** 2 + (omega * q) ** 2) / 2 + 0.1 * jnp.sum(q) ** 4

    return HamiltonianSystem(hamiltonian, n, name="stiff-chain", z0=np.r_[np.ones(n), np.zeros(n)])


def fput(n: int) -> HamiltonianSystem:  # noqa: D103
    def hamiltonian(q, p):
        dq = jnp.diff(jnp.concatenate([jnp.zeros(1, q.dtype), q, jnp.zeros(1, q.dtype)]))
        return jnp.sum(p ** 2) / 2 + jnp.sum(dq ** 2 / 2 + dq ** 4 / 4)

    z0 = np.concatenate([np.zeros(n), np.sin(np.pi * np.arange(1, n + 1) / (n + 1))])
    return HamiltonianSystem(hamiltonian, n, name=f"fput-{n}", z0=z0, separable=True)


def dense_newton(field, a, tab, z, hb, L, iterations=60):
    """The simplified Newton iteration with the full (s n × s n) matrix I − (diag(hb) μ) ⊗ A."""
    s, n = L.shape
    matrix = np.eye(s * n) - np.kron(np.diag(hb) @ tab["mu"], a)
    stages = jax.jit(lambda L: field(z + small_matmul(tab["mu"], L)))
    for _ in range(iterations):
        g = L - hb[:, None] * np.asarray(stages(jnp.asarray(L)))
        L = L + np.linalg.solve(matrix, -g.reshape(-1)).reshape(s, n)
    return L


@pytest.mark.long
# s = 1 and 4 add nothing s = 3 (a real eigenvalue and a pair) and s = 12 (pairs only) do not check:
# out of CI for its time (20 s each), run with -m slow
@pytest.mark.parametrize("stages", [pytest.param(1, marks=pytest.mark.slow), 3, pytest.param(4, marks=pytest.mark.slow),
                                    12])
def test_the_decoupled_newton_iteration_equals_the_dense_one(stages):
    """On a stiff system at a step 100× past the fixed-point iteration's reach, the decoupled
    iteration (odd s: a real eigenvalue among the pairs) converges to the dense one's stages to
    round-off."""
    with jax.enable_x64(True):
        system = stiff_chain()
        tab = tableau_arrays(gauss_tableau(stages))
        z = jnp.asarray(system.z0)
        h = 0.05  # h·ω = 80 for the fastest oscillator
        hb = h * tab["b"]
        field = system.vector_field
        a = np.asarray(system.jacobian(z[None])[0])
        L0 = hb[:, None] * np.asarray(field(jnp.tile(z, (stages, 1))))
        dense = dense_newton(field, a, tab, np.asarray(z), hb, L0)
        jacobian = _dense_factor(lambda x: system.jacobian(x[None])[0])
        L, iterations, ok = jax.jit(lambda z, hb, L0: _newton(field, jacobian, tab, z, jnp.zeros_like(z), hb, L0, 100))(
            z, jnp.asarray(hb), jnp.asarray(L0))
        assert bool(ok)
        scale = np.abs(dense).max()
        assert np.abs(np.asarray(L) - dense).max() <= 1e-13 * scale
        residual = dense - hb[:, None] * np.asarray(field(z + small_matmul(tab["mu"], jnp.asarray(dense))))
        assert np.abs(residual).max() <= 1e-13 * scale  # the dense reference itself solved the equations


def test_a_stiff_system_is_solved_by_newton_to_the_closed_form():
    """The stiff chain without its coupling is three harmonic oscillators: with a given long h the
    windows need Newton, and the result is the rotation cos ωt, −ω sin ωt to round-off of the
    method's error at that h."""
    with jax.enable_x64(True):
        omega = np.array([1.0, 40.0, 1600.0])
        system = HamiltonianSystem(lambda q, p: jnp.sum(p ** 2 + (jnp.asarray(omega) * q) ** 2) / 2, 3,
                                   z0=np.r_[np.ones(3), np.zeros(3)])
        T = 1.0
        sol = solve(system, None, (0.0, T), solver=GaussCollocation(stages=6, h=0.01))
        assert sol.info["newton_windows"] >= sol.n_windows - 1
        # the Gauss method on a linear system is the (2s, 2s) Padé approximant of exp(hA): the phase
        # error per window at hω = 16 is what it is; compare with that map applied 100 times
        A = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.diag(omega ** 2), np.zeros((3, 3))]])
        tab = gauss_tableau(6)
        M = np.eye(6)
        # one window of the Gauss method on z' = Az: z1 = z0 + (b ⊗ I) K, K = (I − h A_rk ⊗ A)^{-1} (1 ⊗ A z0)
        a_rk = tab.mu * tab.b[None, :]
        big = np.eye(36) - 0.01 * np.kron(a_rk, A)
        K = np.linalg.solve(big, np.kron(np.ones((6, 1)), A))
        M = np.eye(6) + 0.01 * np.kron(tab.b[None, :], np.eye(6)) @ K
        expected = np.linalg.matrix_power(M, 100) @ system.z0
        assert np.abs(sol(T) - expected).max() <= 1e-10 * np.abs(expected).max()


def test_newton_is_compiled_only_once_a_window_needs_it(monkeypatch):
    """By default the march's program leaves Newton's iteration out; a window the fixed-point
    iteration cannot solve hands the march, unchanged, to the program with it, which goes on to
    the solution Newton given from the start gives (every member of a batch), with the same
    windows, Newton windows and rejections."""
    asked = []
    real = _gauss.compiled_gauss_march
    monkeypatch.setattr(_gauss, "compiled_gauss_march", lambda *a, **k: asked.append(k["newton"]) or real(*a, **k))
    with jax.enable_x64(True):
        system = HamiltonianSystem(lambda q, p: jnp.sum(p ** 2 + (50.0 * q) ** 2) / 2, 1, name="stiff-oscillator",
                                   z0=np.array([1.0, 0.0]))
        smooth = solve(system, None, (0.0, 4.0), solver=GaussCollocation(rtol=1e-6))
        assert asked == [NEWTON_LATER] and smooth.info["newton_windows"] == 0
        z0s = np.array([[1.0, 0.0], [-0.5, 20.0], [0.1, 3.0]])
        asked.clear()
        later = solve_batch(system, z0s, (0.0, 4.0), solver=GaussCollocation(stages=4, h=0.2))
        assert asked == [NEWTON_LATER, True]
        eager = solve_batch(system, z0s, (0.0, 4.0), solver=GaussCollocation(stages=4, h=0.2, newton=True))
        for a, b in zip(later, eager):
            assert a.n_windows == b.n_windows == 20
            assert a.info["newton_windows"] == b.info["newton_windows"] >= 19
            assert a.info["rejected"] == b.info["rejected"]
            np.testing.assert_allclose(a.z, b.z, rtol=0, atol=1e-12 * np.abs(b.z).max())


def copies_of_henon_heiles(m: int) -> HamiltonianSystem:
    """m uncoupled copies of the Hénon–Heiles system, vectorised (d = 2m)."""

    def hamiltonian(q, p):
        x, y = q[:m], q[m:]
        return jnp.sum(p ** 2) / 2 + jnp.sum((x ** 2 + y ** 2) / 2 + x ** 2 * y - y ** 3 / 3)

    rng = np.random.default_rng(0)
    base = np.array([0.3, -0.3, 0.3, 0.15])
    starts = base + 1e-3 * rng.standard_normal((m, 4))  # rows: (x, y, px, py) of each copy
    z0 = np.concatenate([starts[:, 0], starts[:, 1], starts[:, 2], starts[:, 3]])
    return HamiltonianSystem(hamiltonian, 2 * m, name=f"henon-heiles-x{m}", z0=z0, separable=True)


@pytest.mark.long
def test_iterations_per_window_do_not_grow_with_the_dimension():
    """One copy of Hénon–Heiles and 1 024 nearly equal copies side by side (d = 4 … 4 096): the
    windows and the fixed-point iterations per window stay within 1.5× of one copy's — the work of
    a window is the field's evaluations times a count that does not depend on the dimension."""
    counts = {}
    with jax.enable_x64(True):
        for m in (1, 16, 1024):
            system = copies_of_henon_heiles(m)
            sol = solve(system, None, (0.0, 20.0), solver=GaussCollocation(stages=8, rtol=1e-10, atol=1e-12))
            counts[m] = (sol.n_windows, sol.info["iterations"] / sol.n_windows)
    for m in (16, 1024):
        assert counts[m][0] <= 1.5 * counts[1][0], counts
        assert counts[m][1] <= 1.5 * counts[1][1], counts


def test_the_fixed_point_march_holds_no_n_by_n_array():
    """Without Newton, the compiled march of a 256-dimensional chain holds no array with n² entries:
    nothing in it (the first length, the iteration, the check) costs more than the field does. With
    Newton its Jacobian is there (the probe sees such arrays)."""
    from atlasnn.precision import trace_settings
    from atlasnn.solver._gauss_march import GaussState, _cached, initial_state

    n = 256
    system = fput(n // 2)
    texts = {}
    with jax.enable_x64(True):
        st = initial_state(system.z0, 0.0, 8)
        state = GaussState(*(np.asarray(x)[None] for x in st))
        for newton in (False, True):
            program = _cached(system, 8, "constant", 16, 100, newton, 4.0, 2.0, 8, 30, None, trace_settings())["alone"]
            texts[newton] = program.lower(state, 1.0, 1e-10, 1e-12, 0.0, 16.0).as_text()
    assert f"{n}x{n}" not in texts[False]
    assert f"{n}x{n}" in texts[True]


@pytest.mark.long
def test_the_stage_count_follows_the_tolerance():
    """Without ``stages``, s comes from rtol: never fewer stages for a tighter tolerance, the low
    end at everyday tolerances and 16 near round-off; a given count is kept; the solution records
    the count it used."""
    from atlasnn.solver._gauss import STAGES_BY_TOLERANCE

    tols = [1e-3, 1e-6, 1e-8, 1e-9, 1e-11, 1e-13, 1e-16]
    counts = [GaussCollocation(rtol=r, atol=r / 100).stage_count for r in tols]
    assert counts == sorted(counts) and counts[0] < counts[-1] == 16
    assert {s for _, s in STAGES_BY_TOLERANCE} == set(counts)
    assert GaussCollocation(stages=5, rtol=1e-13).stage_count == 5
    with jax.enable_x64(True):
        system = fput(2)
        loose = solve(system, None, (0.0, 5.0), solver=GaussCollocation(rtol=1e-6, atol=1e-8))
        tight = solve(system, None, (0.0, 5.0), solver=GaussCollocation())
    assert loose.info["stages"] == loose.stages == counts[1] and loose.info["order"] == 2 * counts[1]
    assert tight.info["stages"] == tight.stages == GaussCollocation().stage_count

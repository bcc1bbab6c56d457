"""The splitting methods inside Diffrax (atlasnn.solver.diffrax.SplittingSolver, the atlasnn[diffrax]
extra): the same numbers as atlasnn.solve's SplittingComposition for the same steps, the schemes'
orders, bounded energy, the force carried between steps, the dense output, gradients against
finite differences, an unknown scheme refused in one line. Skipped where Diffrax is not installed.

Compiles are what cost here: the terms are built once per module, and step sizes and end times
are passed as arrays, so that one compiled diffeqsolve serves every step count."""

from __future__ import annotations

import numpy as np
import pytest

diffrax = pytest.importorskip("diffrax", reason="Diffrax is an optional extra: pip install 'atlasnn[diffrax]'")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from atlasnn import AtlasError, builtin_system, solve  # noqa: E402
from atlasnn.errors import ConfigError  # noqa: E402
from atlasnn.solutions import splitting_scheme  # noqa: E402
from atlasnn.solver import SplittingComposition  # noqa: E402
from atlasnn.solver.diffrax import SplittingSolver, SplittingSolverState  # noqa: E402

pytestmark = pytest.mark.usefixtures("x64")  # every test in float64 (tests/conftest.py)

HH = builtin_system("henon_heiles")
Z0 = np.array([0.3, -0.3, 0.3, 0.15])
T = 5.0

#: dq/dt = T'(p), dp/dt = −V'(q) of Hénon–Heiles, from the system's own H (as atlasnn.solve takes them)
HH_TERMS = (diffrax.ODETerm(lambda t, p, args: HH.dH_dp(jnp.zeros_like(p), p)),
            diffrax.ODETerm(lambda t, q, args: -HH.dH_dq(q, jnp.zeros_like(q))))
#: the harmonic oscillator H = p²/2 + q²/2
HO_TERMS = (diffrax.ODETerm(lambda t, p, args: p), diffrax.ODETerm(lambda t, q, args: -q))


def henon_heiles_force(t, q, lam):
    """−V'(q) for V = (q1² + q2²)/2 + λ(q1² q2 − q2³/3), λ as the solve's args."""
    q1, q2 = q[0], q[1]
    return -jnp.stack([q1 + 2 * lam * q1 * q2, q2 + lam * (q1 * q1 - q2 * q2)])


PARAM_TERMS = (diffrax.ODETerm(lambda t, p, args: p), diffrax.ODETerm(henon_heiles_force))


def constant(terms, scheme, end, n, y0, **kwargs):
    """diffeqsolve with n constant steps over [0, end] (times as arrays: no recompile per n)."""
    return diffrax.diffeqsolve(terms, SplittingSolver(scheme), jnp.asarray(0.0), jnp.asarray(end),
                               jnp.asarray(end / n), y0, stepsize_controller=diffrax.ConstantStepSize(), **kwargs)


def hh_end(scheme, n):
    """Hénon–Heiles from Z0 over [0, T] in n steps: the end state (q, p) as one vector."""
    sol = constant(HH_TERMS, scheme, T, n, (jnp.asarray(Z0[:2]), jnp.asarray(Z0[2:])))
    assert int(sol.stats["num_steps"]) == n
    return np.concatenate([np.asarray(sol.ys[0][-1]), np.asarray(sol.ys[1][-1])])


# ------------------------------------------------------------------ the same numbers as atlasnn.solve
@pytest.mark.parametrize("scheme", ["leapfrog", "yoshida4", "kahan_li8"])
def test_same_end_state_as_atlasnn_solve(scheme):
    """The same flows, compensation and carried force: the two doors differ only by how the step
    length rounds (Diffrax's t_{k+1} − t_k against atlasnn's (T − t0)/N), ulps of the state."""
    n = 100
    ref = solve(HH, Z0, (0.0, T), solver=SplittingComposition(scheme=scheme, steps=n))
    assert np.abs(hh_end(scheme, n) - ref.end_state).max() < 1e-12


def test_order_and_orders_measured():
    """Slopes of the end-state error over [0, 5] as the step halves, against kahan_li8 at h = T/400."""
    ref = hh_end("kahan_li8", 400)
    for scheme, steps in (("leapfrog", (50, 100, 200)), ("yoshida4", (25, 50, 100))):
        order = SplittingSolver(scheme).order(HH_TERMS)
        assert order == splitting_scheme(scheme).order
        errors = [np.abs(hh_end(scheme, n) - ref).max() for n in steps]
        slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
        assert np.all(np.abs(slopes - order) < 0.4), (scheme, errors, slopes)
    assert SplittingSolver("leapfrog").error_order(HH_TERMS) is None


# ------------------------------------------------------------------ symplectic: bounded energy
def test_harmonic_oscillator_energy_stays_bounded_over_ten_thousand_steps():
    """Leapfrog (kick–drift–kick) at h = 0.1 on H = (p² + q²)/2 conserves H_h = p²/2 + (1 − h²/4)q²/2
    exactly: the step keeps it to round-off over 10⁴ steps, and H's own error is the bounded
    oscillation H − H_h = h²q²/8, as large over the last thousand steps as over the first."""
    h, n = 0.1, 10_000
    sol = constant(HO_TERMS, "leapfrog", n * h, n, (jnp.array([1.0]), jnp.array([0.0])),
                   saveat=diffrax.SaveAt(steps=True), max_steps=n)
    q, p = np.asarray(sol.ys[0])[:n, 0], np.asarray(sol.ys[1])[:n, 0]
    modified = p ** 2 / 2 + (1 - h * h / 4) * q ** 2 / 2
    assert np.abs(modified - (1 - h * h / 4) / 2).max() < 1e-13
    dH = np.abs((p ** 2 + q ** 2) / 2 - 0.5)
    first, last = dH[:1000].max(), dH[-1000:].max()
    assert first < h * h / 8 + 1e-12 and last < 1.0001 * first, (first, last)


# ------------------------------------------------------------------ the step itself
def counted(terms):
    """The terms with their evaluations counted (under jax.disable_jit: each call is one evaluation)."""
    calls = {"drift": 0, "kick": 0}

    def drift(t, p, args):
        calls["drift"] += 1
        return terms[0].vector_field(t, p, args)

    def kick(t, q, args):
        calls["kick"] += 1
        return terms[1].vector_field(t, q, args)

    return (diffrax.ODETerm(drift), diffrax.ODETerm(kick)), calls


@pytest.mark.parametrize("scheme", ["yoshida4", "kahan_li8"])
def test_the_force_is_carried_from_step_to_step(scheme):
    """A kick-first scheme evaluates V' once per nonzero kick but the first (the previous step's
    last), and once more after a jump of the vector field, where the carried force is stale.
    Under disable_jit nothing is compiled away: the dense output's rates are counted too."""
    terms, calls = counted(HO_TERMS)  # cheap fields: the step runs op by op here
    solver, y0 = SplittingSolver(scheme), (jnp.array([1.0]), jnp.array([0.5]))
    kicks = sum(b != 0.0 for b in splitting_scheme(scheme).b_f)
    with jax.disable_jit():
        state = solver.init(terms, 0.0, 0.1, y0, None)
        calls["kick"] = 0
        y1, error, _, state1, _ = solver.step(terms, 0.0, 0.1, y0, None, state, False)
        assert calls["kick"] == kicks - 1 and error is None
        drifts = sum(a != 0.0 for a in splitting_scheme(scheme).a_f)
        assert calls["drift"] == drifts + 2  # and the dense output's rates at the two ends (no kicks)
        stale = SplittingSolverState(state.y, state.e, state.force + 1.0)
        jumped, _, _, _, _ = solver.step(terms, 0.0, 0.1, y0, None, stale, jnp.asarray(True))
        assert calls["kick"] == 2 * kicks - 1  # evaluated again at the step's start
    np.testing.assert_array_equal(np.asarray(jumped[1]), np.asarray(y1[1]))
    np.testing.assert_array_equal(np.asarray(state1.force), -np.asarray(y1[0]))  # V' at the step's end


def test_dense_output_between_the_step_ends_is_of_order_four():
    """Yoshida4 on the harmonic oscillator, at times inside the steps: the cubic Hermite interpolant
    (local error O(h⁴)) on top of the scheme's own error (order 4): the error falls 16-fold as h halves."""
    t = jnp.linspace(0.0, 4.0, 41)[:-1] + 0.013
    errors = []
    for n in (20, 40):
        sol = constant(HO_TERMS, "yoshida4", 4.0, n, (jnp.array([1.0]), jnp.array([0.0])),
                       saveat=diffrax.SaveAt(ts=t))
        errors.append(np.abs(np.asarray(sol.ys[0])[:, 0] - np.cos(np.asarray(t))).max())
    assert 2 ** 3.5 < errors[0] / errors[1] < 2 ** 4.5, errors


# ------------------------------------------------------------------ gradients
def test_gradient_through_diffeqsolve_matches_central_differences():
    """d/d(q0, p0, λ) of a weighted sum of the end state, by the default adjoint
    (RecursiveCheckpointAdjoint: reverse mode through the steps), against central differences."""
    w = jnp.array([0.7, -1.3, 0.4, 2.1])

    def loss(x):
        sol = constant(PARAM_TERMS, "yoshida4", 3.0, 30, (x[:2], x[2:4]), args=x[4])
        return jnp.dot(w, jnp.concatenate([sol.ys[0][-1], sol.ys[1][-1]]))

    run = jax.jit(jax.value_and_grad(loss))  # one compile for the gradient and the differences
    x, eps = np.concatenate([Z0, [1.0]]), 1e-6
    g = np.asarray(run(x)[1])
    fd = np.array([float(run(x + eps * d)[0] - run(x - eps * d)[0]) / (2 * eps) for d in np.eye(5)])
    assert np.abs(g - fd).max() < 1e-6 * np.abs(g).max(), (g, fd)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("name", ["yoshida5", "", 4])
def test_unknown_scheme_is_refused_in_one_line(name):
    with pytest.raises(ConfigError, match="yoshida4") as info:
        SplittingSolver(name)
    assert "\n" not in str(info.value) and isinstance(info.value, AtlasError)

"""The Gauss collocation inside Diffrax (atlasnn.solver.diffrax.GaussLegendre, the atlasnn[diffrax]
extra): the same numbers as atlasnn.solve for the same steps, its orders, bounded energy with
constant steps, adaptive steps from its error estimate (and rejected tries leaving no trace), dense
output, events, vmap, gradients against finite differences, failures reported, bad input in one
line. Skipped where Diffrax is not installed (CI runs it both ways)."""

from __future__ import annotations

import numpy as np
import pytest

diffrax = pytest.importorskip("diffrax", reason="Diffrax is an optional extra: pip install 'atlasnn[diffrax]'")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import optimistix as optx  # noqa: E402

from atlasnn import AtlasError, solve  # noqa: E402
from atlasnn.errors import ConfigError  # noqa: E402
from atlasnn.solutions import gauss_tableau  # noqa: E402
from atlasnn.solver import GaussCollocation  # noqa: E402
from atlasnn.solver._gauss_march import ReplayState, compiled_gauss_replay  # noqa: E402
from atlasnn.solver.diffrax import GaussLegendre, GaussLegendreState  # noqa: E402
from atlasnn.systems import expression_system  # noqa: E402

E = 0.6
PERIOD = 2 * np.pi


pytestmark = pytest.mark.usefixtures("x64")  # every test in float64 (tests/conftest.py)


def kepler_system():
    return expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                             z0=[1 - E, 0.0, 0.0, float(np.sqrt((1 + E) / (1 - E)))], separable=True,
                             name="kepler-diffrax")


def kepler_field(t, y, mu):
    q1, q2, p1, p2 = y
    r3 = (q1 * q1 + q2 * q2) ** 1.5
    return jnp.stack([p1, p2, -mu * q1 / r3, -mu * q2 / r3])


def kepler_z0():
    return jnp.array([1 - E, 0.0, 0.0, np.sqrt((1 + E) / (1 - E))])


def kepler_exact(t):
    """From pericentre at t = 0 (a = 1, μ = 1), by Kepler's equation E − e sin E = M."""
    M = np.mod(np.asarray(t, np.float64), PERIOD)
    Ea = M + E * np.sin(M)
    for _ in range(50):
        Ea = Ea - (Ea - E * np.sin(Ea) - M) / (1 - E * np.cos(Ea))
    c, s, w = np.cos(Ea), np.sin(Ea), np.sqrt(1 - E * E)
    return np.stack([c - E, w * s, -s / (1 - E * c), w * c / (1 - E * c)], axis=-1)


def henon_heiles(t, y, lam):
    x, yy, px, py = y
    return jnp.stack([px, py, -x - 2 * lam * x * yy, -yy - lam * (x * x - yy * yy)])


def constant(term, solver, T, h, y0, args=None, **kw):
    """Constant steps h over [0, T]; the times as arrays and max_steps a power of two, so that runs
    of other lengths reuse one compiled program."""
    steps = 1 << int(np.ceil(np.log2(np.ceil(T / h) + 4)))
    return diffrax.diffeqsolve(term, solver, jnp.asarray(0.0), jnp.asarray(float(T)), jnp.asarray(float(h)), y0,
                               args=args, stepsize_controller=diffrax.ConstantStepSize(), max_steps=steps, **kw)


def accepted(sol):
    n = int(sol.stats["num_accepted_steps"])
    return np.asarray(sol.ts)[:n], np.asarray(sol.ys)[:n]


# ------------------------------------------------------------------ one step, two doors
@pytest.mark.long
def test_same_numbers_as_atlasnn_solve():
    """h = 2⁻⁴ (every time k·h exact in float64): diffeqsolve's step times are atlasnn.solve's window
    edges bit for bit; the states at them and the dense outputs agree to round-off (on a CPU the
    march is compiled with XLA's loop emitters, diffeqsolve with its defaults: the same sums in
    another order, 5e-15 of the state's size apart after 384 steps when this was written)."""
    system = kepler_system()
    term = diffrax.ODETerm(lambda t, y, args: system.vector_field(y[None])[0])
    h, T = 2.0 ** -4, 24.0
    ts, ys = accepted(constant(term, GaussLegendre(), T, h, jnp.asarray(system.z0), saveat=diffrax.SaveAt(steps=True)))
    ref = solve(system, None, (0.0, T), solver=GaussCollocation(h=h))
    assert ref.n_windows == ts.size == 384
    np.testing.assert_array_equal(ts[:-1], ref.edges[1:-1])
    size = np.abs(ref.z).max()
    assert np.abs(ys[:-1] - ref.z[1:]).max() <= 1e-13 * size
    assert np.abs(ys[-1] - ref.end_state).max() <= 1e-13 * size
    t = np.linspace(0.0, T, 997)
    dense = constant(term, GaussLegendre(), T, h, jnp.asarray(system.z0), saveat=diffrax.SaveAt(ts=jnp.asarray(t)))
    assert np.abs(np.asarray(dense.ys) - ref(t)).max() <= 1e-13 * np.abs(ref(t)).max()


@pytest.mark.long
def test_same_numbers_for_any_step_sequence():
    """h = 0.05: Diffrax's times are rounded (t_{k+1} − t_k differs from h by ulps of t), so the
    march is given the very lengths Diffrax stepped; the two are then identical."""
    system = kepler_system()
    term = diffrax.ODETerm(lambda t, y, args: system.vector_field(y[None])[0])
    ts, ys = accepted(constant(term, GaussLegendre(), 30.0, 0.05, jnp.asarray(system.z0),
                               saveat=diffrax.SaveAt(steps=True)))
    lengths = np.diff(np.concatenate([[0.0], ts]))
    assert np.ptp(lengths) > 0  # the rounding of the times is there to be matched
    replay = compiled_gauss_replay(system, stages=12, max_iterations=100, newton=True)
    start = ReplayState(np.asarray(system.z0), np.zeros(4), np.float64(0.0), np.zeros((12, 4)), np.int64(0))
    end, (z, _, _) = replay(start, lengths)
    np.testing.assert_array_equal(np.asarray(z)[1:], ys[:-1])
    np.testing.assert_array_equal(np.asarray(end.z), ys[-1])


# ------------------------------------------------------------------ the method's properties
@pytest.mark.long
def test_order_2s_at_the_step_ends():
    solver = GaussLegendre(stages=3)
    term = diffrax.ODETerm(kepler_field)
    assert solver.order(term) == 6 and solver.error_order(term) == 4 and solver.strong_order(term) is None
    ends = []
    for n in (40, 80, 160):
        sol = constant(term, solver, PERIOD, PERIOD / n, kepler_z0(), args=1.0)
        ends.append(np.abs(np.asarray(sol.ys)[-1] - kepler_exact(PERIOD)).max())
    slopes = np.log2(np.array(ends[:-1]) / np.array(ends[1:]))
    assert np.all(np.abs(slopes - 6) < 0.6), (ends, slopes)


@pytest.mark.long
def test_the_dense_output_is_of_order_s_plus_1():
    """Between the step ends the polynomial is of order s + 1 (harmonic oscillator, s = 4)."""
    term = diffrax.ODETerm(lambda t, y, args: jnp.stack([y[1], -y[0]]))
    t = np.linspace(0.0, 4.0, 1001)
    errors = []
    for h in (0.4, 0.2, 0.1):
        sol = constant(term, GaussLegendre(stages=4), 4.0, h, jnp.array([1.0, 0.0]),
                       saveat=diffrax.SaveAt(dense=True))
        z = np.asarray(jax.vmap(sol.evaluate)(jnp.asarray(t)))
        errors.append(np.abs(z - np.stack([np.cos(t), -np.sin(t)], axis=-1)).max())
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(slopes - 5) < 0.7), (errors, slopes)


@pytest.mark.long
def test_constant_steps_keep_the_energy_bounded_and_angular_momentum_exact():
    """Kepler e = 0.6 over 300 periods at 24 steps a period, s = 4 (an energy error well above
    round-off): that of the last hundred periods is that of the first hundred (no drift);
    q1 p2 − q2 p1 to round-off."""
    n = 24
    sol = constant(diffrax.ODETerm(kepler_field), GaussLegendre(stages=4), 300 * PERIOD, PERIOD / n, kepler_z0(),
                   args=1.0, saveat=diffrax.SaveAt(steps=True))
    _, z = accepted(sol)
    q1, q2, p1, p2 = z.T
    energy = (p1 ** 2 + p2 ** 2) / 2 - 1 / np.sqrt(q1 ** 2 + q2 ** 2)
    drift = np.abs(energy / (-0.5) - 1)
    first, last = drift[: 100 * n].max(), drift[-100 * n:].max()
    assert 1e-6 < first < 1e-2 and last < 1.05 * first, (first, last)
    momentum = q1 * p2 - q2 * p1
    assert np.abs(momentum - momentum[0]).max() < 1e-13


@pytest.mark.long
def test_time_dependent_fields_are_evaluated_at_the_nodes_times():
    """y' = (t⁵, cos t): the Gauss quadrature of 3 nodes is exact for t⁵, so the first component is
    exact at every step end whatever h; the second is of order 6."""
    def field(t, y, args):
        return jnp.stack([t ** 5, jnp.cos(t)])

    ts, ys = accepted(constant(diffrax.ODETerm(field), GaussLegendre(stages=3), 2.0, 0.5, jnp.zeros(2),
                               saveat=diffrax.SaveAt(steps=True)))
    np.testing.assert_allclose(ys[:, 0], ts ** 6 / 6, rtol=1e-14, atol=1e-15)
    assert np.abs(ys[:, 1] - np.sin(ts)).max() < 1e-5


def test_steps_across_a_jump_of_the_field():
    """y' = c(t) cos y with c = 1 before t = 1 and 2 after, the jump declared to the controller
    (the step after it starts from a fresh guess, not from the previous polynomial)."""
    def field(t, y, args):
        return jnp.where(t < 1.0, 1.0, 2.0) * jnp.cos(y)

    controller = diffrax.ClipStepSizeController(diffrax.PIDController(rtol=1e-12, atol=1e-12),
                                                jump_ts=jnp.array([1.0]))
    sol = diffrax.diffeqsolve(diffrax.ODETerm(field), GaussLegendre(stages=6), 0.0, 2.0, 0.3, jnp.zeros(1),
                              stepsize_controller=controller, saveat=diffrax.SaveAt(ts=jnp.array([1.0, 2.0])))
    y1 = 2 * np.arctan(np.tanh(0.5))  # y = 2 atan(tanh(c t/2 + atanh(tan(y0/2))))
    y2 = 2 * np.arctan(np.tanh(1.0 + np.arctanh(np.tan(y1 / 2))))
    np.testing.assert_allclose(np.asarray(sol.ys)[:, 0], [y1, y2], rtol=1e-11)


@pytest.mark.long
def test_a_pytree_state_gives_the_flat_states_numbers():
    def split(t, y, lam):
        dz = henon_heiles(t, jnp.concatenate([y["q"], y["p"]]), lam)
        return {"q": dz[:2], "p": dz[2:]}

    z0 = jnp.array([0.3, -0.2, 0.25, 0.2])
    flat = constant(diffrax.ODETerm(henon_heiles), GaussLegendre(stages=6), 3.0, 0.25, z0, args=1.0)
    tree = constant(diffrax.ODETerm(split), GaussLegendre(stages=6), 3.0, 0.25, {"q": z0[:2], "p": z0[2:]}, args=1.0)
    np.testing.assert_array_equal(np.concatenate([tree.ys["q"][-1], tree.ys["p"][-1]]), np.asarray(flat.ys[-1]))


# ------------------------------------------------------------------ adaptive steps
@pytest.mark.long
def test_pid_controller_meets_its_tolerance_on_an_eccentric_orbit():
    term, t = diffrax.ODETerm(kepler_field), np.linspace(0.0, 4 * PERIOD, 200)
    errors, steps = [], []
    for tol in (1e-7, 1e-10):
        sol = diffrax.diffeqsolve(term, GaussLegendre(stages=8), 0.0, 4 * PERIOD, None, kepler_z0(), args=1.0,
                                  saveat=diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=jnp.asarray(t)),
                                                              diffrax.SubSaveAt(steps=True)]),
                                  stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol), max_steps=10_000)
        errors.append(np.abs(np.asarray(sol.ys[0]) - kepler_exact(t)).max())
        times = np.asarray(sol.ts[1])[:int(sol.stats["num_accepted_steps"])]
        steps.append(np.diff(times))
    assert errors[0] < 1e-5 and errors[1] < 1e-8 and errors[1] < errors[0] / 100, errors
    assert steps[1].max() > 3 * steps[1].min()  # short steps at pericentre, long ones at apocentre


@pytest.mark.long
def test_rejected_tries_leave_no_trace():
    """A PID run with rejected tries gives the numbers of the accepted steps alone (replayed with
    StepTo), so nothing of a rejected try (stages, compensation) reaches the next step."""
    term, T = diffrax.ODETerm(kepler_field), 2 * PERIOD
    pid = diffrax.diffeqsolve(term, GaussLegendre(stages=8), 0.0, T, 0.5, kepler_z0(), args=1.0,
                              saveat=diffrax.SaveAt(steps=True), max_steps=4096,
                              stepsize_controller=diffrax.PIDController(rtol=1e-9, atol=1e-9))
    assert int(pid.stats["num_rejected_steps"]) > 0
    ts, ys = accepted(pid)
    replay = diffrax.diffeqsolve(term, GaussLegendre(stages=8), 0.0, T, None, kepler_z0(), args=1.0,
                                 saveat=diffrax.SaveAt(steps=True), max_steps=4096,
                                 stepsize_controller=diffrax.StepTo(ts=jnp.concatenate([jnp.zeros(1), ts])))
    assert np.abs(accepted(replay)[1] - ys).max() < 1e-14


@pytest.mark.long
def test_a_compensation_is_used_only_for_the_state_it_was_made_for():
    term, solver = diffrax.ODETerm(kepler_field), GaussLegendre(stages=4)
    y0 = kepler_z0()
    st = solver.init(term, 0.0, 0.1, y0, 1.0)
    step = jax.jit(lambda y, state: solver.step(term, 0.0, 0.1, y, 1.0, state, False)[0])  # one compile, four steps
    plain = step(y0, st)
    other = GaussLegendreState(y0 + 1e-3, jnp.full(4, 1e-9), st.L, st.h)  # made for another state: not used
    np.testing.assert_array_equal(step(y0, other), plain)
    # made for y0: the step is from y0 + e (the same as a step from the rounded sum, to round-off)
    mine = step(y0, GaussLegendreState(y0, jnp.full(4, 1e-9), st.L, st.h))
    shifted = step(y0 + 1e-9, st._replace(z=y0 + 1e-9))
    assert np.abs(np.asarray(mine - plain)).max() > 5e-10
    assert np.abs(np.asarray(mine - shifted)).max() < 1e-15


@pytest.mark.long
def test_unsolved_stage_equations_fail_a_constant_step_and_shrink_an_adaptive_one():
    """ω = 100 with h = 1 and no Newton: the fixed-point iteration cannot contract."""
    term, y0 = diffrax.ODETerm(lambda t, y, w: jnp.stack([y[1], -w * w * y[0]])), jnp.array([1.0, 0.0])
    failed = constant(term, GaussLegendre(stages=4, newton=False), 3.0, 1.0, y0, args=100.0, throw=False)
    assert failed.result != diffrax.RESULTS.successful
    newton = constant(term, GaussLegendre(stages=4), 3.0, 1.0, y0, args=100.0)
    assert newton.result == diffrax.RESULTS.successful
    assert abs(float(newton.ys[-1, 0] ** 2 + newton.ys[-1, 1] ** 2 / 1e4) - 1) < 1e-12  # a quadratic invariant
    adaptive = diffrax.diffeqsolve(term, GaussLegendre(stages=4, newton=False), 0.0, 0.3, 1.0, y0, args=100.0,
                                   stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-8))
    assert abs(float(adaptive.ys[-1, 0]) - np.cos(30.0)) < 1e-6


# ------------------------------------------------------------------ dense output, events, vmap
@pytest.mark.long
def test_dense_output_meets_the_equations_at_the_gauss_nodes():
    sol = constant(diffrax.ODETerm(kepler_field), GaussLegendre(stages=6), 3.0, 0.25, kepler_z0(), args=1.0,
                   saveat=diffrax.SaveAt(dense=True, t1=True))
    t = jnp.asarray((0.25 * (np.arange(12)[:, None] + gauss_tableau(6).c[None, :])).reshape(-1))
    z, dz = jax.vmap(sol.evaluate)(t), jax.vmap(sol.derivative)(t)
    field = jax.vmap(lambda y: kepler_field(0.0, y, 1.0))(z)
    assert np.abs(np.asarray(dz - field)).max() < 1e-12
    np.testing.assert_array_equal(np.asarray(sol.evaluate(0.0)), np.asarray(kepler_z0()))
    edges = jnp.arange(1, 12) * 0.25
    jump = jax.vmap(sol.evaluate)(edges - 1e-13) - jax.vmap(sol.evaluate)(edges)
    assert np.abs(np.asarray(jump)).max() < 1e-11  # continuous across the step ends
    assert np.abs(np.asarray(sol.evaluate(3.0) - sol.ys[-1])).max() < 1e-15


@pytest.mark.long
def test_an_event_is_located_on_the_polynomial():
    """x = 0 first crossed where cos E = e (Kepler's equation gives its time)."""
    event = diffrax.Event(lambda t, y, args, **kw: y[0], root_finder=optx.Newton(rtol=1e-13, atol=1e-13))
    sol = constant(diffrax.ODETerm(kepler_field), GaussLegendre(stages=8), 10.0, PERIOD / 64, kepler_z0(), args=1.0,
                   event=event)
    Ea = np.arccos(E)
    assert abs(float(sol.ts[0]) - (Ea - E * np.sin(Ea))) < 1e-12
    assert abs(float(sol.ys[0, 0])) < 1e-12


@pytest.mark.long
def test_vmap_over_initial_states():
    @jax.jit
    def end(z0):
        return constant(diffrax.ODETerm(henon_heiles), GaussLegendre(stages=6), 4.0, 0.2, z0, args=1.0).ys[-1]

    z0s = jnp.array([0.3, -0.2, 0.25, 0.2]) + 0.05 * jnp.arange(4.0)[:, None]
    batch = jax.vmap(end)(z0s)
    for i in range(4):  # a batch iterates until every member has converged: the same to round-off
        assert np.abs(np.asarray(batch[i] - end(z0s[i]))).max() < 1e-14


# ------------------------------------------------------------------ gradients
@pytest.mark.slow  # 20 s; the door's gradients are checked against atlasnn.solve's in test_gauss_core
def test_gradients_match_finite_differences():
    """∂z(T)/∂z0 and ∂z(T)/∂λ of Hénon–Heiles by RecursiveCheckpointAdjoint (reverse mode through the
    implicit function theorem) against central differences, and against forward mode."""
    z0 = jnp.array([0.3, -0.2, 0.25, 0.2])

    def end(z0, lam, adjoint=diffrax.RecursiveCheckpointAdjoint()):
        return constant(diffrax.ODETerm(henon_heiles), GaussLegendre(stages=6), 6.0, 0.25, z0, args=lam,
                        adjoint=adjoint).ys[-1]

    jz, jl = jax.jit(jax.jacrev(end, argnums=(0, 1)))(z0, 1.0)
    fz, fl = jax.jit(jax.jacfwd(lambda a, b: end(a, b, diffrax.ForwardMode()), argnums=(0, 1)))(z0, 1.0)
    run, eps = jax.jit(end), 1e-6
    fd_l = (run(z0, 1.0 + eps) - run(z0, 1.0 - eps)) / (2 * eps)
    fd_z = jnp.stack([(run(z0 + eps * d, 1.0) - run(z0 - eps * d, 1.0)) / (2 * eps) for d in jnp.eye(4)], axis=1)
    assert float(jnp.abs(jl - fd_l).max() / jnp.abs(jl).max()) < 1e-6
    assert float(jnp.abs(jz - fd_z).max() / jnp.abs(jz).max()) < 1e-6
    assert float(jnp.abs(jz - fz).max()) < 1e-12 and float(jnp.abs(jl - fl).max()) < 1e-12


@pytest.mark.long
def test_gradient_with_respect_to_keplers_mu():
    def end(mu):
        return constant(diffrax.ODETerm(kepler_field), GaussLegendre(stages=8), PERIOD, PERIOD / 32, kepler_z0(),
                        args=mu).ys[-1]

    g = jax.jit(jax.jacrev(end))(1.0)
    run, eps = jax.jit(end), 1e-6
    fd = (run(1.0 + eps) - run(1.0 - eps)) / (2 * eps)
    assert float(jnp.abs(g - fd).max() / jnp.abs(g).max()) < 1e-6


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("kwargs", [{"stages": 0}, {"stages": 17}, {"stages": 2.5}, {"max_iterations": 0},
                                    {"newton": "yes"}])
def test_bad_settings_are_refused_in_one_line(kwargs):
    with pytest.raises(ConfigError) as info:
        GaussLegendre(**kwargs)
    assert "\n" not in str(info.value) and isinstance(info.value, AtlasError)


def test_a_float32_state_is_refused_in_one_line():
    with jax.enable_x64(False), pytest.raises(ConfigError, match="float64") as info:
        constant(diffrax.ODETerm(kepler_field), GaussLegendre(stages=2), 1.0, 0.5, jnp.zeros(4, jnp.float32) + 0.5,
                 args=1.0)
    assert "\n" not in str(info.value)

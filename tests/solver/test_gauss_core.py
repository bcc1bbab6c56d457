"""``solve`` as a JAX function: inside jit, grad, vmap and jvp it runs the traceable core, which must
compute the host march's numbers and exact derivatives of them (against central differences,
forward against reverse mode, Diffrax's checkpointed adjoint through the same method, and closed
forms of the harmonic oscillator)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.solutions import TracedSolution
from atlasnn.solver import GaussCollocation, solve
from atlasnn.systems import HamiltonianSystem, expression_system

E = 0.6
PERIOD = 2 * np.pi


pytestmark = pytest.mark.usefixtures("x64")  # every test in float64 (tests/conftest.py)


def kepler():
    return expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                             z0=[1 - E, 0.0, 0.0, float(np.sqrt((1 + E) / (1 - E)))], separable=True,
                             name="kepler-core")


def oscillator(k):
    return HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + k * q[0] ** 2 / 2, 1, name="oscillator-core")


@pytest.mark.long
def test_jit_gives_the_host_numbers():
    """Given windows (h): the same windows and, to round-off, the same polynomials; with the control:
    the same tolerance met (a length may tip where the check's round-off differs between programs)."""
    system, T = kepler(), 3 * PERIOD
    t = np.linspace(0.0, T, 301)
    for solver, close in ((GaussCollocation(h=2.0 ** -4, stages=6), 1e-13), (GaussCollocation(), 1e-10)):
        host = solve(system, None, (0.0, T), solver=solver)
        traced = jax.jit(lambda z: solve(system, z, (0.0, T), solver=solver))(jnp.asarray(system.z0))
        assert isinstance(traced, TracedSolution)
        assert abs(int(traced.count) - host.n_windows) <= (0 if solver.h else 0.05 * host.n_windows)
        assert np.abs(np.asarray(traced(t)) - host(t)).max() <= close * np.abs(host(t)).max()
        assert np.abs(np.asarray(traced.derivative(t)) - host.derivative(t)).max() <= 1e3 * close


def richardson(f, z0, eps):
    """Central differences of f at z0 along each axis, Richardson-extrapolated over eps and eps/2."""
    def central(h):
        return np.stack([(np.asarray(f(z0 + h * u)) - np.asarray(f(z0 - h * u))) / (2 * h)
                         for u in np.eye(z0.size)], axis=-1)
    return (4 * central(eps / 2) - central(eps)) / 3


@pytest.mark.slow  # 54 s; test_derivatives_in_the_interval_and_in_hs_parameters_match_closed_forms checks the traced gradients exactly (CI stays under 30 min)
def test_gradients_agree_with_differences_forward_mode_and_diffrax():
    """Kepler e = 0.6 over 200 fixed windows (h = 2⁻⁴, about 2 periods; T a multiple of h, so that
    Diffrax's constant steps, which divide [0, T] evenly, are the same windows): reverse mode,
    forward mode, Richardson differences and Diffrax's RecursiveCheckpointAdjoint through its
    GaussLegendre agree."""
    diffrax = pytest.importorskip("diffrax")
    from atlasnn.solver.diffrax import GaussLegendre

    h = 2.0 ** -4
    system, T = kepler(), 200 * h
    z0 = jnp.asarray(system.z0)
    end = lambda z, how="reverse": solve(system, z, (0.0, T), solver=GaussCollocation(  # noqa: E731
        h=h, stages=4, differentiation=how))(T)
    reverse = np.asarray(jax.jit(jax.jacrev(end))(z0))
    forward = np.asarray(jax.jit(jax.jacfwd(lambda z: end(z, "forward")))(z0))
    size = np.abs(reverse).max()
    assert np.abs(reverse - forward).max() <= 1e-12 * size
    assert np.abs(reverse - richardson(jax.jit(end), np.asarray(z0), 1e-5)).max() <= 1e-8 * size
    term = diffrax.ODETerm(lambda t, y, args: system.vector_field(y[None])[0])
    steps = int(np.ceil(T / h)) + 4
    other = np.asarray(jax.jit(jax.jacrev(lambda z: diffrax.diffeqsolve(
        term, GaussLegendre(stages=4), 0.0, T, h, z, stepsize_controller=diffrax.ConstantStepSize(),
        max_steps=steps).ys[-1]))(z0))
    assert np.abs(reverse - other).max() <= 1e-10 * size


@pytest.mark.long
def test_adaptive_windows_differentiate_as_the_map_they_take():
    """With the control (lengths from the check, not differentiated): the gradient is that of the
    map over the windows taken, which central differences reproduce only where a nudge of z0 does
    not move the lengths by more than the tolerance allows: ≤ 1e-6 relative at rtol 1e-11."""
    system, T = kepler(), PERIOD
    z0 = np.asarray(system.z0)
    end = jax.jit(lambda z: solve(system, z, (0.0, T))(T))
    g = np.asarray(jax.jacrev(end)(jnp.asarray(z0)))
    assert np.abs(g - richardson(end, z0, 1e-4)).max() <= 1e-6 * np.abs(g).max()


@pytest.mark.long
def test_derivatives_in_the_interval_and_in_hs_parameters_match_closed_forms():
    """Harmonic oscillator H = p²/2 + k q²/2 from (1, 0): q(T) = cos(√k T), so ∂q/∂T = −√k sin(√k T)
    and ∂q/∂k = −T sin(√k T)/(2√k); the parameter closed over by a system built inside grad."""
    T, k = 7.3, 2.3

    def q_end(k, T):
        return solve(oscillator(k), jnp.array([1.0, 0.0]), (0.0, T))(T)[0]

    dk, dT = jax.jit(jax.grad(q_end, argnums=(0, 1)))(k, T)
    w = np.sqrt(k)
    assert abs(float(dT) + w * np.sin(w * T)) <= 1e-9
    assert abs(float(dk) + T * np.sin(w * T) / (2 * w)) <= 1e-9
    sol = jax.jit(lambda k: solve(oscillator(k), jnp.array([1.0, 0.0]), (0.0, T)))(k)
    t = jnp.linspace(0.0, T, 50)
    assert np.abs(np.asarray(sol(t))[:, 0] - np.cos(w * np.asarray(t))).max() <= 1e-10


@pytest.mark.long
def test_vmap_gives_each_members_own_solve_and_gradient():
    system, T = kepler(), PERIOD
    z0s = np.asarray(system.z0) * np.array([[1.0], [1.02], [0.97]])
    def p1(z):
        end = solve(system, z, (0.0, T))(T)
        return end[1], end

    # the end state and the gradient of its p1 in one program (two compiles in all, not four)
    both = jax.value_and_grad(p1, has_aux=True)
    (_, ends), grads = jax.jit(jax.vmap(both))(jnp.asarray(z0s))  # the adjoint, batched
    alone = jax.jit(both)
    for z, got, g in zip(z0s, np.asarray(ends), np.asarray(grads)):
        (_, end), grad = alone(jnp.asarray(z))
        assert np.abs(got - np.asarray(end)).max() <= 1e-13
        assert np.abs(g - np.asarray(grad)).max() <= 1e-10 * np.abs(g).max()
    # the gradient of a vmapped solve (on a CPU its members marched one after the other, inside the adjoint)
    outer = jax.jit(jax.grad(lambda zs: jnp.sum(jax.vmap(lambda z: p1(z)[0])(zs))))(jnp.asarray(z0s))
    assert np.abs(np.asarray(outer) - np.asarray(grads)).max() <= 1e-10 * np.abs(np.asarray(grads)).max()


@pytest.mark.long
def test_vmap_over_a_value_h_closes_over_is_forward_mode_or_refused_in_one_line():
    # the reverse-mode core cannot be mapped over a value H closes over (JAX's sequential_vmap asserts);
    # the forward-mode one can: q(3) = cos(3 sqrt(k))
    def q3(k, differentiation):
        system = HamiltonianSystem(lambda q, p: 0.5 * p[0] ** 2 + 0.5 * k * q[0] ** 2, 1, z0=(1.0, 0.0))
        return solve(system, None, (0.0, 3.0), solver=GaussCollocation(differentiation=differentiation))(3.0)[0]

    ks = jnp.array([1.0, 2.0, 3.0])
    got = np.asarray(jax.vmap(lambda k: q3(k, "forward"))(ks))
    assert np.abs(got - np.cos(3 * np.sqrt(np.asarray(ks)))).max() < 1e-12
    with pytest.raises(ConfigError, match="differentiation='forward'") as info:
        jax.vmap(lambda k: q3(k, "reverse"))(ks)
    assert "\n" not in str(info.value)


def test_a_march_past_its_budget_raises_naming_it():
    system = kepler()
    run = jax.jit(lambda z: solve(system, z, (0.0, 10 * PERIOD), solver=GaussCollocation(max_windows=5))(1.0))
    with pytest.raises(Exception, match=r"max_windows=5\), was spent before T"):  # JAX wraps Equinox's error
        jax.block_until_ready(run(jnp.asarray(system.z0)))


@pytest.mark.long
def test_what_the_core_cannot_do_is_refused_in_one_line():
    system = kepler()
    with pytest.raises(ConfigError, match="jax_enable_x64"):
        with jax.enable_x64(False):
            jax.jit(lambda z: solve(system, z, (0.0, 1.0))(1.0))(jnp.asarray(system.z0, jnp.float32))
    with pytest.raises(ConfigError, match="time_scale"):
        jax.jit(lambda z: solve(system, z, (0.0, 1.0), solver=GaussCollocation(time_scale="potential"))(1.0))(
            jnp.asarray(system.z0))
    with pytest.raises(ConfigError, match="differentiation"):
        GaussCollocation(differentiation="backward")
    with pytest.raises(ConfigError, match="differentiation='forward'"):
        z0 = jnp.asarray(system.z0)
        jax.jvp(lambda z: solve(system, z, (0.0, 1.0))(1.0), (z0,), (z0,))


def test_a_system_built_from_traced_values_says_so():
    seen = []

    def f(k):
        system = oscillator(k)
        seen.append(system.traced)
        return k

    jax.grad(f)(1.0)
    assert seen == [True] and not oscillator(1.0).traced


@pytest.mark.long
def test_a_traced_interval_that_is_empty_or_not_finite_raises_and_times_outside_give_nan():
    """No silent NaN from a march that never started: T ≤ t0 or a NaN end raises when the program
    runs; a time outside [t0, T] gives NaN (no warning can be raised in a trace), inside the exact value."""
    system = oscillator(1.0)
    run = jax.jit(lambda T: solve(system, jnp.array([1.0, 0.0]), (0.0, T)))
    sol = run(3.0)
    assert abs(float(sol(3.0)[0]) - np.cos(3.0)) < 1e-12
    assert np.all(np.isnan(np.asarray(sol(jnp.array([-0.5, 3.5])))))
    for T in (-1.0, 0.0, float("nan")):
        with pytest.raises(Exception, match=r"interval's ends finite with T > t0"):  # JAX wraps Equinox's error
            jax.block_until_ready(run(T).z)


def test_a_traced_interval_far_from_zero_is_as_accurate_as_one_at_zero():
    """[1.7e9, 1.7e9 + 40] (a Unix time, float64 times 2.4e-7 apart): the windows are placed by their
    starts and the offsets those leave out, as on the host, not by the rounded starts alone (1e-7
    off before)."""
    t0 = 1.7e9
    ts = t0 + jnp.linspace(0.0, 40.0, 101)
    z = jax.jit(lambda z0: solve(oscillator(1.0), z0, (t0, t0 + 40.0))(ts))(jnp.array([1.0, 0.0]))
    exact = np.stack([np.cos(np.asarray(ts) - t0), -np.sin(np.asarray(ts) - t0)], axis=-1)
    assert np.abs(np.asarray(z) - exact).max() < 1e-11


@pytest.mark.long
def test_a_float32_h_a_budget_past_memory_and_complex_times_are_refused_when_traced(monkeypatch):
    """What the traced core cannot do well is refused at trace time in one line: an H computing in
    float32 (it cannot reach the tolerance), a window budget whose arrays exceed the memory, times
    that are not real numbers. An H closing over float32 weights computes in float64 and solves."""
    import atlasnn.solver._gauss as gauss
    from atlasnn.errors import AtlasError

    z0 = jnp.array([1.0, 0.0])
    narrow = HamiltonianSystem(lambda q, p: jnp.sum(p.astype(jnp.float32) ** 2 / 2 + q.astype(jnp.float32) ** 2 / 2),
                               1)
    with pytest.raises(AtlasError, match="computes in float32") as info:
        jax.jit(lambda z: solve(narrow, z, (0.0, 1.0)).z)(z0)
    assert "\n" not in str(info.value)
    monkeypatch.setattr(gauss, "available_memory", lambda: 2**30)
    with pytest.raises(ConfigError, match="max_windows = 10000000 keeps about .* GiB .* lower max_windows"):
        jax.jit(lambda z: solve(oscillator(1.0), z, (0.0, 1.0), solver=GaussCollocation(max_windows=10**7)).z)(z0)
    monkeypatch.undo()
    weights = jnp.asarray(np.array([1.0], np.float32))
    promoted = HamiltonianSystem(lambda q, p: jnp.sum(weights * (p * p + q * q)) / 2, 1)
    sol = jax.jit(lambda z: solve(promoted, z, (0.0, 2.0), solver=GaussCollocation(max_windows=64)))(z0)
    assert abs(float(sol(2.0)[0]) - np.cos(2.0)) < 1e-11
    for t in (1j, "a"):
        with pytest.raises(ConfigError, match="times must be"):
            sol(t)
    with pytest.raises(ConfigError, match="times must be real numbers"):
        jax.jit(lambda t: sol(t))(jnp.array(1j))


@pytest.mark.long
def test_with_params_takes_traced_values_and_solve_differentiates_through_them():
    """``with_params(system, k=k)`` inside ``jax.grad``: dq(1)/dk of q'' = −k q from (1, 0),
    −sin(√k)/(2√k) (a compile of 20 s; vmap goes through the same traced H)."""
    from atlasnn.systems import with_params

    system = expression_system("p**2/2 + k*q**2/2", ["q"], ["p"], params={"k": 1.0}, z0=[1.0, 0.0])

    def q1(k):
        return solve(with_params(system, k=k), jnp.array([1.0, 0.0]), (0.0, 1.0),
                     solver=GaussCollocation(max_windows=64))(1.0)[0]

    assert abs(float(jax.grad(q1)(2.0)) + np.sin(np.sqrt(2.0)) / (2 * np.sqrt(2.0))) < 1e-11
    assert with_params(system, k=2.0).params["k"] == 2.0  # numbers: rebuilt from the spec as before


def test_traced_inputs_that_cannot_be_one_solve_are_refused_in_one_line():
    from atlasnn.solver import solve_batch

    system = oscillator(1.0)
    with pytest.raises(ConfigError, match="T must be a number, got shape \\(2,\\)"):
        jax.jit(lambda T: solve(system, jnp.array([1.0, 0.0]), (0.0, T))(1.0))(jnp.array([1.0, 2.0]))
    with pytest.raises(ConfigError, match="solve_batch runs on numbers.*jax.vmap or jax.lax.map of atlasnn.solve"):
        jax.grad(lambda k: solve_batch(oscillator(k), np.array([[1.0, 0.0]]), (0.0, 1.0))[0](1.0)[0])(1.0)

"""Round-off the Gauss march cannot see for itself, against closed forms: a constant of H that
reaches the float64 program as float32 (JAX's x64 mode off), and a state so large that its own
ulps are above the tolerance (an oscillator about a large offset c)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from atlasnn.errors import SystemError_
from atlasnn.solver import GaussCollocation, solve
from atlasnn.systems import HamiltonianSystem


def _oscillator_error(sol, K: float, T: float) -> float:
    """max |ẑ − z| against q = cos(√K t), p = −√K sin(√K t)."""
    w, t = np.sqrt(K), np.linspace(0.0, T, 401)
    return float(np.abs(sol(t) - np.stack([np.cos(w * t), -w * np.sin(w * t)], axis=-1)).max())


@pytest.mark.long
def test_a_numpy_constant_that_h_closes_over_stays_float64_with_x64_off():
    """The system is built (and its H tried) with x64 off: the march still sees K in float64."""
    K = np.array([2.3])
    with jax.enable_x64(False):
        system = HamiltonianSystem(lambda q, p: jnp.sum(p**2) / 2 + jnp.sum(jnp.asarray(K) * q**2) / 2, 1)
        sol = solve(system, [1.0, 0.0], (0.0, 10.0))
    error = _oscillator_error(sol, 2.3, 10.0)
    assert error < 1e-10, error  # 2e-7 when the float32 copy of K reached the march
    assert error <= 5 * sol.estimate().max_abs


def test_a_float32_constant_in_h_is_refused_in_one_line_before_the_march():
    with jax.enable_x64(False):
        K = jnp.asarray(np.array([2.3]))  # float32: 2.3 is lost before atlasnn sees it
        system = HamiltonianSystem(lambda q, p: jnp.sum(p**2) / 2 + jnp.sum(K * q**2) / 2, 1, name="mine")
        with pytest.raises(SystemError_) as ei:
            solve(system, [1.0, 0.0], (0.0, 10.0))
    msg = str(ei.value)
    assert len(msg.splitlines()) == 1
    assert "system 'mine'" in msg and "float32 constant" in msg and "x64" in msg


def test_a_float32_copy_kept_from_the_users_own_trace_is_refused_not_used():
    """JAX keeps its float32 copy of K while a trace of H made with x64 off lives (here the user's
    jit), and would hand it to the float64 march."""
    K = np.array([2.3])

    def H(q, p):
        return jnp.sum(p**2) / 2 + jnp.sum(jnp.asarray(K) * q**2) / 2

    with jax.enable_x64(False):
        kept = jax.jit(H)
        kept(jnp.ones(1), jnp.ones(1))
        with pytest.raises(SystemError_, match="float32 constant"):
            solve(HamiltonianSystem(H, 1), [1.0, 0.0], (0.0, 10.0))
    del kept


@pytest.mark.long
@pytest.mark.parametrize("c", [1e6, 1e8])
def test_an_oscillator_about_a_large_offset_takes_few_windows_and_says_its_round_off(c):
    """H = p²/2 + (q − c)²/2: ṗ = −(q − c) carries an ulp of q (1.2e-10 at c = 1e6, 1.5e-8 at 1e8),
    which the default tolerance on p is below. The windows no longer shrink chasing it (13 375 at
    1e6 and millions at 1e8 before), and the estimate is no smaller than the error, which is the
    ulps of c (before: 1e-13 of the range, the error 500× larger)."""
    T = 10.0
    system = HamiltonianSystem(lambda q, p: jnp.sum(p**2) / 2 + jnp.sum((q - c) ** 2) / 2, 1)
    sol = solve(system, [c + 1.0, 0.0], (0.0, T))
    t = np.linspace(0.0, T, 1001)
    error = np.abs(sol(t) - np.stack([c + np.cos(t), -np.sin(t)], axis=-1)).max()
    est = sol.estimate()
    assert sol.n_windows <= 40, sol.n_windows
    assert error <= 4 * np.spacing(c), error  # the answer is right to the ulps of c
    assert error <= 2 * est.max_abs, (error, est.max_abs)
    assert est.max_abs >= np.spacing(c)  # … and the estimate says no better
    assert est.relative_max > 1e-11  # not "accurate" to 1e-13 of the range


def test_an_oscillator_about_a_large_offset_with_a_given_tolerance_on_p_is_not_chased_below_round_off():
    """The same at c = 1e7 with rtol 1e-14: the field's round-off counts as round-off."""
    c = 1e7
    system = HamiltonianSystem(lambda q, p: jnp.sum(p**2) / 2 + jnp.sum((q - c) ** 2) / 2, 1)
    sol = solve(system, [c + 1.0, 0.0], (0.0, 10.0), solver=GaussCollocation(rtol=1e-14, atol=1e-16))
    assert sol.n_windows <= 60, sol.n_windows
    t = np.linspace(0.0, 10.0, 1001)
    assert np.abs(sol(t)[:, 0] - (c + np.cos(t))).max() <= 4 * np.spacing(c)

"""A program kept on disk is served only to the system it was made for: a system whose functions
were swapped for another system's (``dataclasses.replace``) is not "defined by data", so it is
traced, never served another system's program."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from atlasnn import solve
from atlasnn.compile_cache import CACHE_ENV, clear_programs
from atlasnn.systems import defined_by_data, expression_system, henon_heiles, nonlinear_oscillator

SLOW = expression_system("p**2/2 + x**2/2", ["x"], ["p"], z0=[1.0, 0.0], name="spring")
FAST = expression_system("p**2/2 + 4*x**2/2", ["x"], ["p"], z0=[1.0, 0.0], name="spring")  # x = cos 2t


def test_an_expression_system_with_another_ones_hamiltonian_is_not_defined_by_data():
    """Before, every expression system's H shared one code object and only a built-in's closure
    was compared, so this passed."""
    assert defined_by_data(SLOW) and defined_by_data(FAST)
    assert not defined_by_data(dataclasses.replace(SLOW, hamiltonian=FAST.hamiltonian))
    assert not defined_by_data(dataclasses.replace(SLOW, parametric=FAST.parametric))
    same = expression_system("p**2/2 + x**2/2", ["x"], ["p"], z0=[1.0, 0.0], name="spring")
    assert defined_by_data(dataclasses.replace(SLOW, hamiltonian=same.hamiltonian))  # the same definition


def test_a_built_ins_parametric_function_is_compared_too():
    hh = henon_heiles()
    assert not defined_by_data(dataclasses.replace(hh, parametric=nonlinear_oscillator().parametric))


@pytest.mark.long
def test_a_warm_cache_serves_no_program_of_another_system(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    t = np.array([3.0])

    def x_at_3(system):
        clear_programs()  # a new process, as far as atlasnn's programs go
        return float(solve(system, None, (0.0, 3.0), rtol=1e-10, atol=1e-12)(t)[0, 0])

    assert abs(x_at_3(SLOW) - np.cos(3.0)) < 1e-8  # the cache now holds SLOW's program
    swapped = dataclasses.replace(SLOW, hamiltonian=FAST.hamiltonian, parametric=FAST.parametric)
    assert abs(x_at_3(swapped) - np.cos(6.0)) < 1e-8


def test_the_gradient_is_jitted_inside_a_trace_and_not_on_numbers():
    # inside a compiled program ∇H is one jitted function per system (traced once per shape); called
    # on numbers it is not compiled (a system built anew each call paid a compile each: 14x)
    import jax

    from atlasnn.systems import _hamiltonian

    system = expression_system("p**2/2 + x**4/4", ["x"], ["p"], z0=[1.0, 0.0], name="quartic")
    before = _hamiltonian._jitted_gradient.cache_info().currsize
    eager = np.asarray(system.grad(np.array([[2.0, 3.0]])))
    assert _hamiltonian._jitted_gradient.cache_info().currsize == before
    traced = np.asarray(jax.jit(system.grad)(np.array([[2.0, 3.0]])))
    assert _hamiltonian._jitted_gradient.cache_info().currsize == before + 1
    assert np.allclose(eager, [[8.0, 3.0]]) and np.allclose(traced, eager, rtol=1e-15, atol=0)

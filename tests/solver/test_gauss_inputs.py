"""A Gauss solution's residual in its own precision, times that are not finite numbers refused in
one line, the remedy a given window length that cannot converge is told, and a setting a solver
does not have named in one line with the ones it has."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn import AtlasError, builtin_system, solve
from atlasnn.errors import ConfigError
from atlasnn.solver import GaussCollocation


@pytest.mark.long
def test_a_float64_solution_has_a_float64_residual(ho):
    # the field was evaluated in float32 (jnp.asarray outside x64): a residual of 1e-8 for a
    # solution accurate to 1e-13 told the user it was 1e5 times worse than it is
    sol = solve(ho, None, (0.0, 1.0))
    assert np.abs(sol.residual(np.linspace(0.0, 1.0, 7))).max() < 1e-10
    assert sol.residual(0.5).shape == (2,)


@pytest.mark.parametrize("t", [np.nan, [0.1, np.inf], "a"])
def test_times_that_are_not_finite_numbers_are_one_line(ho, t):
    sol = solve(ho, None, (0.0, 1.0))
    with pytest.raises(AtlasError, match="times must be finite numbers") as info:
        sol(t)
    assert "\n" not in str(info.value)


@pytest.mark.long
def test_a_given_length_that_cannot_converge_says_shorten_it_not_newton_when_newton_is_on():
    system = builtin_system("nonlinear_oscillator")
    with pytest.raises(AtlasError, match="try a shorter h") as info:
        solve(system, None, (0.0, 10.0), solver=GaussCollocation(h=3.0))
    assert "newton=True" not in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(AtlasError, match=r"the fixed-point iteration failed; newton=False\).*set newton=True"):
        solve(system, None, (0.0, 10.0), solver=GaussCollocation(h=3.0, newton=False))


@pytest.mark.parametrize("cls", ["GaussCollocation", "Collocation", "AdamMarch", "Transfer", "FlowMap",
                                 "NetworkBundle"])
def test_an_unknown_setting_is_one_line_naming_it_and_the_settings(cls):
    import atlasnn.solver as solvers

    with pytest.raises(ConfigError) as info:
        getattr(solvers, cls)(foo=1)
    msg = str(info.value)
    assert msg.startswith(f"{cls} has no setting 'foo'; its settings are ") and "\n" not in msg
    if cls == "GaussCollocation":
        assert "stages, rtol, atol, steps, h," in msg

"""Every solution `solve` returns saves and loads: the time-transformed one of the default on an
eccentric orbit too (evaluations bit-identical, the estimate back); a time scale given as a Python
function is refused in one line, the file never written."""

from __future__ import annotations

import math

import numpy as np
import pytest

from atlasnn import expression_system, load, save, solve
from atlasnn.errors import CheckpointError
from atlasnn.solutions import TimeTransformedSolution
from atlasnn.solver import GaussCollocation


def _kepler(e: float):
    return expression_system("(px**2 + py**2)/2 - 1/sqrt(qx**2 + qy**2)", ["qx", "qy"], ["px", "py"],
                             separable=True, z0=[1 - e, 0.0, 0.0, math.sqrt((1 + e) / (1 - e))], name="kepler")


def test_the_defaults_time_transformed_solution_round_trips(tmp_path):
    kepler = _kepler(0.99)
    T = 4 * 2 * math.pi
    sol = solve(kepler, None, (0.0, T), rtol=1e-9, atol=1e-11)
    assert isinstance(sol, TimeTransformedSolution)  # the default marched it in tau
    path = tmp_path / "kepler.npz"
    save(path, sol)
    back = load(path)
    assert isinstance(back, TimeTransformedSolution)
    t = np.linspace(0.0, T, 301)
    assert np.array_equal(back(t), sol(t)) and np.array_equal(back.derivative(t), sol.derivative(t))
    assert back.interval == sol.interval and back.info["time_scale"] == "potential"
    assert back.estimate().max_abs == pytest.approx(sol.estimate().max_abs, rel=1e-12)


def test_a_function_time_scale_is_refused_in_one_line(tmp_path):
    kepler = _kepler(0.6)
    scale = lambda q, p: (q[0] ** 2 + q[1] ** 2) ** 0.75  # noqa: E731
    sol = solve(kepler, None, (0.0, 2.0), solver=GaussCollocation(time_scale=scale))
    path = tmp_path / "kepler.npz"
    with pytest.raises(CheckpointError, match="Python function") as info:
        save(path, sol)
    assert "\n" not in str(info.value) and not path.exists()

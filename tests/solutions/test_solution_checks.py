"""A solution refuses a network whose state size is not its system's, naming both sizes."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.nn import make_model
from atlasnn.solutions import PiecewiseSolution, Solution
from atlasnn.systems import builtin_system


def test_solution_with_a_model_of_another_state_size_is_refused():
    hh = builtin_system("henon_heiles")  # 4 state components
    model = make_model(np.array([1.0, 0.0], np.float32), width=8, depth=1)
    with pytest.raises(ConfigError, match=r"has 2 state components but the system 'henon_heiles' has 4"):
        Solution(model, hh, (0.0, 1.0))


def test_piecewise_solution_names_the_window():
    hh = builtin_system("henon_heiles")
    good = make_model(np.zeros(4, np.float32), width=8, depth=1)
    bad = make_model(np.zeros(2, np.float32), width=8, depth=1)
    with pytest.raises(ConfigError, match="window 1's model has 2 state components"):
        PiecewiseSolution([good, bad], hh, np.array([0.0, 1.0, 2.0]))


def test_a_matching_model_is_accepted():
    osc = builtin_system("nonlinear_oscillator")
    model = make_model(np.array([1.3, 1.0], np.float32), width=8, depth=1)
    z = Solution(model, osc, (0.0, 1.0))(np.linspace(0, 1, 3))
    assert z.shape == (3, 2)

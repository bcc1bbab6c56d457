"""Solution outside its training interval: warn once, raise, or allow; unknown interval: silent."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from atlasnn.checkpoint import load_checkpoint, save_checkpoint
from atlasnn.errors import AtlasError
from atlasnn.nn import make_model
from atlasnn.solutions import ExtrapolationError, ExtrapolationWarning, Solution


@pytest.fixture
def model(ho):
    return make_model(ho.z0, scaling="tanh", width=4, depth=1)


def test_inside_is_silent_even_at_the_rounded_ends(model, ho):
    sol = Solution(model, ho, (0.0, 8 * np.pi))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sol(np.linspace(0.0, 8 * np.pi, 101))
        sol(8 * np.pi * (1 + 1e-12))  # rounding of an end point
        sol.energy(np.linspace(0.0, 8 * np.pi, 5))


def test_outside_warns_once_per_solution(model, ho):
    sol = Solution(model, ho, (0.0, 8 * np.pi))
    with pytest.warns(ExtrapolationWarning) as record:
        z = sol(np.linspace(0.0, 12 * np.pi, 7))
        sol(30 * np.pi)
        sol.derivative([-1.0])
        sol.energy([40.0])
    assert len(record) == 1
    msg = str(record[0].message)
    assert msg.startswith("evaluating the solution at times in [0, 37.6991], outside its training interval "
                          "[0, 25.1327]: values there are an extrapolation")
    assert z.shape == (7, 2)  # still evaluated
    assert issubclass(ExtrapolationWarning, UserWarning)
    with pytest.warns(ExtrapolationWarning):  # another Solution warns again
        Solution(model, ho, (0.0, 8 * np.pi))(-0.5)


def test_outside_raises_when_asked(model, ho):
    sol = Solution(model, ho, (1.0, 2.0), outside="raise")
    sol([1.0, 1.5, 2.0])
    with pytest.raises(ExtrapolationError) as info:
        sol([0.5, 1.5])
    assert isinstance(info.value, AtlasError) and isinstance(info.value, ValueError)
    assert str(info.value) == ("evaluating the solution at times in [0.5, 1.5], outside its training interval "
                               "[1, 2]: values there are an extrapolation (Solution(..., outside='allow') permits it)")
    with pytest.raises(ExtrapolationError):
        sol.residual([3.0])


def test_allow_and_unknown_interval_are_silent(model, ho):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Solution(model, ho, (0.0, 1.0), outside="allow")(np.linspace(-5, 50, 11))
        Solution(model, ho)(np.linspace(-5, 50, 11))
        Solution(model, ho, outside="raise")(100.0)


def test_bad_options(model, ho):
    with pytest.raises(ValueError, match="outside must be one of"):
        Solution(model, ho, (0.0, 1.0), outside="ignore")
    with pytest.raises(ValueError, match="t0 < T"):
        Solution(model, ho, (1.0, 1.0))
    with pytest.raises(ValueError, match="interval must be"):
        Solution(model, ho, (0.0,))


def test_checkpoint_solution_knows_its_interval(model, ho, tmp_path):
    path = tmp_path / "m.npz"
    save_checkpoint(path, model, ho, extra={"interval": [0.0, 4.0]})
    ck = load_checkpoint(path)
    assert ck.solution().interval == (0.0, 4.0)
    with pytest.warns(ExtrapolationWarning, match=r"\[0, 4\]"):
        ck.solution()(5.0)
    with pytest.raises(ExtrapolationError):
        ck.solution(outside="raise")(5.0)


@pytest.mark.parametrize("t", [np.nan, [0.1, -np.inf], "a"])
def test_times_that_are_not_finite_numbers_are_one_line_for_a_network_too(model, ho, t):
    with pytest.raises(AtlasError, match="times must be finite numbers"):
        Solution(model, ho, (0.0, 1.0))(t)

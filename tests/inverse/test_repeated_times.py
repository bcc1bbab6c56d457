"""Observations with repeated times (replicate measurements) are data like any other: every fit
method takes them."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.inverse import CollocationFit, Shooting, fit, synthetic_observations
from atlasnn.observations import Observations, Unknown
from atlasnn.systems import henon_heiles

HH = henon_heiles(lam=0.8)
LAM = [Unknown("lam", 0.9, 0.2, 1.5)]


def _replicated() -> Observations:
    """20 noisy (x, y) observations and a second measurement at three of their times."""
    obs = synthetic_observations(HH, None, np.linspace(0.5, 8.0, 20), ["x", "y"], 0.01, 0)
    again = synthetic_observations(HH, None, obs.t[5:8], ["x", "y"], 0.01, 1)
    return Observations.from_arrays(np.concatenate([obs.t, again.t]), np.concatenate([obs.values, again.values]),
                                    ["x", "y"])


@pytest.mark.long
@pytest.mark.parametrize("method", [CollocationFit(), CollocationFit(polish=False)], ids=["polished", "own"])
def test_the_collocation_fit_takes_repeated_observation_times(method):
    """Before, the collocation fit's starting spline raised SciPy's "`x` must be strictly increasing"."""
    obs = _replicated()
    assert np.any(np.diff(obs.t) == 0)
    shooting = fit(HH, obs, LAM, method=Shooting(starts=1))
    result = fit(HH, obs, LAM, method=method)
    assert result.trusted and abs(result.value("lam") - shooting.value("lam")) <= 2 * shooting.std[0]

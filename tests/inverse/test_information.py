"""What the data can tell a fit: values no unknown can change (at t0, of a component whose
initial value is known) inform nothing, count in no degree of freedom and no σ; a fit whose σ
says nothing is not trusted."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.inverse import (CollocationFit, FitResult, Joint, JointConfig, Shooting, fit, fit_shooting, flag_misfit,
                             synthetic_observations)
from atlasnn.observations import Observations, Unknown, fixed_values
from atlasnn.systems import expression_system

PENDULUM = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], params={"g": 1.3}, z0=[1.0, 0.0], name="pendulum")
G = [Unknown("g", 1.0, 0.5, 2.0)]


def _noisy(times, seed=0):
    return synthetic_observations(PENDULUM, None, np.asarray(times, float), ["x"], 0.01, seed)


def _with_known_start(obs: Observations) -> Observations:
    """``obs`` with the known initial value x(0) = z0 added as a first row."""
    return Observations.from_arrays(np.concatenate([[0.0], obs.t]),
                                    np.concatenate([[PENDULUM.initial_state()[0]], obs.values[:, 0]]), ["x"])


@pytest.mark.parametrize("method", [Shooting(starts=1), Shooting(starts=3), CollocationFit(),
                                    Joint(JointConfig(epochs=10, lm_steps=2))], ids=lambda m: type(m).__name__)
def test_the_known_initial_value_plus_one_point_is_refused_by_every_method(method):
    """Before, the guard counted two values for one unknown: the fit interpolated the one
    informative point and said g = 1.30 ± 5e-14, trusted."""
    obs = Observations.from_arrays([0.0, 2.0], [1.0, _noisy([2.0, 3.0]).values[0, 0]], ["x"])
    with pytest.raises(ConfigError) as ei:
        fit(PENDULUM, obs, G, method=method)
    msg = str(ei.value)
    assert len(msg.splitlines()) == 1 and "got 1" in msg and "at t0 = 0.0" in msg and "add observations" in msg


def test_the_initial_value_informs_when_it_is_an_unknown():
    obs = Observations.from_arrays([0.0, 2.0], [1.0, 0.5], ["x"])
    assert fixed_values(obs, G, 0.0).tolist() == [[True], [False]]
    assert fixed_values(obs, [*G, Unknown("z0.x", 1.0, 0.5, 1.5)], 0.0).tolist() == [[False], [False]]
    assert fixed_values(obs, G, -1.0).tolist() == [[False], [False]]  # a fit from an earlier t0


@pytest.mark.long
def test_a_known_start_row_changes_neither_the_estimate_nor_its_sigma():
    """Before, the row at t0 (residual 0) added a degree of freedom: σ shrank by √(4/3) here."""
    obs = _noisy([1.0, 2.0, 3.0, 4.5])
    plain, padded = fit_shooting(PENDULUM, obs, G), fit_shooting(PENDULUM, _with_known_start(obs), G)
    assert padded.value("g") == pytest.approx(plain.value("g"), rel=1e-6)
    assert padded.std[0] == pytest.approx(plain.std[0], rel=1e-3)
    assert padded.noise_estimate == pytest.approx(plain.noise_estimate, rel=1e-3)
    assert padded.n_data == plain.n_data == 4


def _result(noise, identifiable=True):
    return FitResult(names=("g",), estimate=np.array([1.3]), std=np.array([1e-12]), covariance=np.eye(1) * 1e-24,
                     noise_estimate=noise, residual_rms=noise, wall_time=0.0, n_rhs=0, n_solves=0, method="shooting",
                     success=True, message="", identifiable=identifiable, n_data=3)


def test_a_fit_through_the_data_has_no_sigma_and_is_not_trusted():
    obs = _noisy([1.0, 2.0, 3.0])
    flagged = flag_misfit(_result(0.0), obs)
    assert not flagged.trusted and np.isinf(flagged.std[0]) and any("no σ" in n for n in flagged.notes)
    assert flag_misfit(_result(1e-3), obs).trusted  # a residual of the noise's size: σ stands


def test_an_unidentifiable_unknown_makes_the_fit_untrusted():
    flagged = flag_misfit(_result(1e-3, identifiable=False), _noisy([1.0, 2.0, 3.0]))
    assert not flagged.trusted and any("not identifiable" in n for n in flagged.notes)

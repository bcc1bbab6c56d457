"""A Gauss march that cannot reach T keeps what it computed, and one that would not fit in memory
is stopped, with the projection and the remedy, before it takes the machine."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn import AtlasError, expression_system, solve, solve_batch
from atlasnn.solver import GaussCollocation
from atlasnn.solver import _gauss


def test_a_march_stopped_by_a_singularity_keeps_the_solution_up_to_the_stop():
    # H = p²/2 − q⁴/4 blows up in finite time (q' = p, p' = q³ from q = 1, p = 1/√2: t* = √2)
    blow = expression_system("p**2/2 - q**4/4", ["q"], ["p"], z0=[1.0, 2 ** -0.5])
    with pytest.raises(AtlasError, match="stopped at t = ") as info:
        solve(blow, None, (0.0, 3.0))
    part = info.value.partial
    assert "\n" not in str(info.value) and ".partial" in str(info.value)
    t_end = part.interval[1]
    assert 1.0 < t_end < 2 ** 0.5
    # up to the stop it is the exact solution q = 1/(1 − t/√2)
    t = np.linspace(0.0, 0.9, 50)
    assert np.abs(part(t)[:, 0] - 1.0 / (1.0 - t / 2 ** 0.5)).max() < 1e-9


def test_a_batch_with_one_member_that_fails_keeps_the_others():
    blow = expression_system("p**2/2 - q**4/4", ["q"], ["p"], z0=[1.0, 2 ** -0.5])
    with pytest.raises(AtlasError, match="of member 1") as info:
        solve_batch(blow, [[0.1, 0.0], [1.0, 2 ** -0.5], [0.0, 0.1]], (0.0, 3.0))
    first, failed, third = info.value.partial
    assert first.interval == (0.0, 3.0) and third.interval == (0.0, 3.0)
    assert failed.interval[1] < 3.0


def test_a_march_that_would_not_fit_in_memory_is_stopped_with_its_projection(ho, monkeypatch):
    monkeypatch.setattr(_gauss, "available_memory", lambda: 64 << 20)  # 64 MiB
    with pytest.raises(AtlasError, match=r"it would need about .* windows .* GiB.*shorten the interval") as info:
        solve(ho, None, (0.0, 1.0), solver=GaussCollocation(h=1e-9))
    assert "\n" not in str(info.value)
    assert info.value.partial.interval[1] > 0.0  # what it did is kept


# ------------------------------------------------------------------ messages that send the user the right way
def _kepler(e: float):
    return expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                             z0=[1 - e, 0.0, 0.0, ((1 + e) / (1 - e)) ** 0.5])


@pytest.mark.parametrize("stages", [15, 16])
def test_a_tolerance_below_round_off_counts_as_round_off_at_every_stage_count(stages):
    """rtol 1e-15, atol 0 on a circular orbit: stopped at t = 0 before ("loosen the tolerance, or the
    system may be singular"), a component through zero whose check's own rounding, summed over
    s + 1 coefficients, exceeded 8 ulps."""
    sol = solve(_kepler(0.0), None, (0.0, 10.0), solver=GaussCollocation(stages=stages, rtol=1e-15, atol=0.0))
    t = np.linspace(0.0, 10.0, 201)
    exact = np.stack([np.cos(t), np.sin(t), -np.sin(t), np.cos(t)], axis=-1)
    assert np.abs(sol(t) - exact).max() < 1e-13
    assert sol.n_windows < 100

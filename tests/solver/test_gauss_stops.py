"""A Gauss march that cannot reach T keeps what it computed, and one that would not fit in memory
is stopped, with the projection and the remedy, before it takes the machine."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn import AtlasError, expression_system, solve, solve_batch
from atlasnn.checkpoint import load_piecewise, save_piecewise
from atlasnn.solver import GaussCollocation
from atlasnn.solver import _gauss


@pytest.mark.long
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


@pytest.mark.long
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


@pytest.mark.long
@pytest.mark.parametrize("t0", [1.7e9, 1e12, -3e10])
def test_an_interval_far_from_zero_is_solved_as_accurately_as_one_at_zero(t0, tmp_path):
    """[t0, t0 + 40] far from 0 (a Unix time, 1e12): the float64 times are 2.4e-7 … 1.2e-4 apart
    there, so the window edges are the float64 numbers and the offsets they leave out; evaluated at
    float64 times, the oscillator is as accurate as at t0 = 0, the estimate says so, and a saved
    solution keeps the offsets. (At 1e12 windows shortened after a rejection were once stretched
    back to the whole rest of the interval, a slack of 1e-12·|T| = 1, until the march gave up.)"""
    sol = solve(expression_system("p**2/2 + q**2/2", ["q"], ["p"]), [1.0, 0.0], (t0, t0 + 40.0))
    t = t0 + np.linspace(0.0, 40.0, 201)
    exact = np.stack([np.cos(t - t0), -np.sin(t - t0)], axis=-1)
    error = np.abs(sol(t) - exact).max()
    assert error < 1e-11  # at t0 = 0 about 1.5e-13; placed by the rounded edges alone: 1e-7 … 1e-4
    assert error <= 3 * sol.estimate().max_abs <= 3e-11
    assert np.abs(sol.offsets).max() > 0.0
    save_piecewise(tmp_path / "far.npz", sol)
    assert np.array_equal(load_piecewise(tmp_path / "far.npz")(t), sol(t))


def test_a_march_stopped_by_the_rounding_of_time_says_so_with_the_digits_that_tell_the_ends_apart():
    with pytest.raises(AtlasError) as info:
        solve(_kepler(0.9), None, (1e13, 1e13 + 20.0))
    msg = str(info.value)
    assert "\n" not in msg and "of [1e+13, 1.000000000002e+13]" in msg
    assert "float64 numbers 0.00195 apart" in msg and "give h" in msg and "loosen the tolerance" not in msg


def test_a_fixed_point_failure_with_newton_off_says_so_and_suggests_newton():
    stiff = expression_system("p**2/2 + 1e6*q**2/2", ["q"], ["p"], z0=[1.0, 0.0])
    with pytest.raises(AtlasError) as info:
        solve(stiff, None, (0.0, 10.0), solver=GaussCollocation(newton=False, h=0.1))
    msg = str(info.value)
    assert "the fixed-point iteration failed; newton=False" in msg and "set newton=True" in msg
    assert "Newton iterations both failed" not in msg


def test_too_few_iterations_say_raise_max_iterations_not_shorten_h():
    with pytest.raises(AtlasError) as info:
        solve(_kepler(0.0), None, (0.0, 10.0), solver=GaussCollocation(max_iterations=3, h=0.5))
    msg = str(info.value)
    assert "raise max_iterations (3; the default is 100)" in msg and "shorter h" not in msg


def test_a_field_that_is_not_finite_at_z0_is_one_line_before_any_window():
    system = expression_system("p**2/2 + sqrt(q - 2)", ["q"], ["p"])
    with pytest.raises(AtlasError) as info:
        solve(system, [1.0, 0.0], (0.0, 10.0))
    msg = str(info.value)
    assert msg.startswith("the Gauss march cannot start: the vector field J∇H is not finite at z0 = [1.0, 0.0]")
    assert "\n" not in msg and "did not converge" not in msg and ".partial" not in msg
    assert info.value.partial is None


@pytest.mark.parametrize("expression, cause, when", [
    ("p**2/2 - q**4/4", "the field grew", 1.8541),  # q'' = q³ from (1, 0) blows up at t = 1.85407
    ("p**2/2 + sqrt(2 - q)", "not finite just ahead along the flow", None),  # H is NaN past q = 2
], ids=["blow-up", "nan-ahead"])
def test_a_field_that_blows_up_or_turns_nan_on_the_way_is_named_not_round_off(expression, cause, when):
    """The march stops where the field fails, and says so rather than blaming the rounding of t;
    what was reached is kept."""
    system = expression_system(expression, ["q"], ["p"])
    with pytest.raises(AtlasError) as info:
        solve(system, [1.0, 0.0], (0.0, 3.0))
    msg = str(info.value)
    assert cause in msg and "float64 numbers" not in msg and "\n" not in msg
    part = info.value.partial
    assert part is not None and part.edges[-1] < 3.0
    if when is not None:
        assert abs(part.edges[-1] - when) < 1e-3

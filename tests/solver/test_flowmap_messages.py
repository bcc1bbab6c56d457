"""The flow map's refusals: numbers as numbers (not np.float64(…)), and a box too large for the
window length named with its cause and remedy (before: "is H conserved and the region right?")."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.solver import FlowMap, solve_bundle
from atlasnn.systems import BundleBox, nonlinear_oscillator

OSC = nonlinear_oscillator()
SMALL = FlowMap(windows=4, time_degree=3, state_degree=4, param_degree=2)


@pytest.mark.parametrize("kw, shown", [({"windows": np.int64(0)}, "got 0"), ({"shell_margin": np.float64(-1.0)}, "got -1.0"),
                                       ({"oversampling": np.float32(0.5)}, "got 0.5")])
def test_settings_given_as_numpy_numbers_are_shown_as_numbers(kw, shown):
    with pytest.raises(ConfigError) as ei:
        FlowMap(**kw)
    assert shown in str(ei.value) and "np." not in str(ei.value)
    assert FlowMap(oversampling=np.float32(1.5)).oversampling == 1.5  # a NumPy float is a number too


@pytest.mark.long
def test_a_member_outside_the_region_is_refused_with_plain_numbers():
    box = BundleBox.around(OSC.z0, 0.1, {"lam": (0.9, 1.1)}, T=1.0)
    bundle = solve_bundle(OSC, box, SMALL)
    with pytest.raises(ConfigError) as ei:
        bundle(np.array([0.5]), np.array([[10.0, 0.0]]), np.array([[1.0]]))
    msg = str(ei.value)
    assert "lies outside the region" in msg and "np.float64" not in msg and "z0 = [10, 0]" in msg


@pytest.mark.long
def test_a_box_too_large_for_the_windows_names_the_cause_and_the_remedy():
    box = BundleBox.around(OSC.z0, 3.0, {"lam": (0.5, 1.5)}, T=4 * np.pi)
    with pytest.raises(ConfigError) as ei:
        solve_bundle(OSC, box, FlowMap(windows=24, time_degree=3, state_degree=5, param_degree=2))
    msg = str(ei.value)
    assert len(msg.splitlines()) == 1 and "far off the box's energy shell" in msg
    assert "more windows than 24" in msg and "smaller box" in msg and "np." not in msg

"""The built-ins' NumPy fields (for SciPy's integrators at their best) are the systems' own J∇H."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from atlasnn.evaluation import reference_rhs
from atlasnn.systems import BUILTIN_SYSTEMS, builtin_system, expression_system, numpy_field


@pytest.mark.parametrize("name", sorted(BUILTIN_SYSTEMS))
def test_each_written_field_is_the_systems_own(name):
    rng = np.random.default_rng(7)
    params = {k: float(rng.uniform(0.3, 2.0)) for k in builtin_system(name).params}
    system = builtin_system(name, **params)
    field = numpy_field(system)
    assert field is not None, f"{name}: no NumPy field written"
    for z in rng.standard_normal((5, system.state_dim)):
        want = reference_rhs(system)(0.0, z)
        # to round-off of the field's size (a spectral derivative's FFT rounds relative to its largest entry)
        assert np.allclose(field(0.0, z), want, rtol=1e-14, atol=1e-14 * max(1.0, float(np.max(np.abs(want)))))


def test_a_system_without_one_gets_none():
    assert numpy_field(expression_system("p**2/2 - cos(q)", ["q"], ["p"])) is None
    # a built-in whose Hamiltonian was replaced is no longer the one its spec builds
    hh = builtin_system("henon_heiles")
    other = dataclasses.replace(hh, hamiltonian=lambda q, p: (p[0] ** 2 + p[1] ** 2) / 2)
    assert numpy_field(other) is None

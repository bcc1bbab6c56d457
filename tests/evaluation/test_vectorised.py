"""The member-vectorised symplectic integrators: order, agreement with the DOP853 reference,
shapes and chunking, and one-line errors for bad input."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.errors import ConfigError, SystemError_
from atlasnn.evaluation import MemberRun, _vectorised, reference_members, verlet_members, yoshida4_members
from atlasnn.systems import BundleBox, builtin_system, expression_system, harmonic_exact


@pytest.fixture(scope="module")
def harmonic():
    system = builtin_system("harmonic_oscillator")
    box = BundleBox.around([1.0, 0.5], 0.2, {"omega": (0.8, 1.2)}, T=4.0)
    z0, lam = box.draw(np.random.default_rng(3), 6)
    t = np.array([1.0, 2.0, 3.0, 4.0])
    exact = np.stack([harmonic_exact(t, z, w) for z, w in zip(z0, lam[:, 0])])
    return system, box, z0, lam, t, exact


@pytest.fixture(scope="module")
def oscillator():
    system = builtin_system("nonlinear_oscillator")
    box = BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=4 * np.pi)
    return system, box


def _error(fn, case, spu):
    system, box, z0, lam, t, exact = case
    return float(np.abs(fn(system, box, z0, lam, t, spu).z - exact).max())


@pytest.mark.parametrize("fn, order", [(yoshida4_members, 4), (verlet_members, 2)])
def test_order_on_the_harmonic_oscillator(harmonic, fn, order):
    coarse, fine = _error(fn, harmonic, 10), _error(fn, harmonic, 20)
    observed = np.log2(coarse / fine)
    assert abs(observed - order) < 0.15, (coarse, fine, observed)


def test_yoshida_matches_the_reference(oscillator):
    system, box = oscillator
    z0, lam = box.draw(np.random.default_rng(0), 5)
    t = np.linspace(0.0, box.T, 13)
    ref = reference_members(system, box, z0, lam, t)
    run = yoshida4_members(system, box, z0, lam, t, 800)
    assert np.abs(run.z - ref).max() < 1e-8


def test_shapes_steps_and_evaluations(oscillator):
    system, box = oscillator
    z0, lam = box.draw(np.random.default_rng(1), 3)
    t = np.array([0.0, 0.5, 0.5, 2.0, box.T])
    y = yoshida4_members(system, box, z0, lam, t, 4)
    v = verlet_members(system, box, z0, lam, t, 4)
    assert isinstance(y, MemberRun)
    assert y.z.shape == v.z.shape == (3, 5, 2) and y.z.dtype == np.float64
    np.testing.assert_array_equal(y.z[:, 0], z0)  # t = t0 is the initial state itself
    np.testing.assert_array_equal(y.z[:, 1], y.z[:, 2])  # a repeated time takes no step
    expected = 2 + 0 + 6 + int(np.ceil((box.T - 2.0) * 4))
    assert y.steps == v.steps == expected
    assert (y.force_evaluations, v.force_evaluations) == (1 + 3 * expected, 1 + expected)


@pytest.mark.parametrize("blocks_per_call", [2, 3])
def test_blocks_and_chunks_agree_with_one_call(oscillator, monkeypatch, blocks_per_call):
    system, box = oscillator
    z0, lam = box.draw(np.random.default_rng(2), 11)
    t = np.linspace(0.0, 2.0, 6)
    whole = yoshida4_members(system, box, z0, lam, t, 8).z
    # 11 members in blocks of 3 (padded to 12): calls of 6 + 6, or of 9 + 3
    monkeypatch.setattr(_vectorised, "MEMBER_BLOCK", 3)
    monkeypatch.setattr(_vectorised, "CHUNK_BYTES", blocks_per_call * 3 * t.size * 2 * 8)
    split = yoshida4_members(system, box, z0, lam, t, 8).z
    assert split.shape == whole.shape
    np.testing.assert_allclose(split, whole, rtol=0, atol=1e-14)


def _one_line(exc_info) -> str:
    msg = str(exc_info.value)
    assert "\n" not in msg
    return msg


def test_non_separable_system_is_refused():
    system = expression_system("p**2/2 + q**2/2 + q*p", ["q"], ["p"], {}, separable=False, z0=[1, 0])
    box = BundleBox((0.9, -0.1), (1.1, 0.1), T=1.0)
    z0 = np.array([[1.0, 0.0], [0.95, 0.05]])
    for fn in (yoshida4_members, verlet_members):
        with pytest.raises(SystemError_) as err:  # as the single-trajectory integrators
            fn(system, box, z0, None, [0.5, 1.0], 10)
        assert "separable" in _one_line(err)


def test_a_box_without_parameters_works():
    system = builtin_system("harmonic_oscillator")
    box = BundleBox((0.9, -0.1), (1.1, 0.1), T=1.0)
    z0 = np.array([[1.0, 0.0], [0.95, 0.05]])
    run = yoshida4_members(system, box, z0, None, [0.5, 1.0], 50)
    exact = np.stack([harmonic_exact([0.5, 1.0], z) for z in z0])
    assert np.abs(run.z - exact).max() < 1e-8


@pytest.mark.parametrize("change, words", [
    ({"t": [1.0, 0.5]}, "sorted"),
    ({"t": [-1.0, 0.5]}, "t0"),
    ({"t": []}, "non-empty"),
    ({"t": [0.5, np.nan]}, "finite"),
    ({"spu": 0}, "steps_per_unit"),
    ({"spu": True}, "steps_per_unit"),
    ({"z0": np.zeros((2, 3))}, "shape"),
    ({"lam": np.ones((3, 1))}, "lam"),
])
def test_bad_input_is_one_line(oscillator, change, words):
    system, box = oscillator
    args = {"z0": np.array([[1.3, 1.0], [1.2, 0.9]]), "lam": np.array([[1.0], [0.7]]), "t": [0.5, 1.0], "spu": 10}
    args.update(change)
    with pytest.raises(ConfigError) as err:
        verlet_members(system, box, args["z0"], args["lam"], args["t"], args["spu"])
    assert words in _one_line(err)

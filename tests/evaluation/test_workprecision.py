"""Work–precision points of the classical methods, and the comparison with a network point."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.evaluation import _workprecision as wp
from atlasnn.systems import harmonic_exact, harmonic_oscillator


@pytest.fixture(scope="module")
def problem():
    system = harmonic_oscillator()
    t = np.linspace(0.0, 4 * np.pi, 101)
    return system, system.z0, t, harmonic_exact(t, system.z0)


def test_symplectic_points_converge_at_their_order(problem):
    system, z0, t, z_ref = problem
    pts = wp.symplectic_points(system, z0, t, z_ref, multiples=(1, 2, 4), min_seconds=0.0)
    assert [p.setting for p in pts[:3]] == ["N=100", "N=200", "N=400"]
    for method, order in (("symplectic_euler", 1), ("stormer_verlet", 2), ("yoshida4", 4)):
        err = [p.max_error for p in pts if p.method == method]
        rates = np.log2(np.array(err[:-1]) / np.array(err[1:]))
        assert rates == pytest.approx([order, order], abs=0.35), method
    assert all(p.seconds > 0 and p.kind == "classical" for p in pts)


def test_dop853_tighter_tolerance_is_more_accurate(problem):
    system, z0, t, z_ref = problem
    loose, tight = wp.dop853_points(system, z0, t, z_ref, tolerances=(1e-4, 1e-9), min_seconds=0.0)
    assert tight.max_error < loose.max_error / 100
    assert loose.setting == "tol=0.0001"


def test_errors_by_hand(problem):
    system, z0, t, z_ref = problem
    z = z_ref.copy()
    z[:, 0] += 0.01
    z[5, 1] -= 0.5
    e = wp.errors(system, z, z_ref, 0.5)
    assert e["max_error"] == pytest.approx(0.5)
    assert e["l2_first"] == pytest.approx(0.01 * np.sqrt(len(t)))
    energy = (z[:, 0] ** 2 + z[:, 1] ** 2) / 2
    assert e["energy_drift"] == pytest.approx(np.max(np.abs(energy - 0.5)) / 0.5)


def test_cheapest_match_and_verdicts():
    pts = [wp.WorkPoint("stormer_verlet", "N=10", 1.0, 1e-2, 1e-1, 0.0),
           wp.WorkPoint("yoshida4", "N=10", 2.0, 1e-5, 1e-4, 0.0),
           wp.WorkPoint("yoshida4", "N=20", 0.5, 1e-3, 1e-2, 0.0)]
    net = wp.WorkPoint("ATLAS-NN", "seed 0", 50.0, 5e-3, 5e-2, 0.0, kind="network")
    assert wp.cheapest_match(pts, net).setting == "N=20"  # 1e-3 <= 5e-3, and the fastest
    better = wp.WorkPoint("ATLAS-NN", "seed 1", 50.0, 1e-9, 1e-8, 0.0, kind="network")
    assert wp.cheapest_match(pts, better) is None
    lines = wp.verdicts(pts + [net, better])
    assert "Yoshida-4 (N=20) reaches 0.001 in 0.5 s (100x cheaper)" in lines[0]
    assert "no classical setting measured is that accurate" in lines[1]


def test_plot_writes_png_and_pdf(problem, tmp_path):
    system, z0, t, z_ref = problem
    pts = wp.symplectic_points(system, z0, t, z_ref, multiples=(1, 2), min_seconds=0.0)
    pts.append(wp.network_point("net", "seed 0", 3.0, system, z_ref + 1e-3, z_ref, 0.5))
    from atlasnn.report import plot_work_precision

    from atlasnn.report import figure_formats

    assert [p.suffix for p in plot_work_precision(tmp_path / "png", pts, title="t")] == [".png"]  # the default
    with figure_formats("png", "pdf"):
        paths = plot_work_precision(tmp_path / "wp", pts, title="t")
    assert [p.suffix for p in paths] == [".png", ".pdf"] and all(p.stat().st_size > 5000 for p in paths)


@pytest.mark.slow  # a timing: 6.6x under CI's two busy workers, 2.9-4x on a quiet machine (run with -m slow)
def test_dop853_timings_are_not_dominated_by_dispatch():
    """DOP853 through atlasnn's compiled right-hand side against the same solve with a hand-written
    NumPy one (the cheapest a Python right-hand side can be): same steps, and a time within 6× (it
    was 9–10× in round 2; 2.9–4× measured here with two other processes busy, docs/PERFORMANCE.md)."""
    import math
    import time

    from scipy.integrate import solve_ivp

    from atlasnn.systems import henon_heiles

    system = henon_heiles()
    z0 = np.array([0.3, -0.3, 0.3, 0.15])
    t = np.linspace(0.0, 24 * math.pi, 500)

    def numpy_rhs(_, z):
        x, y, px, py = z
        return np.array([px, py, -x - 2 * x * y, -y - x * x + y * y])

    def best(fn, repeats=5):
        out, times = None, []
        for _ in range(repeats):
            start = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - start)
        return out, min(times)

    (z, nfev), ours = best(lambda: wp.dop853(system, z0, t, 1e-10, 1e-10))
    ref, plain = best(lambda: solve_ivp(numpy_rhs, (0.0, t[-1]), z0, method="DOP853", t_eval=t, rtol=1e-10, atol=1e-10))
    assert nfev == ref.nfev and np.allclose(z, ref.y.T, rtol=0, atol=1e-9)
    points = wp.dop853_points(system, z0, t, ref.y.T, tolerances=(1e-10,), min_seconds=0.0)
    assert points[0].evaluations == nfev
    assert ours < 6 * plain, f"DOP853 {ours:.3f} s with atlasnn's right-hand side, {plain:.3f} s with NumPy"

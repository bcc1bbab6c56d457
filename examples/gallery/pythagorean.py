"""The Pythagorean three-body problem (Burrau 1913; Szebehely and Peters 1967): masses 3, 4 and 5 at
rest at the vertices of a 3-4-5 right triangle, each opposite the side of its own length (G = 1),
solved by ``atlasnn.solve`` at its defaults, which switch by themselves to a march in a fictitious
time (``time_scale="potential"``) once they meet the close encounters. The relative energy error
along the dense output, and the close encounters (a pair's distance at a local minimum below 0.1,
located on the dense output): the closest, at t ≈ 15.83, brings two bodies within 4e-4. At full
size the run goes past t ≈ 60, where the bodies of masses 4 and 5 leave as a binary and that of mass
3 escapes the other way.

    python examples/gallery/pythagorean.py --T 70 --figure docs/figures/gallery/pythagorean.png
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import minimize_scalar

import atlasnn

MASSES = (3.0, 4.0, 5.0)
PAIRS = ((0, 1), (0, 2), (1, 2))


# --8<-- [start:system]
def pythagorean_system():
    """H = Σ |p_i|²/(2 m_i) − Σ m_i m_j / r_ij in the plane, q = (x1, y1, x2, y2, x3, y3)."""
    kinetic = " + ".join(f"(px{i + 1}**2 + py{i + 1}**2)/{2 * MASSES[i]:g}" for i in range(3))
    potential = " - ".join(f"{MASSES[i] * MASSES[j]:g}/sqrt((x{i + 1} - x{j + 1})**2 + (y{i + 1} - y{j + 1})**2)"
                           for i, j in PAIRS)
    q = [f"{c}{i + 1}" for i in range(3) for c in "xy"]
    return atlasnn.expression_system(f"{kinetic} - {potential}", q, ["p" + n for n in q],
                                     z0=[1.0, 3.0, -2.0, -1.0, 1.0, -1.0] + [0.0] * 6,  # at rest
                                     separable=True, name="pythagorean")


def pythagorean_run(T: float):
    """The solution over [0, T] at the defaults, its states at 2 000 times a unit of time, and the
    relative energy error at those times."""
    system = pythagorean_system()
    sol = atlasnn.solve(system, None, (0.0, T))  # the defaults
    t = np.linspace(0.0, T, int(2000 * T) + 1)
    z = sol(t)
    drift = np.abs(system.energy64(z) / system.energy64(system.z0) - 1)
    return system, sol, t, z, drift
# --8<-- [end:system]


def distance(z: np.ndarray, i: int, j: int) -> np.ndarray:
    """The distance between bodies i and j in states z (…, 12)."""
    return np.hypot(z[..., 2 * i] - z[..., 2 * j], z[..., 2 * i + 1] - z[..., 2 * j + 1])


def encounters(sol, t: np.ndarray, z: np.ndarray, below: float = 0.1) -> list[tuple[float, float, int, int]]:
    """(time, distance, i, j) of every local minimum of a pair's distance below `below`: found on
    the samples, then located on the dense output (Brent's method between the neighbouring samples)."""
    found = []
    for i, j in PAIRS:
        r = distance(z, i, j)
        for k in np.nonzero((r[1:-1] < r[:-2]) & (r[1:-1] <= r[2:]) & (r[1:-1] < below))[0] + 1:
            best = minimize_scalar(lambda s, i=i, j=j: float(distance(sol(np.asarray([s]))[0], i, j)),
                                   bounds=(t[k - 1], t[k + 1]), method="bounded", options={"xatol": 1e-13})
            found.append((float(best.x), float(best.fun), i, j))
    return sorted(found)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--T", type=float, default=70.0)
    parser.add_argument("--figure", default="pythagorean.png")
    args = parser.parse_args(argv)
    system, sol, t, z, drift = pythagorean_run(args.T)
    H0 = system.energy64(system.z0)
    tic = time.perf_counter()
    close = encounters(sol, t, z)
    seconds = time.perf_counter() - tic
    at_close = np.abs(system.energy64(sol(np.asarray([c[0] for c in close]))) / H0 - 1) if close else np.zeros(1)
    march = "in τ (time_scale='potential', chosen by the defaults)" if "time_scale_chosen" in sol.info else "in t"
    print(f"t in [0, {args.T:g}]: {sol.n_windows} windows, marched {march}")
    print(f"max |H/H0 − 1| = {drift.max():.1e} along the dense output, {drift[-1]:.0e} at T")
    if close:
        tc, rc, i, j = min(close, key=lambda c: c[1])
        print(f"{len(close)} close encounters (< 0.1) located in {seconds:.1f} s, the closest at t = {tc:.4f}: "
              f"masses {MASSES[i]:g} and {MASSES[j]:g} {rc:.1e} apart")
    assert drift.max() < 1e-8 and at_close.max() < 1e-8, "the energy is not kept through the encounters"
    if args.T > 16:  # the closest approach, at t ≈ 15.83: masses 4 and 5, 4.1e-4 apart
        tc, rc, *_ = min(close, key=lambda c: c[1])
        assert abs(tc - 15.83) < 0.01 and rc < 1e-3, "the closest approach is not where it should be"

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(9, 4.2))
    orbits = fig.add_subplot(1, 2, 1)
    for b in range(3):
        orbits.plot(z[:, 2 * b], z[:, 2 * b + 1], lw=0.5, color=f"C{b}", label=f"m = {MASSES[b]:g}")
        orbits.plot(z[0, 2 * b], z[0, 2 * b + 1], "o", color=f"C{b}", ms=5)
        orbits.plot(z[-1, 2 * b], z[-1, 2 * b + 1], "x", color=f"C{b}", ms=6)
    orbits.set_aspect("equal", adjustable="datalim")
    orbits.set_xlabel("x")
    orbits.set_ylabel("y")
    orbits.set_title(f"t ∈ [0, {args.T:g}] (o start, x end)")
    orbits.legend(fontsize=8, loc="lower left")
    closest = fig.add_subplot(2, 2, 2)
    closest.semilogy(t, np.min([distance(z, i, j) for i, j in PAIRS], axis=0), lw=0.6, color="0.3")
    closest.plot([c[0] for c in close], [c[1] for c in close], "r.", ms=4, label="encounters, located")
    closest.set_ylabel("closest pair's distance")
    closest.legend(fontsize=8, loc="lower right")
    energy = fig.add_subplot(2, 2, 4, sharex=closest)
    energy.semilogy(t, np.maximum(drift, 1e-17), lw=0.5)
    energy.set_xlabel("t")
    energy.set_ylabel("|H/H0 − 1|")
    closest.set_title(f"atlasnn.solve, defaults: {sol.n_windows} windows")
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()

"""A Poincaré section of Hénon–Heiles at energy E = 1/8: orbits started on x = 0 with p_y = 0 and
p_x > 0 from the energy, marched together by ``atlasnn.solve_batch``; each orbit's crossings of
x = 0 with p_x > 0 found on its dense output (sign changes, then Newton steps t ← t − x/p_x on the
polynomial windows) and drawn as (y, p_y): invariant curves of the regular orbits, a scattered sea
of the chaotic ones. The energy of every point is checked against E.

    python examples/gallery/henon_heiles_section.py --orbits 24 --T 3000 --figure docs/figures/gallery/henon_heiles_section.png
"""

from __future__ import annotations

import argparse

import numpy as np

import atlasnn
from atlasnn import builtin_system

E = 1.0 / 8.0


# --8<-- [start:section]
def crossings(sol, T: float, dt: float = 0.05) -> np.ndarray:
    """The states where x passes 0 upwards (p_x > 0) along a solution, to round-off."""
    t = np.arange(0.0, T, dt)
    x = sol(t)[:, 0]
    k = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    tc = t[k] - x[k] * dt / (x[k + 1] - x[k])  # the chord's zero
    for _ in range(3):  # Newton on the dense output: ẋ = p_x
        z = sol(tc)
        tc = tc - z[:, 0] / z[:, 2]
    return sol(tc)


hh = builtin_system("henon_heiles")


def section(orbits: int, T: float) -> list[np.ndarray]:
    """Each orbit's crossings, the orbits started on x = 0 with p_y = 0, y evenly spaced, and p_x
    from the energy; marched together by solve_batch."""
    y0 = np.linspace(-0.3, 0.45, orbits)
    px0 = np.sqrt(2 * E - y0 ** 2 + 2 * y0 ** 3 / 3)  # H = E at x = 0, p_y = 0
    starts = np.stack([np.zeros_like(y0), y0, px0, np.zeros_like(y0)], axis=1)
    sols = atlasnn.solve_batch(hh, starts, (0.0, T))
    return [crossings(sol, T) for sol in sols]
# --8<-- [end:section]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--orbits", type=int, default=12)
    parser.add_argument("--T", type=float, default=500.0)
    parser.add_argument("--figure", default="henon_heiles_section.png")
    args = parser.parse_args(argv)
    points = section(args.orbits, args.T)
    worst = max(np.max(np.abs(hh.energy64(p) - E)) for p in points)
    on_section = max(np.max(np.abs(p[:, 0])) for p in points)
    print(f"{args.orbits} orbits to t = {args.T:g}: {sum(len(p) for p in points)} crossings, |x| ≤ {on_section:.1e} "
          f"there, |H − E| ≤ {worst:.1e}")
    assert worst < 1e-10 and on_section < 1e-10

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 5))
    for m, p in enumerate(points):
        ax.plot(p[:, 1], p[:, 3], ".", ms=0.8, color=plt.cm.tab20(m % 20))
    ax.set_xlabel("y")
    ax.set_ylabel("p_y")
    ax.set_title(f"Hénon–Heiles, E = 1/8: x = 0, p_x > 0 ({args.orbits} orbits, t ≤ {args.T:g})")
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()

"""Kepler's problem, e = 0.6, over many periods: the relative energy error along the dense output of
``atlasnn.solve`` at its defaults (the Gauss method: symplectic, the error bounded), beside SciPy's
DOP853 at rtol 1e-10 (not symplectic: its error grows with t), which runs over at most 1 000 periods.

    python examples/gallery/kepler_energy.py --periods 100000 --figure docs/figures/gallery/kepler_energy.png
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.integrate import solve_ivp

import atlasnn

E = 0.6


def energy(z: np.ndarray) -> np.ndarray:
    return 0.5 * (z[..., 2] ** 2 + z[..., 3] ** 2) - 1.0 / np.hypot(z[..., 0], z[..., 1])


def field(t, z):
    r3 = np.hypot(z[0], z[1]) ** 3
    return np.array([z[2], z[3], -z[0] / r3, -z[1] / r3])


# --8<-- [start:solve]
kepler = atlasnn.expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                                   z0=[1 - E, 0.0, 0.0, np.sqrt((1 + E) / (1 - E))], separable=True)


def energy_error(periods: int):
    """atlasnn.solve at its defaults over `periods` periods (a = 1: the period is 2π), and the
    relative energy error along its dense output at 8 000 times, log- and evenly spaced."""
    T = 2 * np.pi * periods
    sol = atlasnn.solve(kepler, None, (0.0, T))
    t = np.unique(np.concatenate([np.geomspace(1.0, T, 4000), np.linspace(0.0, T, 4000)]))
    return sol, t, np.abs(energy(sol(t)) / energy(np.asarray(kepler.z0)) - 1)
# --8<-- [end:solve]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--periods", type=int, default=1000)
    parser.add_argument("--figure", default="kepler_energy.png")
    args = parser.parse_args(argv)
    tic = time.perf_counter()
    sol, t, gauss = energy_error(args.periods)
    seconds = time.perf_counter() - tic
    T_rk = 2 * np.pi * min(args.periods, 1000)
    t_rk = t[t <= T_rk]
    rk = solve_ivp(field, (0.0, T_rk), np.asarray(kepler.z0), method="DOP853", t_eval=t_rk, rtol=1e-10, atol=1e-12)
    dop = np.abs(energy(rk.y.T) / energy(np.asarray(kepler.z0)) - 1)
    print(f"{args.periods} periods: atlasnn {sol.n_windows} windows (solved and evaluated in {seconds:.2f} s), "
          f"max |ΔH/H| = {gauss.max():.1e}; "
          f"DOP853 (rtol 1e-10) over {min(args.periods, 1000)} periods: {dop.max():.1e}")
    assert gauss.max() < 1e-11

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6))
    periods = t / (2 * np.pi)
    ax.loglog(periods[1:], np.maximum(gauss[1:], 1e-17), lw=0.6, label="atlasnn.solve, defaults (Gauss, s = 16)")
    ax.loglog(t_rk[1:] / (2 * np.pi), np.maximum(dop[1:], 1e-17), lw=0.6, label="SciPy DOP853, rtol 1e-10")
    ax.set_xlabel("periods")
    ax.set_ylabel("|H(t) / H(0) − 1|")
    ax.set_title(f"Kepler, e = {E}: the energy along the dense output")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()

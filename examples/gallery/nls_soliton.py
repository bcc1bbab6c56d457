"""The NLS soliton: the focusing cubic Schrödinger equation i ψ_t + ½ψ_xx + |ψ|²ψ = 0 on a periodic
Fourier grid (``atlasnn.systems.nls``, its stiff linear part declared), from its moving soliton
(amplitude 1, speed ≈ 1), solved by ``atlasnn.solve`` at its defaults. Along the dense output: the
discrete mass Σ q² + p² (a quadratic invariant, which the Gauss method keeps to round-off), the
energy H, and the distance to the exact soliton (``nls_soliton``), which at full size travels once
around the domain and more. Each is checked.

    python examples/gallery/nls_soliton.py --points 512 --length 64 --T 70 --figure docs/figures/gallery/nls_soliton.png
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import atlasnn
from atlasnn.systems import nls, nls_mass, nls_soliton, periodic_grid

jax.config.update("jax_enable_x64", True)


# --8<-- [start:solve]
def soliton_run(points: int, length: float, T: float, samples: int = 201):
    """The soliton solved over [0, T]; its states at `samples` times, its mass and energy relative
    to the start's, and its distance to the exact soliton at those times."""
    system = nls(points=points, length=length)  # z0: the soliton a = 1, v ≈ 1, at t = 0
    sol = atlasnn.solve(system, system.z0, (0.0, T))  # the defaults: the Gauss method, the linear part used
    t = np.linspace(0.0, T, samples)
    z = sol(t)  # (samples, 2·points): Re ψ on the grid, then Im ψ
    mass, energy = nls_mass(z), system.energy64(z)
    distance = np.max(np.abs(z - nls_soliton(t, points, length)), axis=1)
    return sol, t, z, np.abs(mass / mass[0] - 1), np.abs(energy / energy[0] - 1), distance
# --8<-- [end:solve]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=512, help="grid points (the state has twice as many)")
    parser.add_argument("--length", type=float, default=64.0, help="the periodic domain's length")
    parser.add_argument("--T", type=float, default=70.0)
    parser.add_argument("--figure", default="nls_soliton.png")
    args = parser.parse_args(argv)
    tic = time.perf_counter()
    sol, t, z, mass, energy, distance = soliton_run(args.points, args.length, args.T)
    seconds = time.perf_counter() - tic
    print(f"NLS on {args.points} points, length {args.length:g}, t in [0, {args.T:g}]: {sol.n_windows} windows "
          f"in {seconds:.1f} s (with the compile)")
    print(f"max |mass/mass0 − 1| = {mass.max():.1e}, max |H/H0 − 1| = {energy.max():.1e}, "
          f"max distance to the exact soliton = {distance.max():.1e}")
    assert mass.max() < 1e-13 and energy.max() < 1e-12, "the invariants are not kept to round-off"
    assert distance.max() < 1e-6, "the solution left the exact soliton (too few grid points for the length?)"

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = periodic_grid(args.points, args.length)
    modulus = np.hypot(z[:, : args.points], z[:, args.points:])
    fig, (left, right) = plt.subplots(1, 2, figsize=(8.5, 3.4), gridspec_kw={"width_ratios": [1, 1.25]})
    image = left.pcolormesh(x, t, modulus, shading="auto", cmap="magma", rasterized=True)
    fig.colorbar(image, ax=left, label="|ψ|")
    left.set_xlabel("x")
    left.set_ylabel("t")
    left.set_title("|ψ(x, t)|: the soliton moving right")
    tiny = 1e-17  # a zero drawn on the log axis
    right.semilogy(t, np.maximum(distance, tiny), lw=1, label="max |z − exact soliton|")
    right.semilogy(t, np.maximum(energy, tiny), lw=1, label="|H/H0 − 1|")
    right.semilogy(t, np.maximum(mass, tiny), lw=1, label="|mass/mass0 − 1|")
    right.set_ylim(1e-17, 1e3 * max(distance.max(), energy.max(), mass.max()))  # room for the legend
    right.set_xlabel("t")
    right.set_title(f"{args.points} points, {sol.n_windows} Gauss windows")
    right.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()

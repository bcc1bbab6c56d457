"""The Gauss method on a Hamiltonian wave equation: the sine-Gordon breather on a periodic Fourier
grid (``atlasnn.systems.sine_gordon``, its linear part 1 + k² on u declared) against the explicit
symplectic methods a user of wave equations picks — Störmer–Verlet (order 2) and Yoshida's
composition of it (order 4), with the spectral Laplacian, in JAX, compiled — and Diffrax's Tsit5 and
Kvaerno5,
at equal accuracy (one core, the whole call; errors against the exact breather).

    taskset -c 1 python -m benchmarks.sine_gordon_pde --out docs/benchmarks/sine_gordon_pde.json \\
        --figure docs/benchmarks/sine_gordon_pde.png
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("ATLASNN_CACHE_DIR", "off")  # cold first calls (set before atlasnn is imported)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from atlasnn.systems import fourier_wavenumbers, sine_gordon, sine_gordon_breather  # noqa: E402

from benchmarks.nls_pde import (SPLIT_STEPS, TOLS, against, atlasnn_points, composed, record_runs,  # noqa: E402
                                diffrax_points)
from benchmarks.problems import timed  # noqa: E402

LENGTH, OMEGA = 60.0, 0.5


def verlet(points: int, T: float, order: int):
    """A jitted Störmer–Verlet (kick–drift–kick) run of n steps for u_tt = u_xx − sin u, or
    Yoshida's order-4 composition of it."""
    k2 = jnp.asarray(fourier_wavenumbers(points, LENGTH) ** 2)

    def force(u):
        return -jnp.real(jnp.fft.ifft(k2 * jnp.fft.fft(u))) - jnp.sin(u)

    def kdk(z, tau):
        u, v = z
        v = v + 0.5 * tau * force(u)
        u = u + tau * v
        return u, v + 0.5 * tau * force(u)

    return composed(kdk, T, order)


def verlet_points(system, points: int, T: float, exact, order: int) -> list[dict]:
    run = verlet(points, T, order)
    z0 = (jnp.asarray(system.z0[:points]), jnp.asarray(system.z0[points:]))
    e0 = float(system.energy64(system.z0))
    rows = []
    for n in SPLIT_STEPS:
        jax.block_until_ready(run(z0, n))
        (u, v), best, _ = timed(lambda: tuple(np.asarray(x) for x in run(z0, n)))
        z = np.concatenate([u, v])
        rows.append({"steps": n, "seconds": best, "error": float(np.max(np.abs(z - exact))), "mass_drift": None,
                     "energy_drift": float(abs(float(system.energy64(z)) / e0 - 1))})
        print(f"verlet order {order}", rows[-1], flush=True)
    return rows


def compare(points: int, T: float, stages) -> dict:
    system = sine_gordon(points=points, length=LENGTH, omega=OMEGA)
    exact = sine_gordon_breather(T, points, LENGTH, OMEGA)
    out = {"problem": "sine-Gordon breather", "points": points, "length": LENGTH, "T": T, "omega": OMEGA,
           "atlasnn": atlasnn_points(system, system.z0, T, exact, (None, *TOLS), stages, mass=None),
           "verlet": verlet_points(system, points, T, exact, 2),
           "yoshida4": verlet_points(system, points, T, exact, 4),
           "tsit5": diffrax_points(system, T, exact, mass=None),
           "kvaerno5": diffrax_points(system, T, exact, mass=None, method="kvaerno5"),
           "rivals": ["verlet", "yoshida4", "tsit5", "kvaerno5"]}
    return against(out)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, nargs="+", default=[256])
    parser.add_argument("--T", type=float, default=10.0)
    parser.add_argument("--stages", type=int, nargs="*", default=[8, 12])
    parser.add_argument("--out", default="docs/benchmarks/sine_gordon_pde.json")
    parser.add_argument("--figure", default=None)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    runs = [compare(m, args.T, (None, *args.stages)) for m in args.points]
    record_runs("sine_gordon_pde", args, runs)


if __name__ == "__main__":
    main()

"""Window lengths of the Gauss collocation: constant (symplectic) against adaptive, by the energy
error over many periods and the cost, on Kepler orbits of rising eccentricity at a loose and at the
default tolerance.

For each eccentricity, tolerance and mode: the windows, the wall time, the largest relative energy
error, and its growth exponent over the last two decades (∝ t: a drift; ∝ √t: round-off alone).

    python -m benchmarks.step_modes --out docs/benchmarks/step_modes.json
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.energy_long import binned, growth, invariants
from benchmarks.problems import kepler_system

CASES = [(0.6, 1000), (0.9, 1000), (0.99, 40)]
TOLS = (1e-6, GaussCollocation.rtol)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/step_modes.json")
    args = ap.parse_args(argv)
    rows = []
    for e, periods in CASES:
        system, T = kepler_system(e), 2 * np.pi * periods
        for rtol in TOLS:
            for steps in ("constant", "adaptive"):
                solver = GaussCollocation(steps=steps, rtol=rtol, atol=rtol / 100, keep=False)
                tic = time.perf_counter()
                sol = solve(system, None, (0.0, T), solver=solver)
                seconds = time.perf_counter() - tic
                energy, momentum = invariants(system, sol.z + sol.e)
                bt, be = binned(sol.edges[:-1], energy, T)
                row = {"e": e, "periods": periods, "rtol": rtol, "steps": steps, "windows": sol.n_windows,
                       "seconds": seconds, "energy_max": float(energy.max()), "momentum_max": float(momentum.max()),
                       "growth_exponent": growth(bt, be)}
                rows.append(row)
                print(f"e = {e} rtol {rtol:g} {steps:9s}: {sol.n_windows:8d} windows, {seconds:6.1f} s, max |ΔH/H| "
                      f"{row['energy_max']:.2e}, ∝ t^{row['growth_exponent']:.2f}, max |ΔL| {row['momentum_max']:.1e}",
                      flush=True)
    write_result(args.out, {"command": "python -m benchmarks.step_modes " + " ".join(argv or []),
                            "machine": machine_info(), "rows": rows})


if __name__ == "__main__":
    main()

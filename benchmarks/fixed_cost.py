"""A call's fixed cost: one window of Hénon–Heiles (t ∈ [0, 0.1]) solved by the default Gauss
solver and evaluated at 200 times, after compilation, one core — what every call pays before its
windows' own work. Beside it, the same call over [0, 24π] (tens of windows) at two tolerances.

    taskset -c 1 python -m benchmarks.fixed_cost --out docs/benchmarks/fixed_cost.json

Each figure: the minimum and the median of ``--repeats`` calls (the minimum is the steadier on a
shared virtual machine).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import jax
import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation
from atlasnn.systems import builtin_system

from benchmarks.common import machine_info, write_result

CASES = (("one window", 0.1, 1e-11), ("[0, 24π]", 24 * math.pi, 1e-11), ("[0, 24π]", 24 * math.pi, 1e-6))


def measure(fn, repeats: int) -> dict:
    fn()
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        fn()
        times.append(time.perf_counter() - tic)
    return {"min_seconds": min(times), "median_seconds": statistics.median(times)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    system, z0 = builtin_system("henon_heiles"), np.array([0.3, -0.3, 0.3, 0.15])
    rows = []
    for label, T, rtol in CASES:
        solver = GaussCollocation(rtol=rtol, atol=rtol / 100)
        t = np.linspace(0.0, T, 200)
        sol = solve(system, z0, (0.0, T), solver=solver)
        row = {"case": label, "T": T, "rtol": rtol, "windows": sol.n_windows, "stages": sol.info["stages"],
               "solve_and_values": measure(lambda: solve(system, z0, (0.0, T), solver=solver)(t), args.repeats),
               "solve": measure(lambda: solve(system, z0, (0.0, T), solver=solver), args.repeats),
               "values": measure(lambda: sol(t), args.repeats)}
        rows.append(row)
        print(f"{label:10s} rtol {rtol:g} ({row['windows']} windows): " + ", ".join(
            f"{k} {row[k]['min_seconds'] * 1e3:.3g} ms (median {row[k]['median_seconds'] * 1e3:.3g})"
            for k in ("solve_and_values", "solve", "values")), flush=True)
    if args.out:
        write_result(args.out, {"command": "python -m benchmarks.fixed_cost", "machine": machine_info(), "rows": rows})


if __name__ == "__main__":
    main()

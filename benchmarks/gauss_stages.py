"""The Gauss collocation's stage count s: cost and accuracy of ``atlasnn.solve`` for s = 4 … 16 at
two tolerances, on Kepler e = 0.6 over 100 periods (against the exact orbit) and Hénon–Heiles
[0, 24π] (against the Gauss collocation at s = 16 on short windows). Time after compilation, the
solution and its values at 2 000 times, best of 3, one process.

    python -m benchmarks.gauss_stages --out docs/benchmarks/gauss_stages.json
"""

from __future__ import annotations

import argparse

import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.problems import timed
from benchmarks.solver_workprecision import problem

STAGES = (4, 6, 8, 10, 12, 14, 16)
TOLS = (1e-9, 1e-11)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/gauss_stages.json")
    args = ap.parse_args(argv)
    rows = []
    for name in ("kepler-e06-100", "henon-heiles-long"):
        system, z0, interval, t, ref, described, gap = problem(name)
        scale = float(np.ptp(ref, axis=0).max())
        for rtol in TOLS:
            for s in STAGES:
                solver = GaussCollocation(stages=s, rtol=rtol, atol=rtol / 100)
                solve(system, z0, interval, solver=solver)
                (sol, z), best, _ = timed(lambda: (lambda q: (q, q(t)))(solve(system, z0, interval, solver=solver)))
                row = {"problem": name, "reference": described, "rtol": rtol, "stages": s, "seconds": best,
                       "windows": sol.n_windows, "error_rel": float(np.abs(z - ref).max() / scale),
                       "iterations_per_window": sol.info["iterations"] / sol.n_windows}
                rows.append(row)
                print(f"{name:18s} rtol {rtol:.0e} s = {s:2d}: {best * 1e3:8.2f} ms, {sol.n_windows:6d} windows, "
                      f"error {row['error_rel']:.1e}", flush=True)
    write_result(args.out, {"command": "python -m benchmarks.gauss_stages " + " ".join(argv or []),
                            "machine": machine_info(), "rows": rows})


if __name__ == "__main__":
    main()

"""Does the time scaling f let collocation windows grow? The collocation solver with f = s
(linear), tanh(m s) and the rational-exp scaling at several fixed shapes γ̂ (m·h or α·h), and with
more features, on Hénon–Heiles [0, 24π] and Kepler e = 0.9 at the default tolerances, seeds 0–2:
windows, rejected tries, time after compilation, max error relative to the range.

    python -m benchmarks.solver_scalings --out docs/benchmarks/solver_scalings.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from atlasnn import solve
from atlasnn.evaluation import reference_solution
from atlasnn.solver import Collocation

from benchmarks.common import machine_info
from benchmarks.solver_suite import builtin_problem

VARIANTS = [("linear", 1.0, 20), ("tanh", 0.5, 20), ("tanh", 1.0, 20), ("tanh", 2.0, 20),
            ("rational_exp", 1.0, 20), ("rational_exp", 2.0, 20), ("linear", 1.0, 16), ("linear", 1.0, 28)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/solver_scalings.json")
    args = ap.parse_args(argv)
    rows = []
    for name in ("henon-heiles-long", "kepler-e09"):
        system, z0, interval = builtin_problem(name)
        t = np.linspace(*interval, 2000)
        ref = reference_solution(system, z0, t, rtol=1e-13, atol=1e-13)
        scale = float(np.ptp(ref, axis=0).max())
        for scaling, shape, m in VARIANTS:
            for seed in range(3):
                solver = Collocation(scaling=scaling, shape=shape, features=m, seed=seed)
                try:
                    solve(system, z0, interval, solver=solver)  # compile
                    tic = time.perf_counter()
                    sol = solve(system, z0, interval, solver=solver)
                    sec = time.perf_counter() - tic
                    row = {"problem": name, "scaling": scaling, "shape": shape, "features": m, "seed": seed,
                           "windows": sol.n_windows, "rejected": sol.info["rejected"], "seconds": sec,
                           "error_rel": float(np.abs(sol(t) - ref).max() / scale)}
                except Exception as exc:  # a failed march is a result
                    row = {"problem": name, "scaling": scaling, "shape": shape, "features": m, "seed": seed,
                           "failed": str(exc)}
                rows.append(row)
                print(row, flush=True)
    Path(args.out).write_text(json.dumps({"command": "python -m benchmarks.solver_scalings", "machine": machine_info(),
                                          "rows": rows}, indent=1))


if __name__ == "__main__":
    main()

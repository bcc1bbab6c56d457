"""The flow-map bundle's reference-free error estimate against DOP853, on the built-in oscillator
box (seeds 0 and 1), a box 2.5× as wide (z0 ± 50 %, lam in [0, 2]) and a ten times longer interval
([0, 40π], 960 windows): per case the true worst and median held-out member (200 members, 101
times), ``info["estimated_error"]``, the one-window residual and the energy drift.

    taskset -c 0 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m benchmarks.flowmap_estimate [--out docs/benchmarks/flowmap_estimate.json]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from atlasnn.evaluation import reference_members
from atlasnn.solver import FlowMap, solve_bundle
from atlasnn.systems import BundleBox, nonlinear_oscillator
from benchmarks.common import machine_info

# name: (z0 fraction, lam range, T, windows, seed)
CASES = {"built-in box, seed 0": (0.2, (0.5, 1.5), 4 * math.pi, 96, 0),
         "built-in box, seed 1": (0.2, (0.5, 1.5), 4 * math.pi, 96, 1),
         "wide box": (0.5, (0.0, 2.0), 4 * math.pi, 96, 0),
         "[0, 40 pi], 960 windows": (0.2, (0.5, 1.5), 40 * math.pi, 960, 0)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.flowmap_estimate")
    ap.add_argument("--out", default="docs/benchmarks/flowmap_estimate.json")
    args = ap.parse_args(argv)
    system, rows = nonlinear_oscillator(), []
    for name, (rel, lam_range, T, windows, seed) in CASES.items():
        box = BundleBox.around(system.initial_state(), rel, {"lam": lam_range}, T=T)
        z0, lam = box.draw(np.random.default_rng(12345), 200)
        t = np.linspace(0.0, T, 101)
        ref = reference_members(system, box, z0, lam, t)
        sol = solve_bundle(system, box, FlowMap(windows=windows), seed=seed)
        err = np.abs(sol(t, z0, lam) - ref).max(axis=(1, 2))
        info = sol.info
        row = {"case": name, "true_worst": float(err.max()), "true_median": float(np.median(err)),
               "estimated_error": info["estimated_error"], "ratio": info["estimated_error"] / float(err.max()),
               "held_out_residual_rms": info["held_out_residual_rms"],
               "energy_drift_relative": info["energy_drift_relative"], "seconds": info["seconds"]}
        rows.append(row)
        print(f"{name}: true worst {row['true_worst']:.2g}, estimated {row['estimated_error']:.2g} "
              f"({row['ratio']:.2f}x), residual {row['held_out_residual_rms']:.2g}, drift "
              f"{row['energy_drift_relative']:.2g}, {row['seconds']:.1f} s", flush=True)
    Path(args.out).write_text(json.dumps({"rows": rows, "machine": machine_info(), "command":
                                          "python -m benchmarks.flowmap_estimate"}, indent=1), encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Where each route wins on an inverse problem: the joint network fit against least-squares
shooting as the noise level and the number of observations change.

The pendulum H = p²/2 − g·cos x, z0 = (1, 0), g = 1 to recover from observations of the angle x
only at n times uniform on [0, 8] (times seed 5), Gaussian noise of ``noise`` × the RMS of x; the
same data for both methods, seeds 0..S−1 (a noise draw each). Per cell: the median absolute error
of each method, how many seeds' ±2σ cover the truth, the median seconds a fit.

    python -m benchmarks.inverse_noise [--seeds 3] [--out docs/benchmarks/inverse_noise.json]

Then other problems than the built-in experiments (``OTHERS``): two unknowns of an anharmonic
oscillator from x only, Hénon–Heiles' lam together with an unknown initial momentum from x alone,
and a Toda-like pair with an unknown coupling, 1 % noise, same table.

Timings from the machine as it was (not pinned): the ratio between the methods is the point.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np

from atlasnn.inverse import fit_shooting, synthetic_observations
from atlasnn.inverse import fit_joint
from atlasnn import Unknown
from atlasnn.systems import expression_system
from benchmarks.common import machine_info

NOISES = (0.001, 0.01, 0.05)
COUNTS = (10, 20, 50)


def others():
    """(label, system, unknowns, truth, observed names, T) of problems not among the built-ins."""
    anh = expression_system("p**2/2 + a*x**2/2 + b*x**4/4", ["x"], ["p"], {"a": 1.0, "b": 0.5}, z0=[1.2, 0.0],
                            name="anharmonic")
    hh = expression_system("(px**2+py**2)/2 + (x**2+y**2)/2 + lam*(x**2*y - y**3/3)", ["x", "y"], ["px", "py"],
                           {"lam": 1.0}, z0=[0.3, -0.3, 0.3, 0.15], name="hh-expr")
    toda = expression_system("(p1**2+p2**2)/2 + exp(c*(q1-q2)) + exp(c*(q2-q1))", ["q1", "q2"], ["p1", "p2"],
                             {"c": 0.8}, z0=[0.5, -0.5, 0.0, 0.2], name="toda-pair")
    return [
        ("anharmonic a, b from x", anh, [Unknown("a", 0.8, 0.3, 2.0), Unknown("b", 0.3, 0.05, 2.0)],
         {"a": 1.0, "b": 0.5}, ["x"], 10.0),
        ("Henon-Heiles lam, z0.px from x", hh, [Unknown("lam", 0.6, 0.2, 2.0), Unknown("z0.px", 0.2, 0.0, 0.6)],
         {"lam": 1.0, "z0.px": 0.3}, ["x"], 10.0),
        ("Toda pair c from q1, q2", toda, [Unknown("c", 0.5, 0.2, 2.0)], {"c": 0.8}, ["q1", "q2"], 8.0),
    ]


def cell(system, unknowns, noise: float, n: int, seeds: int, truth=None, names=("x",), T: float = 8.0) -> dict:
    truth = truth or {"g": 1.0}
    times = np.sort(np.random.default_rng(5).uniform(0.0, T, n))
    rows = {"joint": [], "shooting": []}
    for seed in range(seeds):
        obs = synthetic_observations(system, system.z0, times, list(names), noise, seed, t0=0.0)
        for method, fit in (("joint", lambda o, s=seed: fit_joint(system, o, unknowns, seed=s)),
                            ("shooting", lambda o: fit_shooting(system, o, unknowns))):
            r = fit(obs)
            err = np.abs(np.asarray([r.value(k) - v for k, v in truth.items()]))
            std = np.asarray([r.std[r.names.index(k)] for k in truth])
            rows[method].append({"seed": seed, "estimate": r.estimate.tolist(), "std": std.tolist(),
                                 "abs_error": float(err.max()), "covered_2sigma": bool(np.all(err <= 2 * std)),
                                 "seconds": r.wall_time})
    out = {"noise": noise, "n": n}
    for method, rs in rows.items():
        out[method] = {"median_abs_error": statistics.median(r["abs_error"] for r in rs),
                       "covered_2sigma": sum(r["covered_2sigma"] for r in rs), "seeds": len(rs),
                       "median_seconds": statistics.median(r["seconds"] for r in rs), "rows": rs}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.inverse_noise", description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--out", default="docs/benchmarks/inverse_noise.json")
    args = ap.parse_args(argv)
    pend = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], {"g": 1.0}, z0=[1.0, 0.0], name="pendulum")
    unknowns = [Unknown("g", 0.7, 0.5, 2.0)]
    cells = []
    print(f"{'noise':>6} {'n':>4} | {'joint |err|':>11} {'cov':>4} {'s':>6} | {'shoot |err|':>11} {'cov':>4} {'s':>6}")
    for noise in NOISES:
        for n in COUNTS:
            c = cell(pend, unknowns, noise, n, args.seeds)
            cells.append(c)
            j, s = c["joint"], c["shooting"]
            print(f"{noise:>6g} {n:>4} | {j['median_abs_error']:>11.3g} {j['covered_2sigma']:>2}/{j['seeds']} "
                  f"{j['median_seconds']:>6.2f} | {s['median_abs_error']:>11.3g} {s['covered_2sigma']:>2}/{s['seeds']} "
                  f"{s['median_seconds']:>6.2f}", flush=True)
    other_cells = []
    for label, system, unknowns, truth, names, T in others():
        c = cell(system, unknowns, 0.01, 40, args.seeds, truth, names, T)
        c["problem"] = label
        other_cells.append(c)
        j, s = c["joint"], c["shooting"]
        print(f"{label}: joint max |err| {j['median_abs_error']:.3g} ({j['covered_2sigma']}/{j['seeds']} within 2σ, "
              f"{j['median_seconds']:.1f} s); shooting {s['median_abs_error']:.3g} ({s['covered_2sigma']}/{s['seeds']}, "
              f"{s['median_seconds']:.2f} s)", flush=True)
    result = {"command": "python -m benchmarks.inverse_noise " + " ".join(argv or sys.argv[1:]),
              "problem": "pendulum g from angle observations on [0, 8], g = 1, z0 = (1, 0)",
              "machine": machine_info(), "cells": cells, "others": other_cells}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

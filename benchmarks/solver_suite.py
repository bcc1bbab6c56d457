"""The default solver (``atlasnn.solve``: GaussCollocation at its default settings) on every problem of
the hard suite, both long experiments and three problems that are not built in (Kepler e = 0.99, a
double pendulum, a Morse chain: chosen before any run, not tuned on): max error relative to the
state's range against a reference, the error estimate's effectivity (estimate / true error), the
verdict, the cost.

The reference: the exact orbit for Kepler's problems; elsewhere the Gauss collocation with s = 16 on
windows a quarter of the default's, checked against DOP853 at rtol 2.3e-14 (their distance is the
``reference_gap``: an error at or below it is at the reference's resolution).

    python -m benchmarks.solver_suite --out docs/runs/solver/suite.json

A verdict is "accurate" when the a-posteriori estimate says max error ≤ 1e-10 of the range; it is
right when the true error agrees (both on one side of 1e-10, or both within 3× of it).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from atlasnn import solve
from atlasnn.solver import solver_from_name
from atlasnn.systems import expression_system

from benchmarks.common import machine_info, write_result
from benchmarks.problems import HARD, LONG, builtin_problem, gauss_reference, kepler_eccentricity, kepler_exact, kepler_system

TARGET = 1e-10


def other_problems():
    """Problems not among the built-in experiments (chosen before any run, not tuned on)."""
    e = 0.99
    kepler = kepler_system(e, name="kepler-e099")
    pendulum = expression_system(
        "(p1**2 + 2*p2**2 - 2*p1*p2*cos(q1 - q2)) / (2*(1 + sin(q1 - q2)**2)) - 2*cos(q1) - cos(q2)",
        ["q1", "q2"], ["p1", "p2"], z0=[1.0, 0.5, 0.0, 0.0], name="double-pendulum")
    morse = expression_system(
        "(p1**2 + p2**2 + p3**2)/2 + (1 - exp(-(q2 - q1 - 1)))**2 + (1 - exp(-(q3 - q2 - 1)))**2",
        ["q1", "q2", "q3"], ["p1", "p2", "p3"], z0=[0.0, 1.2, 2.0, 0.1, 0.0, -0.1], separable=True,
        name="morse-chain")
    return {"kepler-e099": (kepler, np.asarray(kepler.z0), (0.0, 4 * np.pi)),
            "double-pendulum": (pendulum, np.asarray(pendulum.z0), (0.0, 20.0)),
            "morse-chain": (morse, np.asarray(morse.z0), (0.0, 30.0))}


def reference(system, z0, interval, t):
    """(reference at t, description, its gap to the second reference relative to the range)."""
    e = kepler_eccentricity(system, z0)
    if e is not None:
        return kepler_exact(t, e, z0), "exact", 0.0
    return gauss_reference(system, z0, interval, t)


def run_one(name, system, z0, interval, solver, n_eval=2000):
    t = np.linspace(*interval, n_eval)
    ref, described, gap = reference(system, z0, interval, t)
    scale = float(np.ptp(ref, axis=0).max())
    row = {"problem": name, "interval": list(interval), "range": scale, "reference": described,
           "reference_gap": gap, "solver": solver.settings()}
    tic = time.perf_counter()
    try:
        sol = solve(system, z0, interval, solver=solver)
    except Exception as exc:  # a failed march is a result to record, not a crash
        row.update(status="failed", message=str(exc), seconds=time.perf_counter() - tic)
        return row
    seconds = time.perf_counter() - tic
    err = float(np.max(np.abs(sol(t) - ref)))
    tic = time.perf_counter()
    est = sol.estimate(z0=z0)
    estimate_seconds = time.perf_counter() - tic
    says_ok = est.max_abs <= TARGET * scale
    is_ok = err <= TARGET * scale
    right = says_ok == is_ok or (min(err, est.max_abs) > TARGET * scale / 3 and max(err, est.max_abs) < 3 * TARGET * scale)
    row.update(status="ok", seconds=seconds, estimate_seconds=estimate_seconds,
               first_call=sol.info["first_call_time"], windows=sol.n_windows, rejected=sol.info["rejected"],
               error=err, error_rel=err / scale, at_reference_resolution=bool(err / scale <= 3 * gap),
               estimate=est.max_abs, estimate_rel=est.max_abs / scale,
               effectivity=est.max_abs / err if err > 0 else float("nan"), estimate_trusted=est.trusted,
               verdict="accurate" if says_ok else "not accurate", verdict_right=bool(right))
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/runs/solver/suite.json")
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--solver", default="gauss", help="a registered solver name")
    ap.add_argument("--settings", default="{}", help="the solver's settings as JSON, e.g. '{\"rtol\": 1e-10}'")
    args = ap.parse_args(argv)
    solver = solver_from_name(args.solver, **json.loads(args.settings))
    problems = {n: builtin_problem(n) for n in HARD + LONG}
    problems.update(other_problems())
    rows = []
    for name, (system, z0, interval) in problems.items():
        if args.only and name not in args.only:
            continue
        row = run_one(name, system, z0, interval, solver)
        rows.append(row)
        if row["status"] == "ok":
            print(f"{name:22s}: err {row['error_rel']:.2e} of range (reference gap {row['reference_gap']:.1e}), "
                  f"estimate x{row['effectivity']:.2f}, {row['windows']} windows ({row['rejected']} rejected), "
                  f"{row['seconds'] * 1e3:.1f} ms, verdict {row['verdict']}{'' if row['verdict_right'] else ' WRONG'}",
                  flush=True)
        else:
            print(f"{name:22s}: FAILED {row['message']}", flush=True)
    write_result(args.out, {"command": "python -m benchmarks.solver_suite " + " ".join(argv or []),
                            "machine": machine_info(), "target": TARGET, "rows": rows})


if __name__ == "__main__":
    main()

"""The collocation solver on every problem of the hard suite and both long experiments, every
seed (seed = the draw of the random features): max error relative to the state's range against
DOP853 at 1e-13, the error estimates' effectivity (estimate / true error), the verdict, the cost.
Also problems that are not built in (Kepler e = 0.99, a double pendulum, a Morse oscillator chain).

    python -m benchmarks.solver_suite --out docs/runs/solver/suite.json

A verdict is "accurate" when the a-posteriori estimate says max error ≤ 1e-9 of the range; it is
right when the true error agrees (both sides of 1e-9, with the estimate's own factor 3 of slack).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from atlasnn import solve
from atlasnn.evaluation import reference_solution
from atlasnn.experiments.config import builtin_config_path, load_config
from atlasnn.solver import DEFAULT_ATOL, DEFAULT_RTOL, Collocation
from atlasnn.systems import expression_system

HARD = ["figure-eight", "fpu-stiff", "henon-heiles-chaotic", "kepler-e06", "kepler-e09", "pendulum-separatrix",
        "toda-3"]
LONG = ["oscillator-long", "henon-heiles-long"]
TARGET = 1e-9


def builtin_problem(name: str):
    cfg = load_config(builtin_config_path(name))
    system = cfg.system.build()
    return system, np.asarray(system.z0), (float(cfg.eval_stage.t0), float(cfg.eval_stage.T))


def other_problems():
    """Problems not among the built-in experiments (chosen before any run, not tuned on)."""
    e = 0.99
    kepler = expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                               z0=[1 - e, 0.0, 0.0, float(np.sqrt((1 + e) / (1 - e)))], separable=True,
                               name="kepler-e099")
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


def run_one(name, system, z0, interval, seed, rtol, atol, n_eval=2000, settings=None):
    t = np.linspace(*interval, n_eval)
    ref = reference_solution(system, z0, t, rtol=1e-13, atol=1e-13)
    scale = float(np.ptp(ref, axis=0).max())
    row = {"problem": name, "seed": seed, "interval": list(interval), "range": scale, "rtol": rtol, "atol": atol}
    tic = time.perf_counter()
    try:
        sol = solve(system, z0, interval, solver=Collocation(seed=seed, **(settings or {})), rtol=rtol, atol=atol)
    except Exception as exc:  # a failed march is a result to record, not a crash
        row.update(status="failed", message=str(exc), seconds=time.perf_counter() - tic)
        return row
    seconds = time.perf_counter() - tic
    err = float(np.max(np.abs(sol(t) - ref)))
    est = sol.estimate(z0=z0)
    running = float(sol.info["running_estimate_max"])
    says_ok = est.max_abs <= TARGET * scale
    is_ok = err <= TARGET * scale
    right = says_ok == is_ok or (min(err, est.max_abs) > TARGET * scale / 3 and max(err, est.max_abs) < 3 * TARGET * scale)
    row.update(status="ok", seconds=seconds, first_call=sol.info["first_call_time"], windows=sol.n_windows,
               rejected=sol.info["rejected"], newton=sol.info["newton_iterations"], error=err,
               error_rel=err / scale, estimate=est.max_abs, estimate_rel=est.max_abs / scale,
               effectivity=est.max_abs / err if err > 0 else float("nan"), running_estimate=running,
               running_effectivity=running / err if err > 0 else float("nan"), estimate_trusted=est.trusted,
               verdict="accurate" if says_ok else "not accurate", verdict_right=bool(right))
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/runs/solver/suite.json")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--rtol", type=float, default=DEFAULT_RTOL)
    ap.add_argument("--atol", type=float, default=DEFAULT_ATOL)
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--settings", default="{}", help="Collocation settings as JSON, e.g. '{\"scale\": 4}'")
    args = ap.parse_args(argv)
    problems = {n: builtin_problem(n) for n in HARD + LONG}
    problems.update(other_problems())
    rows = []
    for name, (system, z0, interval) in problems.items():
        if args.only and name not in args.only:
            continue
        for seed in range(args.seeds):
            row = run_one(name, system, z0, interval, seed, args.rtol, args.atol, settings=json.loads(args.settings))
            rows.append(row)
            if row["status"] == "ok":
                print(f"{name:22s} seed {seed}: err {row['error_rel']:.2e} of range, estimate x{row['effectivity']:.2f}"
                      f" (running x{row['running_effectivity']:.2f}), {row['windows']} windows "
                      f"({row['rejected']} rejected), {row['seconds'] * 1e3:.0f} ms, verdict {row['verdict']}"
                      f"{'' if row['verdict_right'] else ' WRONG'}", flush=True)
            else:
                print(f"{name:22s} seed {seed}: FAILED {row['message']}", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"command": "python -m benchmarks.solver_suite " + " ".join(argv or []),
                                          "target": TARGET, "rows": rows}, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

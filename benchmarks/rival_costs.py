"""Why the default loses where it loses to a classical method, counted in evaluations of the field:
the NLS soliton against ETDRK4, and the outer solar system against REBOUND's IAS15 — with, beside
IAS15, REBOUND's Wisdom–Holman splittings at their best, for what a planetary splitting would give.

* **NLS** (M = 512 points, T = 5, the end state against the exact soliton, errors of its amplitude
  1): ``solve`` with no solver given (the Gauss solver there) over rtol 1e-4 … 1e-12 (atol = rtol/100),
  its stage evaluations (fixed-point iterations × stages: each the nonlinear field and the linear
  part's solve at one stage) and the time of one; ETDRK4 over 100 … 12 800 steps (four evaluations
  of the nonlinear field a step, each an FFT pair); at each error level, the fastest run of each
  within it. And ``SplittingComposition()`` at rtol 1e-6, 1e-8 and 1e-10 split into its pilot, its
  march (the scheme and step count given, no pilot and no check; timed alone where the pilot's
  march was the solution) and the rest (the check), with the time of one flow of its march (one
  linear and one nonlinear flow).
* **The outer solar system** (benchmarks/outer_solar.py, 10⁶ days, the state at 200 times, the
  reference of benchmarks/rebound_anchor.py): the default at rtol 1e-12 and 1e-9 with its
  evaluations of the field (iterations × stages); IAS15 at ε = 1e-9 and 1e-7 with its force
  evaluations (counted by a callback in a run of their own); WHFast with the 17th-order corrector,
  the second corrector and the lazy implementer's kernel, SABA(10,6,4) and SABACL4 (all in Jacobi
  coordinates) at steps of 20 … 400 days, each dividing the output interval.

One core, best of ``--repeats`` after a first call.

    taskset -c 1 python -m benchmarks.rival_costs --out docs/benchmarks/rival_costs.json
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation, SplittingComposition
from atlasnn.systems import nls, nls_soliton

from benchmarks.common import machine_info, write_result
from benchmarks.nls_pde import LENGTH, split_points
from benchmarks.rebound_anchor import T as SOLAR_T
from benchmarks.rebound_anchor import centred, rebound_run, row
from benchmarks.outer_solar import outer_solar_system
from benchmarks.splitting_breakdown import _best

NLS_T = 5.0
#: the errors at T (of the amplitude 1) compared at, and the rtol the default is swept over for them
NLS_LEVELS = (1e-6, 1e-8, 1e-10, 1e-12)
NLS_SWEEP = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
NLS_SPLITTING_TOLS = (1e-6, 1e-8, 1e-10)
SOLAR_TOLS = (1e-12, 1e-9)
IAS15_EPSILONS = (1e-9, 1e-7)
#: REBOUND's Wisdom–Holman family at its most accurate settings (options set on ``sim.integrator``)
WISDOM_HOLMAN = {"WHFast, corrector 17, lazy kernel": ("whfast", {"corrector": 17, "corrector2": 1,
                                                                  "kernel": "lazy", "safe_mode": 0}),
                 "SABA(10,6,4)": ("SABA10,6,4", {"safe_mode": 0}),
                 "SABACL4": ("SABACL,4", {"safe_mode": 0})}
WH_STEPS_DAYS = (20.0, 50.0, 100.0, 200.0, 400.0)


def _nls_default(system, exact, tol: float, repeats: int) -> dict:
    """``solve`` with no solver given at ``tol`` (atol tol/100): time and end state's error, stage
    evaluations."""
    at_T = np.asarray([NLS_T])
    seconds, (sol, z) = _best(lambda: (lambda s: (s, s(at_T)[0]))(
        solve(system, system.z0, (0.0, NLS_T), rtol=tol, atol=tol * 1e-2)), repeats)
    evaluations = int(sol.info["iterations"]) * int(sol.info["stages"])
    return {"rtol": tol, "solver": sol.info["solver"], "seconds": seconds, "error": float(np.abs(z - exact).max()),
            "windows": sol.n_windows, "stages": int(sol.info["stages"]), "iterations": int(sol.info["iterations"]),
            "evaluations": evaluations, "seconds_per_evaluation": seconds / evaluations}


def _nls_splitting(system, exact, tol: float, repeats: int) -> dict:
    """``SplittingComposition()`` at ``tol``: the whole solve, its pilot, its march alone (scheme and
    step count given) and the rest (the check)."""
    at_T = np.asarray([NLS_T])
    solved = lambda solver: solve(system, system.z0, (0.0, NLS_T), solver=solver, rtol=tol,  # noqa: E731
                                  atol=tol * 1e-2)
    seconds, (sol, z) = _best(lambda: (lambda s: (s, s(at_T)[0]))(solved(SplittingComposition())), repeats)
    info = sol.info
    from_pilot = bool(info.get("march_from_pilot"))  # the pilot's march of half steps is the march
    march_s, _ = _best(lambda: solved(SplittingComposition(scheme=info["scheme"], steps=info["steps"])), repeats)
    flows = info["steps"] * int(info["stages"])
    return {"rtol": tol, "seconds": seconds, "error": float(np.abs(z - exact).max()), "scheme": info["scheme"],
            "steps": info["steps"], "flows_a_step": int(info["stages"]), "tries": info.get("tries"),
            "pilot_s": info["pilot_time"], "march_s": march_s, "march_from_pilot": from_pilot,
            "check_s": max(0.0, seconds - info["pilot_time"] - (0.0 if from_pilot else march_s)),
            "march_seconds_per_flow": march_s / flows}


def _fastest_within(points: list[dict], level: float) -> dict | None:
    good = [p for p in points if p["error"] <= level]
    return min(good, key=lambda p: p["seconds"]) if good else None


def nls_rows(repeats: int) -> dict:
    system = nls(points=512, length=LENGTH)
    exact = nls_soliton(NLS_T, 512, LENGTH)
    etdrk4 = split_points(system, 512, NLS_T, exact, 0)
    for r in etdrk4:
        r["evaluations"] = 4 * r["steps"]
        r["seconds_per_evaluation"] = r["seconds"] / r["evaluations"]
    default = [_nls_default(system, exact, tol, repeats) for tol in NLS_SWEEP]
    levels = []
    for level in NLS_LEVELS:
        mine, rival = _fastest_within(default, level), _fastest_within(etdrk4, level)
        levels.append({"level": level, "default": mine, "etdrk4": rival,
                       "ratio": None if mine is None or rival is None else mine["seconds"] / rival["seconds"]})
        print(f"NLS error ≤ {level:g}: default "
              + ("never" if mine is None else f"rtol {mine['rtol']:g} {mine['seconds'] * 1e3:.1f} ms, {mine['evaluations']} "
                 f"evaluations ({mine['seconds_per_evaluation'] * 1e6:.1f} µs each)") + "; ETDRK4 "
              + ("never" if rival is None else f"{rival['steps']} steps {rival['seconds'] * 1e3:.1f} ms, "
                 f"{rival['evaluations']} evaluations ({rival['seconds_per_evaluation'] * 1e6:.1f} µs each)"), flush=True)
    splitting = [_nls_splitting(system, exact, tol, repeats) for tol in NLS_SPLITTING_TOLS]
    for r in splitting:
        print(f"NLS splitting rtol {r['rtol']:g}: {r['seconds'] * 1e3:.1f} ms, error {r['error']:.1e} (pilot "
              f"{r['pilot_s'] * 1e3:.1f}, march {r['march_s'] * 1e3:.1f}{' in the pilot' * r['march_from_pilot']}, check {r['check_s'] * 1e3:.1f}; {r['scheme']} "
              f"{r['steps']} steps, {r['march_seconds_per_flow'] * 1e6:.1f} µs a flow)", flush=True)
    return {"points": 512, "length": LENGTH, "T": NLS_T, "levels": levels, "default_sweep": default,
            "etdrk4_sweep": etdrk4, "splitting": splitting}


def solar_rows(repeats: int) -> dict:
    system = outer_solar_system()
    z0 = centred(system)
    ts = np.linspace(0.0, SOLAR_T, 200)
    default = solve(system, z0, (0.0, SOLAR_T))
    ref = solve(system, z0, (0.0, SOLAR_T),
                solver=GaussCollocation(stages=16, h=float(np.diff(default.edges).min()) / 4))(ts)
    rows = []
    for tol in SOLAR_TOLS:
        best, (sol, z) = _best(lambda: (lambda s: (s, s(ts)))(solve(system, z0, (0.0, SOLAR_T), rtol=tol,
                                                                     atol=tol / 100)), repeats)
        evaluations = int(sol.info["iterations"]) * int(sol.info["stages"])
        rows.append(row("atlasnn", tol, best, z, ref, windows=sol.n_windows, stages=int(sol.info["stages"]),
                        iterations=int(sol.info["iterations"]), evaluations=evaluations))
    every = SOLAR_T / (len(ts) - 1)
    runs = [("REBOUND IAS15", "ias15", eps, None) for eps in IAS15_EPSILONS]
    runs += [(label, integrator, every / round(every / dt), options) for label, (integrator, options)
             in WISDOM_HOLMAN.items() for dt in WH_STEPS_DAYS]
    for label, integrator, setting, options in runs:
        best, z = _best(lambda: rebound_run(system, ts, integrator, setting, options), repeats)
        counter = [0]
        rebound_run(system, ts, integrator, setting, options, counter)
        rows.append(row(label, setting, best, z, ref, evaluations=counter[0]))
    for r in rows:
        r["seconds_per_evaluation"] = r["seconds"] / max(r["evaluations"], 1)
        print(f"solar {r['method']} {r['setting']:.4g}: {r['seconds'] * 1e3:.1f} ms, position {r['position_error_au']:.1e} "
              f"AU, energy {r['energy_error']:.1e}, {r['evaluations']} evaluations "
              f"({r['seconds_per_evaluation'] * 1e6:.2f} µs each)", flush=True)
    return {"T_days": SOLAR_T, "times": len(ts), "reference": "atlasnn s = 16 on windows a quarter of its default's",
            "rows": rows}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # the rivals written in JAX run in float64 too
    out = {"command": "python -m benchmarks.rival_costs", "benchmark": "rival_costs", "machine": machine_info(),
           "repeats": args.repeats, "nls": nls_rows(args.repeats), "solar": solar_rows(args.repeats)}
    if args.out:
        write_result(args.out, out)


if __name__ == "__main__":
    main()

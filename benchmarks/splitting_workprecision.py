"""Work–precision of the explicit splitting methods beside the Gauss solver and Diffrax, at equal
accuracy (one core, compiled, the whole call with values at 200 output times).

Problems: FPUT-β chains of N = 64, 256 and 1 024 particles over [0, 200] (first normal mode
excited, as ``benchmarks.gauss_scaling``), a chain of 64 with energy in every mode (random
momenta), Hénon–Heiles [0, 24π], Kepler e = 0.6 over 10 periods (exact reference), and the
double pendulum (not separable: no splitting). For each accuracy level (max error over the output
times / the state's range ≤ 1e-5 … 1e-11), each method's fastest run that reaches it, over a sweep
of its tolerance: ``solve`` with no solver (the default's own choice), every splitting scheme,
``GaussCollocation``, Diffrax's Tsit5 and Dopri8. Also the relative energy error of the default
along the output. The default's rule (``SCHEME_BY_TOLERANCE``, and which systems get a splitting)
is read off this record. Times: the best of 3 after a first call.

    taskset -c 1 python -m benchmarks.splitting_workprecision --out docs/benchmarks/splitting_workprecision.json
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from atlasnn.solver import GaussCollocation, SplittingComposition, solve

from benchmarks.common import machine_info, write_result
from benchmarks.gauss_orders import fput_chain, problems as small_problems, reference
from benchmarks.problems import gauss_reference, timed
from benchmarks.solver_workprecision import _row, diffrax_points

LEVELS = (1e-5, 1e-7, 1e-9, 1e-11)
TOLS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13)
RK_TOLS = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14)
ANCHORS = ("diffrax-tsit5", "diffrax-dopri8")
#: the schemes swept (the perturbation methods SABA_n and ABA(10,6,4) left out: their orders are
#: for H = A + εB; leapfrog reaches none of the levels in reasonable time)
SCHEMES = ("yoshida4", "mclachlan4", "blanes_moan4", "kahan_li6", "blanes_moan6", "blanes_moan_rkn6", "kahan_li8",
           "bce_rkn8", "sofspa10")


def all_modes_chain(n: int):
    """An FPUT-β chain with energy in every mode: random momenta (seed 0) scaled to the first
    mode's energy."""
    chain = fput_chain(n)
    p = np.random.default_rng(0).standard_normal(n)
    p *= np.linalg.norm(chain.z0[n:]) / np.linalg.norm(p)
    return chain, np.concatenate([np.zeros(n), p])


def problem_table() -> dict:
    """name -> (system, z0, interval)."""
    small = small_problems()
    out = {name: small[name] for name in ("henon-heiles", "kepler-e06", "double-pendulum")}
    out.update({f"fput-beta-{n}": (fput_chain(n), fput_chain(n).z0, (0.0, 200.0)) for n in (64, 256)})
    chain, z0 = all_modes_chain(64)
    out["fput-beta-64-all-modes"] = (chain, z0, (0.0, 200.0))
    out["fput-beta-1024"] = (fput_chain(1024), fput_chain(1024).z0, (0.0, 200.0))
    return out


def points(label, make, system, z0, interval, t, ref, scale, tols=TOLS) -> list[dict]:
    """The sweep of one method: a row per tolerance (``make(tol)`` -> solver, None: the default)."""
    rows = []
    for tol in tols:
        solver = make(tol)
        run = lambda: solve(system, z0, interval, solver=solver, rtol=tol, atol=tol * 1e-2)  # noqa: E731
        tic = time.perf_counter()
        try:
            run()
        except Exception as exc:  # noqa: BLE001 - a tolerance a method cannot meet is a result
            rows.append({"method": label, "setting": tol, "failed": str(exc)[:200]})
            continue
        first = time.perf_counter() - tic
        (sol, z), best, med = timed(lambda: (lambda s: (s, s(t)))(run()))
        energy = sol.system.energy64(z)
        rows.append(_row(label, tol, best, med, z, ref, scale, first_call_seconds=first, windows=sol.n_windows,
                         solver=sol.info.get("solver"), scheme=sol.info.get("scheme"),
                         energy_rel=float(np.abs(energy - energy[0]).max() / max(abs(energy[0]), 1e-300))))
    return rows


def fastest(rows: list[dict], level: float, method: str) -> dict | None:
    good = [r for r in rows if r["method"] == method and "seconds" in r and r["error_rel"] <= level]
    return min(good, key=lambda r: r["seconds"]) if good else None


def verdicts(rows: list[dict]) -> dict:
    """Per level: the default's fastest run, each method's, and the default's time over the fastest
    anchor's (Diffrax Tsit5 / Dopri8)."""
    methods = sorted({r["method"] for r in rows})
    out = {}
    for level in LEVELS:
        best = {m: fastest(rows, level, m) for m in methods}
        anchor = min((best[m] for m in ANCHORS if best.get(m)), key=lambda r: r["seconds"], default=None)
        d = best.get("default")
        winner = min((r for r in best.values() if r), key=lambda r: r["seconds"], default=None)
        out[f"{level:g}"] = {"fastest": {m: (r["seconds"], r["setting"]) for m, r in best.items() if r},
                             "default_over_anchor": d["seconds"] / anchor["seconds"] if d and anchor else None,
                             "fastest_method": winner["method"] if winner else None}
    return out


def run_problem(name, system, z0, interval, schemes) -> dict:
    t = np.linspace(*interval, 200)
    ref = reference(name, system, z0, interval, t) if name in ("kepler-e06", "henon-heiles", "double-pendulum") \
        else gauss_reference(system, z0, interval, t)[0]
    scale = float(np.ptp(ref, axis=0).max())
    rows = points("default", lambda tol: None, system, z0, interval, t, ref, scale)
    rows += points("gauss", lambda tol: GaussCollocation(), system, z0, interval, t, ref, scale)
    if system.separable:
        for scheme in schemes:
            rows += points(f"splitting-{scheme}", lambda tol, s=scheme: SplittingComposition(scheme=s),
                           system, z0, interval, t, ref, scale)
    rows += diffrax_points(system, z0, interval, t, ref, scale, tols=RK_TOLS)
    return {"interval": list(interval), "dim": system.dim, "scale": scale, "rows": rows, "levels": verdicts(rows)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    table = problem_table()
    parser.add_argument("--problems", nargs="*", default=list(table))
    parser.add_argument("--schemes", nargs="*", default=list(SCHEMES))
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    results = {}
    for name in args.problems:
        tic = time.perf_counter()
        results[name] = run_problem(name, *table[name], args.schemes)
        print(f"== {name} ({time.perf_counter() - tic:.0f} s)")
        for level, v in results[name]["levels"].items():
            ratio = v["default_over_anchor"]
            print(f"  {level}: fastest {v['fastest_method']}; default/anchor "
                  f"{'-' if ratio is None else f'{ratio:.2f}'}; " +
                  ", ".join(f"{m} {s * 1e3:.1f} ms" for m, (s, _) in sorted(v["fastest"].items(),
                                                                             key=lambda kv: kv[1][0])[:5]))
        if args.out:  # after every problem: a long run's record grows as it goes
            write_result(args.out, {"command": "python -m benchmarks.splitting_workprecision", "benchmark": "splitting_workprecision", "machine": machine_info(),
                                    "levels": list(LEVELS), "results": results})


if __name__ == "__main__":
    main()

"""Shooting's orbit solve before and after: SciPy's DOP853 with the variational equations beside
the state (before) against the compiled Gauss collocation with sensitivities from JAX (after,
:class:`atlasnn.solver.ParametricGauss`), on the built-in inverse problems (``henon-heiles-inverse``,
``pendulum-inverse``: their systems, data, unknowns and seeds, as ``atlasnn family`` makes them).

Per family and seed, each of the three fits that integrate — shooting from the guess alone,
the multistart (``Shooting()``: 13 starts), and the collocation fit (``CollocationFit()``, whose
polish is single shooting) — by both solvers, the order alternating seed by seed, in one process:
estimate, σ, seconds, solves and right-hand-side evaluations. Shooting from the guess is timed as
the median of ``--repeats`` fits. Before the timed rounds, one fit per solver and family measures
the first fit of a process (compiling, or loading from the caches on disk), and ``predict_fit`` at
400 times is timed both ways.

    python -m benchmarks.shooting_solver --out docs/benchmarks/shooting_solver.json
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from atlasnn.compile_cache import jax_time
from atlasnn.experiments.config import family_config_path, load_family
from atlasnn.inverse import CollocationFit, Shooting, fit, predict_fit, synthetic_observations

from benchmarks.common import machine_info, write_result

FAMILIES = ("henon-heiles-inverse", "pendulum-inverse")
SOLVERS = ("dop853", "gauss")


def _data(cfg, system, seed: int):
    """The family's observations for ``seed`` (as ``atlasnn family`` draws them)."""
    ob = cfg.observations
    times = np.sort(np.random.default_rng(ob.times_seed).uniform(ob.t0, ob.T, ob.n))
    return synthetic_observations(system, system.initial_state(), times, list(ob.names), ob.noise, seed, t0=ob.t0)


def _methods(solver: str) -> dict:
    return {"single": Shooting(starts=1, solver=solver), "multistart": Shooting(solver=solver),
            "collocation": CollocationFit(polish_solver=solver)}


def _row(result, seconds: float) -> dict:
    row = {"estimate": result.estimate.tolist(), "std": result.std.tolist(), "seconds": seconds,
           "solves": result.n_solves, "rhs": result.n_rhs, "trusted": bool(result.trusted)}
    if "polish_seconds" in result.search:
        row["polish_seconds"] = result.search["polish_seconds"]
    return row


def _timed(system, obs, unknowns, method, t0: float, seed: int, repeats: int):
    seconds = []
    for _ in range(repeats):
        tic = time.perf_counter()
        result = fit(system, obs, unknowns, method=method, t0=t0, seed=seed)
        seconds.append(time.perf_counter() - tic)
    return result, float(np.median(seconds))


def run_family(name: str, repeats: int, log) -> dict:
    cfg = load_family(family_config_path(name))
    system, unknowns, t0 = cfg.system.build(), list(cfg.unknowns), cfg.observations.t0
    first = {}
    obs = _data(cfg, system, cfg.seeds[0])
    for solver in SOLVERS:  # a fresh process's first fit: compiling (or loading) included
        with jax_time() as jt:
            tic = time.perf_counter()
            fit(system, obs, unknowns, method=Shooting(starts=1, solver=solver), t0=t0)
            first[solver] = {"seconds": time.perf_counter() - tic, **jt.summary()}
        log(f"{name}: first fit ({solver}) {first[solver]['seconds']:.2f} s, {jt.line()}")
    reference = fit(system, obs, unknowns, method=Shooting(starts=1, solver="dop853"), t0=t0)
    t = np.linspace(t0, float(obs.t[-1]), 400)
    predict = {}
    for solver in SOLVERS:
        predict_fit(system, reference, None, t, solver=solver)
        seconds = []
        for _ in range(repeats):
            tic = time.perf_counter()
            z = predict_fit(system, reference, None, t, solver=solver)
            seconds.append(time.perf_counter() - tic)
        predict[solver] = {"seconds": float(np.median(seconds)), "z": z}
    gap = float(np.max(np.abs(predict["gauss"]["z"] - predict["dop853"]["z"])))
    predict = {s: {"seconds": p["seconds"]} for s, p in predict.items()}
    predict["max_abs_difference"] = gap
    log(f"{name}: predict_fit at 400 times: dop853 {predict['dop853']['seconds'] * 1e3:.1f} ms, gauss "
        f"{predict['gauss']['seconds'] * 1e3:.1f} ms, largest difference {gap:.2g}")
    rows = []
    for i, seed in enumerate(cfg.seeds):
        obs = _data(cfg, system, seed)
        row = {"seed": seed}
        for method in ("single", "multistart", "collocation"):
            row[method] = {}
            for solver in (SOLVERS if i % 2 == 0 else SOLVERS[::-1]):
                result, seconds = _timed(system, obs, unknowns, _methods(solver)[method], t0, seed,
                                         repeats if method == "single" else 1)
                row[method][solver] = _row(result, seconds)
            a, b = row[method]["dop853"], row[method]["gauss"]
            row[method]["moved_sigmas"] = float(np.max(np.abs(np.subtract(a["estimate"], b["estimate"]))
                                                       / np.asarray(a["std"])))
            row[method]["std_ratio"] = float(np.max(np.asarray(b["std"]) / np.asarray(a["std"])))
            log(f"{name} seed {seed} {method}: dop853 {a['estimate']} ± {a['std'][0]:.2g} in {a['seconds']:.3f} s "
                f"({a['solves']} solves); gauss {b['estimate']} in {b['seconds']:.3f} s ({b['solves']} solves); "
                f"apart {row[method]['moved_sigmas']:.2g}σ")
        rows.append(row)
    summary = {}
    for method in ("single", "multistart", "collocation"):
        med = {s: float(np.median([r[method][s]["seconds"] for r in rows])) for s in SOLVERS}
        summary[method] = {"median_seconds": med, "speedup": med["dop853"] / med["gauss"],
                           "largest_moved_sigmas": max(r[method]["moved_sigmas"] for r in rows),
                           "largest_std_ratio": max(r[method]["std_ratio"] for r in rows)}
        if method == "collocation":
            summary[method]["median_polish_seconds"] = {
                s: float(np.median([r[method][s]["polish_seconds"] for r in rows])) for s in SOLVERS}
        got = summary[method]
        log(f"{name} {method}: median dop853 {med['dop853']:.3f} s, gauss {med['gauss']:.3f} s "
            f"({got['speedup']:.1f}x); estimates apart at most {got['largest_moved_sigmas']:.2g}σ")
    return {"family": name, "first_fit": first, "predict_fit": predict, "rows": rows, "summary": summary}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--repeats", type=int, default=5, help="fits per timing of shooting from the guess")
    ap.add_argument("--only", action="append", default=[], choices=FAMILIES)
    args = ap.parse_args()
    out = {"machine": machine_info(), "repeats": args.repeats, "families": []}
    for name in FAMILIES:
        if not args.only or name in args.only:
            out["families"].append(run_family(name, args.repeats, print))
    if args.out:
        write_result(args.out, out)


if __name__ == "__main__":
    main()

"""The Gauss collocation's stage count against the tolerance: which s reaches a given accuracy
fastest, measured on problems of several kinds (one core, compiled, the whole call with the dense
output on 200 times), with and without the contraction limit on window lengths.

For each problem, tolerance (rtol, atol = rtol/100) and stage count s: the
time of ``solve`` + evaluation (best of 3 after a first call), the max error over the output times
relative to the state's range against a reference (Kepler: its exact orbit; else the Gauss method
with s = 16 on windows a quarter of the default's), windows and iterations. The summary names, for
each accuracy level, the fastest (s, rtol) that reaches it: the table that
``GaussCollocation``'s order-from-tolerance rule (``stages=None``) follows.

    python -m benchmarks.gauss_orders --out docs/benchmarks/gauss_orders.json
    python -m benchmarks.gauss_orders --problems kepler-e06 --stages 4 8 12 --tols 1e-7 1e-11
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import jax
import numpy as np

from atlasnn import HamiltonianSystem, solve
from atlasnn.solver import GaussCollocation
from atlasnn.systems import builtin_system, expression_system, fput

from benchmarks.common import machine_info, write_result
from benchmarks.problems import gauss_reference, kepler_exact, kepler_system, timed

STAGES = (2, 3, 4, 6, 8, 10, 12, 16)
TOLS = (1e-5, 1e-7, 1e-9, 1e-11, 1e-13)
LEVELS = (1e-5, 1e-7, 1e-9, 1e-11)


def fput_chain(n: int, beta: float = 1.0, alpha: float = 0.0) -> HamiltonianSystem:
    """The built-in FPUT chain (``atlasnn.systems.fput``: n moving particles between fixed ends,
    unit masses and springs) started with q = 0 and p_i = sin(π i/(n + 1)) (the first normal mode)."""
    z0 = np.concatenate([np.zeros(n), np.sin(np.pi * np.arange(1, n + 1) / (n + 1))])
    return dataclasses.replace(fput(particles=n, alpha=alpha, beta=beta), z0=z0, name=f"fput-beta-{n}")


def problems() -> dict:
    """name -> (system, z0, interval)."""
    pendulum = expression_system(
        "(p1**2 + 2*p2**2 - 2*p1*p2*cos(q1 - q2)) / (2*(1 + sin(q1 - q2)**2)) - 2*cos(q1) - cos(q2)",
        ["q1", "q2"], ["p1", "p2"], z0=[1.0, 0.5, 0.0, 0.0], name="double-pendulum")
    hh = builtin_system("henon_heiles")
    kepler = kepler_system(0.6)
    chain = fput_chain(16)
    return {"henon-heiles": (hh, np.array([0.3, -0.3, 0.3, 0.15]), (0.0, 24 * math.pi)),
            "kepler-e06": (kepler, np.asarray(kepler.z0), (0.0, 20 * math.pi)),
            "double-pendulum": (pendulum, np.asarray(pendulum.z0), (0.0, 20.0)),
            "fput-beta-16": (chain, np.asarray(chain.z0), (0.0, 200.0))}


def reference(name, system, z0, interval, t):
    if name.startswith("kepler"):
        return kepler_exact(t, 0.6, z0)
    return gauss_reference(system, z0, interval, t)[0]


def measure(system, z0, interval, t, ref, scale, solver) -> dict:
    try:
        tic = time.perf_counter()
        solve(system, z0, interval, solver=solver)
        first = time.perf_counter() - tic
        (sol, z), best, _ = timed(lambda: (lambda s: (s, s(t)))(solve(system, z0, interval, solver=solver)))
    except Exception as exc:  # noqa: BLE001 - a march that cannot meet the tolerance is a result
        return {"failed": str(exc)[:160]}
    return {"seconds": best, "first_call_seconds": first, "error_rel": float(np.abs(z - ref).max() / scale),
            "windows": sol.n_windows, "iterations": sol.info["iterations"], "newton_windows": sol.info["newton_windows"]}


def fastest(rows: list[dict], level: float) -> dict | None:
    """The fastest row whose error is at most ``level``."""
    good = [r for r in rows if "seconds" in r and r["error_rel"] <= level]
    return min(good, key=lambda r: r["seconds"]) if good else None


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problems", nargs="*", default=None)
    parser.add_argument("--stages", nargs="*", type=int, default=list(STAGES))
    parser.add_argument("--tols", nargs="*", type=float, default=list(TOLS))
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    table = problems()
    names = args.problems or list(table)
    results = {}
    for name in names:
        system, z0, interval = table[name]
        t = np.linspace(*interval, 200)
        ref = reference(name, system, z0, interval, t)
        scale = float(np.ptp(ref, axis=0).max())
        rows = []
        for s in args.stages:
            for tol in args.tols:
                if s < -math.log10(tol) / 3:  # order 2s far below the tolerance's digits: minutes, never the fastest
                    continue
                solver = GaussCollocation(stages=s, rtol=tol, atol=tol / 100)
                row = {"stages": s, "rtol": tol, **measure(system, z0, interval, t, ref, scale, solver)}
                rows.append(row)
                print(name, {k: (f"{v:.3g}" if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
        best = {f"{level:g}": fastest(rows, level) for level in LEVELS}
        by_rtol = {f"{tol:g}": min((r for r in rows if r["rtol"] == tol and "seconds" in r), key=lambda r: r["seconds"],
                                   default=None) for tol in args.tols}
        results[name] = {"rows": rows, "fastest": best, "fastest_at_rtol": by_rtol}
        for level, row in best.items():
            print(f"  {name}: error <= {level}: {row}", flush=True)
    if args.out:
        write_result(args.out, {"machine": machine_info(), "command": "python -m benchmarks.gauss_orders",
                                "results": results})
    for tol in args.tols:
        picks = {name: (r["fastest_at_rtol"][f"{tol:g}"] or {}).get("stages") for name, r in results.items()}
        print(f"rtol {tol:g}: fastest s per problem {picks}")


if __name__ == "__main__":
    main()

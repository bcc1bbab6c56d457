"""The nonlinear Schrödinger equation by the explicit splitting solver (the linear part's exact flow
composed with the phase rotation, at the order the tolerance picks) against split-step Fourier
Yoshida-4 and ETDRK4 written in JAX, and the Gauss solver (``solve``'s default there), at equal
accuracy (one core, compiled; the soliton on M = 512 points over [0, 5], its exact solution as the
reference; the end state).

For each tolerance of ``SplittingComposition()``: its error, time, the mass drift, and the fastest
run of each rival at least as accurate (``benchmarks.nls_pde``'s sweeps over the step count).

    taskset -c 1 python -m benchmarks.splitting_nls --out docs/benchmarks/splitting_nls.json
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from atlasnn.solver import SplittingComposition, solve
from atlasnn.systems import nls, nls_mass, nls_soliton

from benchmarks.common import machine_info, write_result
from benchmarks.nls_pde import LENGTH, atlasnn_points, fastest_as_accurate, split_points
from benchmarks.problems import timed

TOLS = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)


def default_points(system, T, exact) -> list[dict]:
    rows = []
    for tol in TOLS:
        run = lambda: solve(system, system.z0, (0.0, T), solver=SplittingComposition(), rtol=tol,  # noqa: E731
                            atol=tol * 1e-2)
        tic = time.perf_counter()
        run()
        first = time.perf_counter() - tic
        (sol, z), best, _ = timed(lambda: (lambda s: (s, s(np.asarray([T]))[0]))(run()))
        rows.append({"rtol": tol, "seconds": best, "first_call_seconds": first, "solver": sol.info["solver"],
                     "scheme": sol.info.get("scheme"), "steps": sol.n_windows,
                     "error": float(np.max(np.abs(z - exact))),
                     "mass_drift": float(abs(nls_mass(z) / nls_mass(system.z0) - 1))})
        print("splitting", rows[-1], flush=True)
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=512)
    parser.add_argument("--T", type=float, default=5.0)
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    system = nls(points=args.points, length=LENGTH)
    exact = nls_soliton(args.T, args.points, LENGTH)
    out = {"points": args.points, "length": LENGTH, "T": args.T,
           "default": default_points(system, args.T, exact),
           "gauss": atlasnn_points(system, system.z0, args.T, exact, (1e-6, 1e-8, 1e-10, 1e-12)),
           "yoshida4": split_points(system, args.points, args.T, exact, 4),
           "etdrk4": split_points(system, args.points, args.T, exact, 0)}
    for row in out["default"]:
        row["against"] = {}
        for rival in ("gauss", "yoshida4", "etdrk4"):
            best = fastest_as_accurate(out[rival], row["error"])
            row["against"][rival] = None if best is None else {"seconds": best["seconds"], "error": best["error"],
                                                               "ratio": row["seconds"] / best["seconds"]}
        ratios = {k: "never" if v is None else f"{v['ratio']:.2f}" for k, v in row["against"].items()}
        print(f"rtol {row['rtol']:g}: error {row['error']:.1e} in {row['seconds'] * 1e3:.1f} ms; ratios {ratios}")
    if args.out:
        write_result(args.out, {"command": "python -m benchmarks.splitting_nls", "benchmark": "splitting_nls", "machine": machine_info(), **out})


if __name__ == "__main__":
    main()

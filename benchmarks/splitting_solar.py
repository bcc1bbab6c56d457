"""The outer solar system (Hairer, Lubich & Wanner's, ``benchmarks.outer_solar``) over 10⁶ days by
the explicit splitting solver, beside the Gauss solver and REBOUND's IAS15 and WHFast as
``benchmarks.rebound_anchor`` recorded them (docs/benchmarks/rebound_anchor.json, same machine).

The reference: the Gauss collocation at s = 16 with windows of 129.2 days (rebound_anchor's); the
position error is the largest over the bodies' coordinates at T, the energy error the largest
|H/H0 − 1| over 2 000 output times. Times: the best of 3 after a first call.

    taskset -c 1 python -m benchmarks.splitting_solar --out docs/benchmarks/splitting_solar.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation, SplittingComposition

from benchmarks.common import machine_info, write_result
from benchmarks.outer_solar import outer_solar_system
from benchmarks.problems import timed

T = 1e6
RUNS = (("kahan_li8", 1e-9), ("sofspa10", 1e-10), ("kahan_li8", 1e-11), ("sofspa10", 1e-12))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    system = outer_solar_system()
    ref = solve(system, None, (0.0, T), solver=GaussCollocation(stages=16, h=129.2)).end_state
    t = np.linspace(0.0, T, 2000)
    rows = []
    for scheme, rtol in RUNS:
        solver = SplittingComposition(scheme=scheme, rtol=rtol)
        solve(system, None, (0.0, T), solver=solver)
        sol, seconds, _ = timed(lambda: solve(system, None, (0.0, T), solver=solver))
        energy = system.energy64(sol(t))
        rows.append({"method": f"splitting {scheme}", "setting": rtol, "seconds": seconds, "steps": sol.n_steps,
                     "position_error_au": float(np.abs(sol.end_state[:18] - ref[:18]).max()),
                     "energy_error": float(np.abs(energy / energy[0] - 1).max())})
        print(rows[-1], flush=True)
    anchor = json.loads(Path("docs/benchmarks/rebound_anchor.json").read_text())
    kept = [r for r in anchor["rows"] if r["method"] in ("atlasnn", "ias15", "whfast")]
    if args.out:
        write_result(args.out, {"command": "python -m benchmarks.splitting_solar", "machine": machine_info(),
                                "T_days": T, "rows": rows, "from_rebound_anchor": kept})


if __name__ == "__main__":
    main()

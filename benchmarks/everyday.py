"""Everyday tolerances: the default Gauss solver against Tsit5, Dopri8 and Yoshida-4 at equal
accuracy, on small problems, one core, compiled, the whole call with values at 200 times.

Problems (those of ``benchmarks.gauss_orders``): Hénon–Heiles [0, 24π], Kepler e = 0.6 over 10
periods (against its exact orbit), the double pendulum [0, 20] (both against the Gauss collocation
at s = 16 on windows a quarter of the default's). For each accuracy level (max error over the
output times / the state's range ≤ 1e-5, 1e-7, 1e-9, 1e-11), each method's fastest run that reaches
it, over a sweep of its setting: ``GaussCollocation(rtol=r, atol=r/100)`` with the stage count it
picks from rtol (the default a user gets when asking for a tolerance), Diffrax's Tsit5 and Dopri8
(rtol 1e-3 … 1e-14, compiled, float64), and Yoshida-4 (compiled, 199 … 51 200 steps; separable
problems only). Times: the best of 3 after a first call.

    taskset -c 1 python -m benchmarks.everyday --out docs/benchmarks/everyday.json
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from atlasnn.solver import GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.gauss_orders import LEVELS, fastest, problems, reference
from benchmarks.solver_workprecision import diffrax_points, solver_points, yoshida_points

GAUSS_TOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
RK_TOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14)
ANCHORS = ("diffrax-tsit5", "diffrax-dopri8", "yoshida4")
NAMES = ("henon-heiles", "kepler-e06", "double-pendulum")


def verdicts(rows: list[dict]) -> dict:
    """Per level: the fastest Gauss run reaching it, the fastest of each anchor, and the Gauss
    time over the fastest anchor's (≤ 1: the target met)."""
    out = {}
    for level in LEVELS:
        g = fastest([r for r in rows if r["method"] == "gauss"], level)
        anchors = {m: fastest([r for r in rows if r["method"] == m], level) for m in ANCHORS}
        best = min((a for a in anchors.values() if a), key=lambda a: a["seconds"], default=None)
        out[f"{level:g}"] = {"gauss": g, **anchors,
                             "ratio": g["seconds"] / best["seconds"] if g and best else None,
                             "fastest_anchor": best["method"] if best else None}
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problems", nargs="*", default=list(NAMES))
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    table = problems()
    results = {}
    for name in args.problems:
        system, z0, interval = table[name]
        t = np.linspace(*interval, 200)
        ref = reference(name, system, z0, interval, t)
        scale = float(np.ptp(ref, axis=0).max())
        rows = (solver_points("gauss", lambda r: GaussCollocation(rtol=r, atol=r / 100), GAUSS_TOLS, system, z0,
                              interval, t, ref, scale)
                + diffrax_points(system, z0, interval, t, ref, scale, RK_TOLS)
                + yoshida_points(system, z0, interval, t, ref, scale))
        results[name] = {"interval": list(interval), "range": scale, "rows": rows, "levels": verdicts(rows)}
        for level, v in results[name]["levels"].items():
            g = v["gauss"]
            cells = [f"{m} {v[m]['seconds'] * 1e3:.3g} ms" for m in ANCHORS if v[m]]
            ratio = "—" if v["ratio"] is None else f"{v['ratio']:.2f}"
            gauss = f"{g['seconds'] * 1e3:.3g} ms (rtol {g['setting']:g}, s = {g['stages']})" if g else "never"
            print(f"{name:16s} ≤ {level}: gauss {gauss}; {', '.join(cells)}; ratio {ratio}", flush=True)
    if args.out:
        write_result(args.out, {"command": "python -m benchmarks.everyday", "machine": machine_info(),
                                "output_times": 200, "levels": [f"{x:g}" for x in LEVELS], "results": results})


if __name__ == "__main__":
    main()

"""What the Gauss collocation's error estimate does not see: round-off carried along an
ill-conditioned orbit. Kepler orbits of rising eccentricity over 10 periods at the defaults: the
estimate (a companion on half windows: truncation error), the error against the exact orbit, and
the float64 floor there — how far two tight solutions (s = 12 and s = 16, adaptive, rtol 1e-14)
are from each other, which no float64 march can get below — and the same method on constant windows
of the default's shortest length and of half of it: where halving the windows makes the error
larger, round-off, not truncation, is what is left.

    python -m benchmarks.gauss_roundoff --out docs/benchmarks/gauss_roundoff.json
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from atlasnn import solve
from atlasnn.solver import GaussCollocation

from benchmarks.common import machine_info, write_result
from benchmarks.problems import kepler_exact, kepler_system

ECCENTRICITIES = (0.6, 0.9, 0.95, 0.99)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/gauss_roundoff.json")
    ap.add_argument("--periods", type=int, default=10)
    args = ap.parse_args(argv)
    rows = []
    for e in ECCENTRICITIES:
        system, T = kepler_system(e), 2 * math.pi * args.periods
        t = np.linspace(0.0, T, 4001)
        exact = kepler_exact(t, e)
        scale = float(np.ptp(exact, axis=0).max())
        sol = solve(system, None, (0.0, T))
        tight = [solve(system, None, (0.0, T), solver=GaussCollocation(stages=s, steps="adaptive", rtol=1e-14,
                                                                         atol=1e-16))(t) for s in (12, 16)]
        row = {"e": e, "periods": args.periods, "windows": sol.n_windows,
               "estimate_rel": sol.estimate().max_abs / scale,
               "error_rel": float(np.abs(sol(t) - exact).max()) / scale,
               "floor_rel": float(np.abs(tight[0] - tight[1]).max()) / scale}
        row["estimate_over_error"] = row["estimate_rel"] / row["error_rel"]
        # round-off, not truncation: the same method on constant windows of the default's shortest
        # length and of half of it (16× less truncation error per window, twice the windows)
        h = float(np.diff(sol.edges)[:-1].min())
        for key, length in (("given_h", h), ("given_h_half", h / 2)):
            other = solve(system, None, (0.0, T), solver=GaussCollocation(h=length))
            row[key] = {"h": length, "windows": other.n_windows, "estimate_rel": other.estimate().max_abs / scale,
                        "error_rel": float(np.abs(other(t) - exact).max()) / scale}
        rows.append(row)
        print(f"e = {e}: estimate {row['estimate_rel']:.1e}, error {row['error_rel']:.1e} of the range "
              f"(estimate / error {row['estimate_over_error']:.2f}); two tight solutions {row['floor_rel']:.1e} apart; "
              f"h = shortest: error {row['given_h']['error_rel']:.1e}, h / 2: {row['given_h_half']['error_rel']:.1e}",
              flush=True)
    write_result(args.out, {"command": "python -m benchmarks.gauss_roundoff " + " ".join(argv or []),
                            "machine": machine_info(), "rows": rows})


if __name__ == "__main__":
    main()

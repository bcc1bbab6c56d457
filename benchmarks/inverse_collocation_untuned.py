"""The simultaneous collocation fit (:func:`atlasnn.inverse.fit_collocation`, default settings) on
inverse problems it was not tuned on: a Duffing oscillator's quartic coefficient, Kepler's GM on an
eccentric orbit, a double pendulum's gravity, a pendulum observed only from t = 4 on, a pendulum
observed through its momentum only, and an unknown initial momentum. 1 % noise, irregular times,
one noise draw per case; five guesses spread over the bounds. "Global minimum": within 0.5σ of
shooting started at the truth (an independent fit).

    python -m benchmarks.inverse_collocation_untuned --out docs/benchmarks/inverse_collocation_untuned.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from atlasnn import AtlasError, Unknown
from atlasnn.inverse import fit_collocation, fit_shooting, synthetic_observations
from atlasnn.systems import expression_system

from benchmarks.common import machine_info

PENDULUM = ("p**2/2 - g*cos(x)", ["x"], ["p"])
DUFFING = ("p**2/2 + x**2/2 + b*x**4/4", ["x"], ["p"])


def cases() -> dict[str, dict]:
    """name -> system (at the truth), observed names, record [first, T] with n times, the unknown."""
    pend = expression_system(*PENDULUM, params={"g": 1.0}, z0=[1.0, 0.0], name="pendulum")
    duff = expression_system(*DUFFING, params={"b": 0.5}, z0=[1.5, 0.0], name="duffing")
    kepler = expression_system("(px**2+py**2)/2 - k/sqrt(x**2+y**2)", ["x", "y"], ["px", "py"], params={"k": 1.0},
                               z0=[1.0, 0.0, 0.0, 1.2], name="kepler")
    double = expression_system("(p1**2 + 2*p2**2 - 2*p1*p2*cos(a-b))/(2*(1+sin(a-b)**2)) - 2*g*cos(a) - g*cos(b)",
                               ["a", "b"], ["p1", "p2"], params={"g": 1.0}, z0=[0.5, 0.3, 0.0, 0.0], name="double")
    return {
        "duffing-b": dict(system=duff, names=["x"], first=0.0, T=15.0, n=40, unknown=("b", 0.5, 0.0, 3.0)),
        "kepler-k (e = 0.44)": dict(system=kepler, names=["x", "y"], first=0.0, T=20.0, n=60,
                                    unknown=("k", 1.0, 0.5, 2.0)),
        "double-pendulum-g": dict(system=double, names=["a", "b"], first=0.0, T=10.0, n=50,
                                  unknown=("g", 1.0, 0.3, 3.0)),
        "pendulum, data from t = 4": dict(system=pend, names=["x"], first=4.0, T=12.0, n=30,
                                          unknown=("g", 1.0, 0.5, 2.0)),
        "pendulum, momentum only": dict(system=pend, names=["p"], first=0.0, T=10.0, n=30,
                                        unknown=("g", 1.0, 0.5, 2.0)),
        "duffing, initial momentum": dict(system=duff, names=["x"], first=0.0, T=10.0, n=30,
                                          unknown=("z0.p", 0.0, -1.0, 1.0)),
    }


def run_case(name: str, case: dict, guesses: int) -> dict:
    system, (uname, truth, lo, hi) = case["system"], case["unknown"]
    times = np.sort(np.random.default_rng(3).uniform(case["first"], case["T"], case["n"]))
    obs = synthetic_observations(system, system.initial_state(), times, case["names"], 0.01, 0)
    best = fit_shooting(system, obs, [Unknown(uname, truth, lo, hi)])
    rows = []
    for g in np.linspace(lo, hi, guesses + 2)[1:-1]:
        try:
            fit = fit_collocation(system, obs, [Unknown(uname, float(g), lo, hi)])
        except AtlasError as exc:
            rows.append({"guess": float(g), "refused": str(exc)})
            continue
        rows.append({"guess": float(g), "estimate": float(fit.estimate[0]), "std": float(fit.std[0]),
                     "global_minimum": bool(abs(fit.estimate[0] - best.estimate[0]) <= 0.5 * best.std[0]),
                     "trusted": bool(fit.trusted), "notes": fit.notes, "seconds": fit.wall_time,
                     "windows": fit.search["windows"], "lm_steps": fit.search["lm_steps"],
                     "collocation_estimate": fit.search["collocation_estimate"][0]})
    fitted = [r for r in rows if "estimate" in r]
    return {"case": name, "truth": truth, "global_minimum": float(best.estimate[0]), "global_std": float(best.std[0]),
            "rows": rows, "reached": sum(r["global_minimum"] for r in fitted),
            "confident_wrong": sum(r["trusted"] and not r["global_minimum"] for r in fitted),
            "marked": sum(not r["trusted"] for r in fitted), "fits": len(rows),
            "median_seconds": float(np.median([r["seconds"] for r in fitted])) if fitted else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--guesses", type=int, default=5)
    args = ap.parse_args()
    out = {"machine": machine_info(), "guesses": args.guesses, "cases": []}
    for name, case in cases().items():
        res = run_case(name, case, args.guesses)
        out["cases"].append(res)
        print(f"{name}: global minimum from {res['reached']}/{res['fits']} guesses, {res['marked']} marked, "
              f"{res['confident_wrong']} confident wrong, median {res['median_seconds']:.2f} s", flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()

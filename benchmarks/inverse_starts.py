"""Inverse problems from bad starts: a grid of first guesses across the bounds, single shooting
(one start: the guess) against the multistart (:func:`atlasnn.inverse.fit_multistart`: the guess
and 12 Halton starts per unknown over the bounds) and, on a few guesses, the joint network fit
cross-checked against the multistart. Data made here, never seen by the defaults: positions only,
1 % noise, irregular times, one noise draw per case.

Per fit: the estimate, σ, whether it is marked untrusted; "global minimum" = within 0.5σ of the
data's global minimum (shooting started at the truth), "recovered" = within 2σ of the truth (one
noise draw per case: a draw 2–4σ off makes every fit of that case miss this, whatever the start);
"confident wrong" = not marked and more than 4σ from the truth (the failure the issue forbids).

    python -m benchmarks.inverse_starts --out docs/benchmarks/inverse_starts.json
    python -m benchmarks.inverse_starts --only hh-builtin --append --out docs/benchmarks/inverse_starts.json
    python -m benchmarks.inverse_starts --column collocation --out docs/benchmarks/inverse_starts.json
    python -m benchmarks.inverse_starts --column segments --out docs/benchmarks/inverse_starts.json

The simultaneous collocation fit (:func:`atlasnn.inverse.fit_collocation`) and multiple shooting
with ``segments="auto"`` from the guess alone run from every guess too; ``--column NAME`` adds
(or refreshes) that column in an existing JSON without refitting the others (the data and the
grid are deterministic).
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np

from atlasnn import AtlasError, Unknown
from atlasnn.inverse import fit_shooting, synthetic_observations
from atlasnn.inverse import JointConfig, fit_collocation, fit_joint, fit_multistart, judge_fit
from atlasnn.systems import expression_system

from benchmarks.common import machine_info

HH = "(px**2 + py**2)/2 + (x**2 + y**2)/2 + lam*(x**2*y - y**3/3)"


def _hh(z0, lam):
    return expression_system(HH, ["x", "y"], ["px", "py"], params={"lam": lam}, z0=z0, name="hh")


def cases() -> dict[str, dict]:
    """name -> system (at the truth), observed names, record, unknowns' truth and bounds."""
    pend = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], params={"g": 1.0}, z0=[1.0, 0.0], name="pendulum")
    return {
        "hh-coupling": dict(system=_hh([0.3, -0.3, 0.3, 0.15], 0.8), names=["x", "y"], n=50, T=20.0,
                            unknowns={"lam": (0.8, 0.2, 1.5)}),
        "hh-chaotic-long": dict(system=_hh([0.0, -0.1, 0.4788875998951459, 0.1], 1.0), names=["x", "y"], n=100,
                                T=40.0, unknowns={"lam": (1.0, 0.5, 1.5)}),
        "pendulum": dict(system=pend, names=["x"], n=40, T=8.0, unknowns={"g": (1.0, 0.5, 2.0)}),
        "pendulum-long": dict(system=pend, names=["x"], n=80, T=40.0, unknowns={"g": (1.0, 0.5, 2.0)}),
        # the built-in henon-heiles-inverse's problem (its truth, record and bounds; our own noise draw)
        "hh-builtin": dict(system=_hh([0.3, -0.3, 0.3, 0.15], 1.0), names=["x", "y"], n=50, T=10.0,
                           unknowns={"lam": (1.0, 0.2, 2.0)}),
        "hh-coupling-and-momentum": dict(system=_hh([0.3, -0.3, 0.3, 0.15], 0.8), names=["x", "y"], n=50, T=20.0,
                                         unknowns={"lam": (0.8, 0.2, 1.5), "z0.px": (0.3, 0.0, 0.6)}),
    }


def guesses(unknowns: dict, count: int) -> list[tuple[float, ...]]:
    """An evenly spaced grid inside the bounds (count points for one unknown, ~count for more)."""
    per = max(2, round(count ** (1 / len(unknowns))))
    axes = [np.linspace(lo, hi, per + 2)[1:-1] for _, lo, hi in unknowns.values()]
    return [tuple(float(x) for x in p) for p in itertools.product(*axes)]


def score(fit, truth: np.ndarray, best) -> dict:
    """``best``: the data's global minimum (shooting started at the truth): a fit within 0.5σ of it
    reached it, wherever the noise draw put it."""
    err = np.abs(np.asarray(fit.estimate) - truth)
    sigma = np.where(np.isfinite(fit.std), fit.std, np.inf)
    at_best = np.all(np.abs(np.asarray(fit.estimate) - best.estimate) <= 0.5 * best.std)
    return {"estimate": fit.estimate.tolist(), "std": fit.std.tolist(), "trusted": bool(fit.trusted),
            "global_minimum": bool(at_best), "recovered": bool(np.all(err <= 2 * sigma)),
            "confident_wrong": bool(fit.trusted and np.any(err > 4 * sigma)),
            "seconds": fit.wall_time, "notes": list(fit.notes), "method": fit.method}


def _data(case: dict):
    """(observations, truth, the data's global minimum: shooting started at the truth)."""
    system, truth_d = case["system"], case["unknowns"]
    times = np.sort(np.random.default_rng(7).uniform(0.0, case["T"], case["n"]))
    obs = synthetic_observations(system, system.initial_state(), times, case["names"], 0.01, 0)
    at_truth = [Unknown(n, t, lo, hi) for n, (t, lo, hi) in truth_d.items()]
    best = fit_shooting(system, obs, at_truth)  # checked: the multistarts and the collocation fits agree
    return obs, np.array([v[0] for v in truth_d.values()]), best


def _collocation(case: dict, obs, unknowns, truth, best) -> dict:
    fit = fit_collocation(case["system"], obs, unknowns)
    row = score(fit, truth, best)
    row.update(windows=fit.search["windows"], lm_steps=fit.search["lm_steps"],
               collocation_estimate=fit.search["collocation_estimate"],
               polish_moved_sigmas=fit.search.get("polish_moved_sigmas"))
    return row


def summarise(rows: list[dict]) -> dict:
    summary = {}
    for method in ("single", "segments", "multistart", "joint", "collocation"):
        rs = [r[method] for r in rows if method in r]
        if rs:
            summary[method] = {"fits": len(rs), "global_minimum": sum(r["global_minimum"] for r in rs),
                               "global_or_marked": sum(r["global_minimum"] or not r["trusted"] for r in rs),
                               "recovered": sum(r["recovered"] for r in rs),
                               "recovered_or_marked": sum(r["recovered"] or not r["trusted"] for r in rs),
                               "confident_wrong": sum(r["confident_wrong"] for r in rs),
                               "median_seconds": float(np.nanmedian([r.get("seconds", np.nan) for r in rs]))}
    return summary


def _segments(case: dict, obs, unknowns, truth, best) -> dict:
    """Multiple shooting from the guess alone, segments="auto"."""
    try:
        fit = judge_fit(fit_shooting(case["system"], obs, unknowns, segments="auto"), unknowns)
    except AtlasError as exc:  # refused at the guess: not a confident answer
        return {"refused": str(exc), "trusted": False, "recovered": False, "global_minimum": False,
                "confident_wrong": False}
    return {**score(fit, truth, best), "segments": fit.segments}


#: the columns that --column can add to an existing JSON
COLUMNS = {"collocation": _collocation, "segments": _segments}


def add_column(column: str, name: str, case: dict, result: dict, log) -> None:
    """Fit every guess of an existing case's rows by one more method; refresh its summary."""
    obs, truth, best = _data(case)
    for row in result["rows"]:
        unknowns = [Unknown(n, x, lo, hi) for (n, (_, lo, hi)), x in zip(case["unknowns"].items(), row["guess"])]
        row[column] = got = COLUMNS[column](case, obs, unknowns, truth, best)
        log(f"{name} guess {row['guess']}: {column} {got.get('estimate', got.get('refused'))} "
            f"{'trusted' if got['trusted'] else 'UNTRUSTED'} {got.get('seconds', 0.0):.2f} s")
    result["summary"] = summarise(result["rows"])


def run_case(name: str, case: dict, count: int, joint: int, log) -> dict:
    system, truth_d = case["system"], case["unknowns"]
    obs, truth, best = _data(case)
    rows, grid = [], guesses(truth_d, count)
    joint_at = set(np.linspace(0, len(grid) - 1, joint).round().astype(int).tolist()) if joint else set()
    for i, g in enumerate(grid):
        unknowns = [Unknown(n, x, lo, hi) for (n, (_, lo, hi)), x in zip(truth_d.items(), g)]
        row = {"guess": list(g)}
        try:
            row["single"] = score(fit_shooting(system, obs, unknowns), truth, best)
        except AtlasError as exc:  # refused at the guess: not a confident answer
            row["single"] = {"refused": str(exc), "trusted": False, "recovered": False, "global_minimum": False,
                             "confident_wrong": False}
        multi = fit_multistart(system, obs, unknowns)
        row["multistart"] = score(multi, truth, best)
        row["multistart"]["minima"] = multi.search["minima"]
        row["multistart"]["failed_starts"] = multi.search["failed_starts"]
        if i in joint_at:  # spread over the grid, the worst guesses included
            tic = time.perf_counter()
            jf = fit_joint(system, obs, unknowns, config=JointConfig(), seed=0)
            jf = judge_fit(jf, unknowns, system=system, observations=obs, better=multi)
            row["joint"] = {**score(jf, truth, best), "seconds": time.perf_counter() - tic}
        row["collocation"] = _collocation(case, obs, unknowns, truth, best)
        row["segments"] = _segments(case, obs, unknowns, truth, best)
        rows.append(row)
        log(f"{name} guess {g}: " + "; ".join(f"{k} {r.get('estimate', r.get('refused', '?'))} "
                                              f"{'trusted' if r['trusted'] else 'UNTRUSTED'}"
                                              for k, r in row.items() if k != "guess"))
    summary = summarise(rows)
    return {"case": name, "truth": truth.tolist(), "global_minimum": best.estimate.tolist(), "global_std": best.std.tolist(), "names": list(truth_d), "observed": case["names"], "n": case["n"],
            "T": case["T"], "rows": rows, "summary": summary}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--guesses", type=int, default=20)
    ap.add_argument("--joint", type=int, default=4, help="guesses per case (spread over the grid) also fitted by the joint network")
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--append", action="store_true", help="add the cases run to those already in --out")
    ap.add_argument("--column", choices=sorted(COLUMNS), default=None,
                    help="fit only this column into the cases already in --out")
    args = ap.parse_args()
    out = {"machine": machine_info(), "guesses": args.guesses, "cases": []}
    if args.append and args.out and args.out.is_file():
        out = json.loads(args.out.read_text(encoding="utf-8"))
    if args.column:
        out = json.loads(args.out.read_text(encoding="utf-8"))
        out[f"{args.column}_machine"] = machine_info()
        for result in out["cases"]:
            if not args.only or result["case"] in args.only:
                add_column(args.column, result["case"], cases()[result["case"]], result, print)
                print(result["case"], json.dumps(result["summary"][args.column]))
        args.out.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
        return
    for name, case in cases().items():
        if args.only and name not in args.only:
            continue
        res = run_case(name, case, args.guesses, args.joint, print)
        out["cases"] = [c for c in out["cases"] if c["case"] != name] + [res]
        print(name, json.dumps(res["summary"]))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()

"""Effectivity of the a-posteriori error estimate over deliberately good and bad trainings.

For every case: train (Adam only, the budget given: from far too short to enough), estimate the
error with no reference (``solution.estimate()``), then compare with the true error against DOP853
(rtol = atol = 1e-12) at the estimate's nodes. effectivity = max_t ‖δ(t)‖ / max_t ‖e(t)‖ (Euclidean
over the state). Also reported: the Gronwall bound (log-norm) and how long it stays within 10× of
the true error, the time up to which the estimate is trusted (‖δ‖ ≤ 5 % of the range), and the
pointwise ratio ‖δ(t)‖/‖e(t)‖ where ‖e‖ > 1e-5 × range.

    python -m benchmarks.estimate_effectivity [--quick] [--out docs/benchmarks/estimate_effectivity.json]

Cases: the nonlinear oscillator on [0, 4π] (5 budgets × 3 seeds, and the paper's three models),
Hénon–Heiles on [0, 6π] (4 budgets × 2 seeds), time-marching on fixed windows (Hénon–Heiles [0, 24π],
Kepler e = 0.6 over two orbits, the pendulum near its separatrix, and a chaotic Hénon–Heiles orbit
near the escape energy; budgets 300–4000 epochs per window). About 10 minutes on one core.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from atlasnn.evaluation import reference_solution
from atlasnn.nn import make_model
from atlasnn.solutions import Solution, residual_bound
from atlasnn.systems import builtin_system, expression_system
from atlasnn.training import DEFAULT_NETWORK, DEFAULT_WINDOW_TRAIN, MarchConfig, march, train

SYSTEMS = {
    "oscillator": lambda: builtin_system("nonlinear_oscillator"),
    "henon_heiles": lambda: builtin_system("henon_heiles"),
    "kepler": lambda: expression_system("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"],
                                        separable=True, z0=[0.4, 0.0, 0.0, 2.0], name="kepler"),
    "pendulum": lambda: expression_system("p**2/2 - cos(q)", ["q"], ["p"], separable=True, z0=[0.0, 1.99],
                                          name="pendulum"),
    "henon_heiles_chaotic": lambda: builtin_system("henon_heiles", z0=(0.0, -0.1, 0.55, 0.1)),
}
PAPER_NET = {"width": 50, "depth": 2, "activation": "sin", "first_layer_scale": 1.0}


def cases(quick: bool) -> list[dict]:
    out = []
    seeds = (0,) if quick else (0, 1, 2)
    for seed in seeds:
        for epochs in ((300, 3000) if quick else (300, 600, 1500, 3000, 8000)):
            out.append(dict(id=f"osc-direct-e{epochs}-s{seed}", system="oscillator", T=4 * math.pi, epochs=epochs,
                            n_points=200, seed=seed, lam_reg=1.0))
    if not quick:
        for seed in (0, 1):
            for epochs in (1000, 2000, 4000, 12000):
                out.append(dict(id=f"hh-direct-e{epochs}-s{seed}", system="henon_heiles", T=6 * math.pi,
                                epochs=epochs, n_points=400, seed=seed, lam_reg=0.5))
        for model in ("hnn", "atlas_tanh", "atlas_exp"):  # the paper's oscillator-short set-up, 10 000 epochs
            out.append(dict(id=f"osc-paper-{model}-s0", system="oscillator", T=4 * math.pi, epochs=10000,
                            n_points=200, seed=0, lam_reg=1.0, net={"scaling": model, **PAPER_NET},
                            train={"lr": 8e-3, "betas": (0.999, 0.9999), "sigma": 0.03 * 4 * math.pi,
                                   "lr_schedule": "constant", "causal_eps": 0.0, "best_rule": "release"}))
    marching = [("hh", "henon_heiles", 24 * math.pi, 4 * math.pi, 0.5), ("kepler", "kepler", 4 * math.pi, math.pi / 2, 1.0),
                ("pendulum", "pendulum", 16.0, 1.0, 1.0), ("hhchaos", "henon_heiles_chaotic", 24 * math.pi, 4 * math.pi, 0.5)]
    for tag, name, T, window, lam in marching[: 2 if quick else 4]:
        for epochs, seed in (((1000, 0),) if quick else ((4000, 0), (4000, 1), (1000, 0), (300, 0))):
            out.append(dict(id=f"{tag}-march-e{epochs}-s{seed}", system=name, T=T, window=window, epochs=epochs,
                            seed=seed, lam_reg=lam))
    return out


def trained(case: dict, system):
    cfg = DEFAULT_WINDOW_TRAIN.replace(epochs=case["epochs"], seed=case["seed"], progress=False, lam_reg=case["lam_reg"],
                                       chunk=min(2000, case["epochs"]), **case.get("train", {}))
    model = make_model(system.z0, **case.get("net", DEFAULT_NETWORK), seed=case["seed"])
    if "window" in case:  # Adam alone per window, fixed windows: the estimate sees bad windows too
        return march(model, system, case["T"], MarchConfig(window=case["window"], train=cfg, polish=None))
    res = train(model, system, case["T"], cfg.replace(n_points=case["n_points"]))
    return Solution(res.model, system, (0.0, case["T"]))


def analyse(case: dict) -> dict:
    system = SYSTEMS[case["system"]]()
    start = time.perf_counter()
    sol = trained(case, system)
    train_s = time.perf_counter() - start
    start = time.perf_counter()
    est = sol.estimate(z0=system.z0)
    est_s = time.perf_counter() - start
    unique, inverse = np.unique(est.t, return_inverse=True)
    ref = reference_solution(system, system.z0, unique)[inverse]
    e = np.linalg.norm(ref - est.z, axis=1)
    d = est.norm
    scale = float((ref.max(0) - ref.min(0)).max())
    _, bound = residual_bound(system, sol.pieces(), est.steps, z0=system.z0)
    within = np.nonzero(bound > 10 * np.maximum(np.maximum.accumulate(e), 1e-300))[0]
    keep = e > 1e-5 * scale
    ratio = d[keep] / e[keep] if np.any(keep) else np.array([np.nan])
    over = np.nonzero(~(d <= 0.05 * est.range))[0]
    n_trust = max(int(over[0]) if over.size else d.size, 2)
    return {
        **{k: v for k, v in case.items() if k not in ("net", "train")},
        "true_max": float(e.max()), "estimate_max": float(d.max()), "effectivity": float(d.max() / e.max()),
        "relative_true": float(e.max() / scale), "counts": bool(e.max() > 1e-5 * scale),
        "in_target": bool(1 / 3 <= d.max() / e.max() <= 3),
        "effectivity_trusted": float(d[:n_trust].max() / max(e[:n_trust].max(), 1e-300)),
        "trusted_until": est.trusted_until, "T": case["T"],
        "pointwise_p05": float(np.quantile(ratio, 0.05)), "pointwise_median": float(np.median(ratio)),
        "pointwise_p95": float(np.quantile(ratio, 0.95)),
        "bound_max": float(bound.max()), "bound_over_true": float(bound.max() / e.max()),
        "bound_within_10x_until": float(est.t[within[0]]) if within.size else float(est.t[-1]),
        "converged": est.converged, "steps": est.steps, "train_seconds": train_s, "estimate_seconds": est_s,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.estimate_effectivity", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="a few cases only (a smoke test)")
    ap.add_argument("--out", default="docs/benchmarks/estimate_effectivity.json")
    ap.add_argument("--doc", default=None, help="also write the table into this page's generated:effectivity section")
    args = ap.parse_args(argv)
    rows = []
    print(f"{'case':28s} {'true max':>9s} {'estimate':>9s} {'eff':>7s} {'trusted to':>10s} {'bound/true':>10s}")
    for case in cases(args.quick):
        row = analyse(case)
        rows.append(row)
        print(f"{row['id']:28s} {row['true_max']:9.2e} {row['estimate_max']:9.2e} {row['effectivity']:7.3g} "
              f"{row['trusted_until']:10.3g} {row['bound_over_true']:10.2e}", flush=True)
    counted = [r for r in rows if r["counts"]]
    summary = {"cases": len(rows), "counted": len(counted),
               "in_target": sum(r["in_target"] for r in counted),
               "under_3x": sum(r["effectivity"] < 1 / 3 for r in counted),
               "effectivity_small_errors": [min((r["effectivity"] for r in counted if r["relative_true"] <= 0.05), default=None),
                                            max((r["effectivity"] for r in counted if r["relative_true"] <= 0.05), default=None)]}
    print(json.dumps(summary))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"summary": summary, "rows": rows}, indent=1), encoding="utf-8")
    print(f"wrote {args.out}")
    if args.doc:
        from benchmarks.common import replace_generated

        replace_generated(Path(args.doc), "effectivity", markdown(rows, summary))
        print(f"wrote the effectivity table into {args.doc}")
    return 0


def markdown(rows: list[dict], summary: dict) -> str:
    head = ["| case | true max ‖e‖ | estimate max ‖δ‖ | effectivity | trusted until (of T) | pointwise ‖δ‖/‖e‖ p05–p95 "
            "| log-norm bound / true | bound within 10× until |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        head.append(f"| {r['id']} | {r['true_max']:.2e} | {r['estimate_max']:.2e} | {r['effectivity']:.3g} | "
                    f"{r['trusted_until']:.3g} ({r['T']:.3g}) | {r['pointwise_p05']:.2f}–{r['pointwise_p95']:.2f} | "
                    f"{r['bound_over_true']:.1e} | {r['bound_within_10x_until']:.2g} |")
    lo, hi = summary["effectivity_small_errors"]
    head += ["", f"{summary['counted']} of {summary['cases']} cases have a true error above 1e-5 of the range; the "
             f"effectivity is within [1/3, 3] in {summary['in_target']} of them and below 1/3 in {summary['under_3x']}; "
             f"where the true error is at most 5 % of the range it lies in {lo:.3g}–{hi:.3g}."]
    return "\n".join(head)


if __name__ == "__main__":
    raise SystemExit(main())

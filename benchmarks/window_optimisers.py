"""One window, three optimisers: Adam alone, Adam + L-BFGS, Adam + Levenberg–Marquardt.

For five windows (the nonlinear oscillator and Hénon–Heiles on [0, 4π], Kepler e = 0.6 on [0, π/2]
and [0, π], the pendulum near its separatrix on [0, 2]) and three seeds: Adam alone at 2 000, 8 000
and 32 000 epochs (the window defaults, cosine over each budget), and from the 2 000-epoch Adam
run the library's L-BFGS polish and its Levenberg–Marquardt phase (float32, and float64 rounded
back). Error = max over 2 001 times and the components of |ẑ − z_ref| / the state's range.
Seconds are the phases' own wall times, compilation excluded (reported apart).

    taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false \\
        python -m benchmarks.window_optimisers [--seeds 3] [--out docs/benchmarks/window_optimisers.json]

(one core, pinned: the timings of a shared machine are otherwise dominated by XLA's thread pool
waiting for a busy core; see docs/PERFORMANCE.md). About 5 minutes.
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
from atlasnn.solutions import Solution, state_range
from atlasnn.systems import builtin_system, expression_system
from atlasnn.training import DEFAULT_NETWORK, DEFAULT_WINDOW_TRAIN, LMConfig, PolishConfig, refine, train

KEPLER = ("(p1**2 + p2**2)/2 - 1/sqrt(q1**2 + q2**2)", ["q1", "q2"], ["p1", "p2"], [0.4, 0.0, 0.0, 2.0])
WINDOWS = {
    "oscillator-4pi": (lambda: builtin_system("nonlinear_oscillator"), 4 * math.pi, 1.0),
    "henon-heiles-4pi": (lambda: builtin_system("henon_heiles"), 4 * math.pi, 0.5),
    "kepler-pi/2": (lambda: expression_system(*KEPLER[:3], separable=True, z0=KEPLER[3]), math.pi / 2, 1.0),
    "kepler-pi": (lambda: expression_system(*KEPLER[:3], separable=True, z0=KEPLER[3]), math.pi, 1.0),
    "pendulum-2": (lambda: expression_system("p**2/2 - cos(q)", ["q"], ["p"], separable=True, z0=[0.0, 1.99]),
                   2.0, 1.0),
}
ADAM = (2000, 8000, 32000)
PHASES = {"lbfgs": PolishConfig(), "lm_f32": LMConfig(), "lm_f64": LMConfig(precision="float64")}


def error(sol_model, system, t, ref, scale) -> float:
    return float(np.abs(Solution(sol_model, system)(t) - ref).max() / scale)


def one(name: str, seed: int) -> list[dict]:
    make, T, lam = WINDOWS[name]
    system = make()
    t = np.linspace(0.0, T, 2001)
    ref = reference_solution(system, system.z0, t)
    scale = state_range(ref)
    rows, base = [], None
    for epochs in ADAM:
        cfg = DEFAULT_WINDOW_TRAIN.replace(epochs=epochs, lam_reg=lam, seed=seed, progress=False)
        res = train(make_model(system.z0, **DEFAULT_NETWORK, seed=seed), system, T, cfg)
        rows.append({"window": name, "seed": seed, "method": f"adam{epochs}", "seconds": res.wall_time,
                     "compile": res.compile_time, "error": error(res.model, system, t, ref, scale),
                     "loss": res.best_loss})
        base = base or res
    for method, config in PHASES.items():
        start = time.perf_counter()
        out = refine(base.model, system, T, config.replace(lam_reg=lam))
        took = time.perf_counter() - start - out.compile_time
        rows.append({"window": name, "seed": seed, "method": f"adam2000+{method}", "seconds": base.wall_time + took,
                     "compile": out.compile_time, "error": error(out.model, system, t, ref, scale),
                     "loss": out.final_loss, "steps": out.steps})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.window_optimisers", description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--windows", default=",".join(WINDOWS))
    ap.add_argument("--out", default="docs/benchmarks/window_optimisers.json")
    ap.add_argument("--doc", default=None, help="also write the table into this page's generated:optimisers section")
    args = ap.parse_args(argv)
    rows = []
    for name in args.windows.split(","):
        for seed in range(args.seeds):
            for r in one(name, seed):
                rows.append(r)
                print(f"{r['window']:18s} seed {seed} {r['method']:18s} error {r['error']:.2e}  {r['seconds']:6.2f} s",
                      flush=True)
    table = {}
    for r in rows:
        table.setdefault((r["window"], r["method"]), []).append(r)
    summary = [{"window": w, "method": m, "median_error": float(np.median([r["error"] for r in rs])),
                "worst_error": float(max(r["error"] for r in rs)), "median_seconds": float(np.median([r["seconds"] for r in rs]))}
               for (w, m), rs in table.items()]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"rows": rows, "summary": summary}, indent=1), encoding="utf-8")
    print(f"wrote {args.out}")
    if args.doc:
        from benchmarks.common import replace_generated

        replace_generated(Path(args.doc), "optimisers", markdown(summary))
        print(f"wrote the table into {args.doc}")
    return 0


def markdown(summary: list[dict]) -> str:
    methods = list(dict.fromkeys(s["method"] for s in summary))
    out = ["| window | " + " | ".join(methods) + " |", "|---|" + "---|" * len(methods)]
    for w in dict.fromkeys(s["window"] for s in summary):
        cells = []
        for m in methods:
            s = next((x for x in summary if x["window"] == w and x["method"] == m), None)
            cells.append("" if s is None else f"{s['median_error']:.1e} [{s['worst_error']:.1e}] in {s['median_seconds']:.2g} s")
        out.append(f"| {w} | " + " | ".join(cells) + " |")
    out += ["", "Each cell: median [worst] over the seeds of max |ẑ − z_ref| / range, in the median seconds of "
            "training (the phase after Adam includes Adam's 2 000 epochs), compilation excluded."]
    return "\n".join(out)


if __name__ == "__main__":
    raise SystemExit(main())

"""Time to accuracy: training seconds per seed until a time-marched solution reaches a max error.

For the paper's two long problems (oscillator-long: the nonlinear oscillator on [0, 20π];
henon-heiles-long: Hénon–Heiles on [0, 24π]; systems, z0 and networks from their configs) and
a grid of settings — adaptive windows at rtol 1e-3, 1e-4, 1e-5, each with 500 or 2 000 Adam
epochs per window before the Levenberg–Marquardt phase — every seed is marched once per setting.
Its cost is the training wall time (every attempt's Adam and LM phases; compilation and the
error estimates between windows excluded, reported apart), its error the max over the
evaluation grid and the components of |ẑ − z_ref| (DOP853 at 1e-12). For each target 1e-3, 1e-4,
1e-5 the table gives, per seed, the cheapest setting that reaches it; beside it the cheapest
classical method that does (Yoshida-4 and DOP853 from the work–precision measurement).

    taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false \\
        python -m benchmarks.time_to_accuracy [--seeds 3] [--doc docs/PERFORMANCE.md]

(one core, pinned: XLA_FLAGS alone leaves YNNPACK's kernels seeing every core; the
issue's target is stated for one core). About 10 minutes.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from atlasnn.evaluation import reference_solution
from atlasnn.evaluation import _workprecision as wp
from atlasnn.experiments.config import builtin_config_path, load_config
from atlasnn.nn import make_model
from atlasnn.training import march
from benchmarks.common import machine_info, replace_generated

PROBLEMS = ("oscillator-long", "henon-heiles-long")
RTOLS = (1e-3, 1e-4, 1e-5)
ADAM_EPOCHS = (500, 2000)
TARGETS = (1e-3, 1e-4, 1e-5)


def problem(name: str):
    cfg = load_config(builtin_config_path(name))
    system = cfg.system.build()
    z0 = system.initial_state(cfg.system.z0)
    st = cfg.eval_stage
    t = np.linspace(st.t0, st.T, cfg.evaluation.eval_points)
    return cfg, system, z0, t, reference_solution(system, z0, t)


def one(name: str, seed: int, rtol: float, epochs: int, log=print) -> dict:
    cfg, system, z0, t, ref = problem(name)
    m = cfg.march
    scheme = m.scheme.replace(rtol=rtol, train=m.scheme.train.replace(epochs=epochs, seed=seed, progress=False,
                                                                     chunk=min(m.scheme.train.chunk, epochs)))
    model = make_model(z0, scaling="atlas_exp", width=m.width, depth=m.depth, t0=float(t[0]),
                       gamma=cfg.gamma_init.get("atlas_exp"), activation=m.activation,
                       first_layer_scale=m.first_layer_scale, seed=seed)
    start = time.perf_counter()
    sol = march(model, system, float(t[-1]), scheme)
    total = time.perf_counter() - start
    training = sum(a["wall_time"] for a in sol.info["attempts"])
    compile_s = sum(r.compile_time for r in sol.windows)
    err = float(np.abs(sol(t) - ref).max())
    row = {"problem": name, "seed": seed, "rtol": rtol, "adam_epochs": epochs, "training_seconds": training,
           "compile_seconds": compile_s, "total_seconds": total, "max_error": err, "windows": len(sol.models),
           "attempts": len(sol.info["attempts"])}
    log(f"{name} seed {seed} rtol {rtol:g} adam {epochs}: max error {err:.2e} after {training:.1f} s of training "
        f"({len(sol.models)} windows, {total:.1f} s in all)")
    return row


def classical(name: str) -> list[dict]:
    _, system, z0, t, ref = problem(name)
    points = wp.symplectic_points(system, z0, t, ref, multiples=(1, 2, 4, 8, 16, 32, 64)) + wp.dop853_points(
        system, z0, t, ref)
    return [{"method": p.method, "setting": p.setting, "seconds": p.seconds, "max_error": p.max_error,
             "evaluations": p.evaluations} for p in points if p.method in ("yoshida4", "dop853")]


def summarise(rows: list[dict], classic: dict[str, list[dict]]) -> list[dict]:
    out = []
    for name in sorted({r["problem"] for r in rows}):
        seeds = sorted({r["seed"] for r in rows if r["problem"] == name})
        for target in TARGETS:
            best = []
            for seed in seeds:
                ok = [r for r in rows if r["problem"] == name and r["seed"] == seed and r["max_error"] <= target]
                best.append(min(ok, key=lambda r: r["training_seconds"]) if ok else None)
            reached = [b for b in best if b is not None]
            cls = [p for p in classic.get(name, []) if p["max_error"] <= target]
            fastest = min(cls, key=lambda p: p["seconds"]) if cls else None
            out.append({
                "problem": name, "target": target, "seeds": len(seeds), "reached": len(reached),
                "median_seconds": statistics.median(b["training_seconds"] for b in reached) if reached else None,
                "max_seconds": max(b["training_seconds"] for b in reached) if reached else None,
                "settings": [None if b is None else f"rtol {b['rtol']:g}, Adam {b['adam_epochs']}" for b in best],
                "classical": None if fastest is None else f"{fastest['method']} {fastest['setting']}",
                "classical_seconds": None if fastest is None else fastest["seconds"],
            })
    return out


def markdown(summary: list[dict]) -> str:
    lines = ["| problem | max error ≤ | seeds reaching it | training s per seed: median (max) | cheapest setting per seed "
             "| cheapest classical (s) |", "|---|---|---|---|---|---|"]
    for s in summary:
        secs = "–" if s["median_seconds"] is None else f"{s['median_seconds']:.1f} ({s['max_seconds']:.1f})"
        settings = "; ".join("none" if x is None else x for x in s["settings"])
        cls = "–" if s["classical"] is None else f"{s['classical']} ({s['classical_seconds']:.2g})"
        lines.append(f"| {s['problem']} | {s['target']:g} | {s['reached']} of {s['seeds']} | {secs} | {settings} | {cls} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.time_to_accuracy", description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--problems", nargs="+", default=list(PROBLEMS))
    ap.add_argument("--rtols", nargs="+", type=float, default=list(RTOLS), help="the adaptive windows' rtol values")
    ap.add_argument("--adam-epochs", nargs="+", type=int, default=list(ADAM_EPOCHS),
                    help="Adam epochs per window before the Levenberg-Marquardt phase")
    ap.add_argument("--out", default="docs/benchmarks/time_to_accuracy.json")
    ap.add_argument("--doc", default=None, help="also write the table into this page's generated:time_to_accuracy section")
    args = ap.parse_args(argv)
    rows = [one(name, seed, rtol, epochs) for name in args.problems for seed in range(args.seeds)
            for rtol in args.rtols for epochs in args.adam_epochs]
    classic = {name: classical(name) for name in args.problems}
    summary = summarise(rows, classic)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"machine": machine_info(), "rows": rows, "classical": classic,
                                          "summary": summary}, indent=1), encoding="utf-8")
    table = markdown(summary)
    print(table)
    if args.doc:
        replace_generated(args.doc, "time_to_accuracy",
                          f"(generated by `python -m benchmarks.time_to_accuracy "
                          f"{' '.join(argv if argv is not None else sys.argv[1:])}`)\n\n{table}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Compile once: the compile time of a run, with an empty persistent cache and with a warm one.

One built-in experiment (default henon-heiles-long, one seed, its quick budgets: the same
programs as the full run) is run twice in fresh processes, both with the same new
``ATLASNN_CACHE_DIR``: the first fills the cache, the second loads from it. In each, JAX's own
monitoring events are summed — tracing (``jaxpr_trace_duration``), lowering
(``jaxpr_to_mlir_module_duration``) and compiling or loading from the cache
(``backend_compile_duration``) — with the count of programs compiled and of cache hits.

    taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false \\
        python -m benchmarks.compile_once [--experiment henon-heiles-long] [--out docs/benchmarks/compile_once.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import machine_info

CHILD = r"""
import json, sys, time
from jax import monitoring
events = {}
counts = {}
per_function = {}
def duration(event, secs, **kw):
    events[event] = events.get(event, 0.0) + secs
    counts[event] = counts.get(event, 0) + 1
    if not event.startswith("/jax/core/compile/"):
        return
    name = kw.get("fun_name", "?").removeprefix("jit(").removesuffix(")")
    row = per_function.setdefault(name, {"programs": 0, "seconds": 0.0})
    row["seconds"] += secs
    row["programs"] += event.endswith("backend_compile_duration")
def event(name, **kw):
    counts[name] = counts.get(name, 0) + 1
monitoring.register_event_duration_secs_listener(duration)
monitoring.register_event_listener(event)
from atlasnn.experiments import run_experiment
from atlasnn.experiments.config import builtin_config_path, load_config
name, out = sys.argv[1], sys.argv[2]
cfg = load_config(builtin_config_path(name), quick=True)
start = time.perf_counter()
run_experiment(cfg, out, seeds=(0,), jobs=1, progress=False, report=False, log=lambda *a: None, overwrite=True)
wall = time.perf_counter() - start
res = json.load(open(out + "/results.json"))
print(json.dumps({"wall_seconds": wall, "events": events, "counts": counts, "per_function": per_function,
                  "training_compile_seconds": sum(r.get("compile_time") or 0.0 for r in res["runs"])}))
"""

TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
BACKEND = "/jax/core/compile/backend_compile_duration"
HITS = "/jax/compilation_cache/cache_hits"


def one(name: str, cache: str, out: str, src: str | None = None) -> dict:
    env = dict(os.environ, ATLASNN_CACHE_DIR=cache)
    if src is not None:  # another checkout's package (e.g. the version before a change)
        env["PYTHONPATH"] = src
    proc = subprocess.run([sys.executable, "-c", CHILD, name, out], env=env, capture_output=True, text=True,
                          check=True)
    data = json.loads(proc.stdout.strip().splitlines()[-1])
    ev, n = data["events"], data["counts"]
    return {"wall_seconds": data["wall_seconds"], "trace_seconds": ev.get(TRACE, 0.0),
            "lower_seconds": ev.get(LOWER, 0.0), "compile_or_load_seconds": ev.get(BACKEND, 0.0),
            "programs": n.get(BACKEND, 0), "cache_hits": n.get(HITS, 0),
            "training_compile_seconds": data["training_compile_seconds"],
            # per jitted function: programs compiled or loaded, and seconds of tracing + lowering +
            # compiling or loading; the 12 costliest
            "by_function": dict(sorted(data["per_function"].items(), key=lambda kv: -kv[1]["seconds"])[:12])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.compile_once", description=__doc__.split("\n")[0])
    ap.add_argument("--experiment", default="henon-heiles-long")
    ap.add_argument("--out", default="docs/benchmarks/compile_once.json")
    ap.add_argument("--doc", default=None, help="also write the table into this page's generated:compile_once section")
    ap.add_argument("--src", default=None, help="run the package in this src/ (another checkout's) instead; no --doc")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        cache = str(Path(tmp) / "cache")
        first = one(args.experiment, cache, str(Path(tmp) / "run1"), args.src)
        second = one(args.experiment, cache, str(Path(tmp) / "run2"), args.src)
    rows = {"first (empty cache)": first, "second (warm cache)": second}
    for label, r in rows.items():
        print(f"{label}: {r['programs']} programs, {r['cache_hits']} from the cache; compile or load "
              f"{r['compile_or_load_seconds']:.2f} s, trace {r['trace_seconds']:.2f} s, lower {r['lower_seconds']:.2f} s; "
              f"run {r['wall_seconds']:.1f} s")
    print("second run, the costliest functions (programs, trace + lower + load s): " + "; ".join(
        f"{k} {v['programs']}, {v['seconds']:.2f}" for k, v in list(second["by_function"].items())[:8]))
    table = ["| run | programs | from the cache | compile or load s | trace s | lower s | training programs' compile s "
             "| run s |", "|---|---|---|---|---|---|---|---|"]
    for label, r in rows.items():
        table.append(f"| {label} | {r['programs']} | {r['cache_hits']} | {r['compile_or_load_seconds']:.2f} | "
                     f"{r['trace_seconds']:.2f} | {r['lower_seconds']:.2f} | {r['training_compile_seconds']:.2f} | "
                     f"{r['wall_seconds']:.1f} |")
    if args.doc and not args.src:
        from benchmarks.common import replace_generated

        replace_generated(args.doc, "compile_once", f"(generated by `python -m benchmarks.compile_once --experiment "
                          f"{args.experiment} --doc {args.doc}`: {args.experiment}, seed 0, its quick budgets)\n\n"
                          + "\n".join(table))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"machine": machine_info(), "experiment": args.experiment, "src": args.src,
                                          "quick": True, "seeds": [0], **rows}, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The first hour's case: `atlasnn run` of Hénon–Heiles on [0, 24π], the default time-marched
template (`atlasnn init --system henon_heiles --T "24*pi" --march`), one seed, with an empty
compilation cache and then with the cache it filled. Each run is a fresh process pinned to one
core; recorded: its wall time, the training seconds and compile seconds its console line prints,
and everything outside training (wall − training), the seconds from the process's start until
the first training's compiled chunk is ready, the seconds of atlasnn's imports, and XLA's
compiling (or loading from the cache) per jitted function, from JAX's monitoring events. The
issue's targets: outside training ≤ training, cold; a second run ≤ 0.5 s before training starts.

    python -m benchmarks.cold_start [--src PATH/src] [--core 1] [--repeat N] [--figures all] [--xla-flags FLAGS] [--out docs/benchmarks/cold_start.json]

``--src``: another checkout's ``src`` (a git worktree of an earlier commit) to measure it the same way.
``--repeat N``: N cold-then-warm pairs, each with an empty cache of its own; ``cold`` and ``warm``
are then the pair whose outside-training seconds are the median, and ``repeats`` holds them all
(one pair measures 0.5–1 s apart from the next on this machine).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import machine_info, write_result

LINE = re.compile(r"seed 0: \d+ epochs \(\w+\), loss \S+, ([\d.]+) s \+ ([\d.]+) s compiling")
READY = re.compile(r"first training program ready after ([\d.]+) s")

# The run's process, timed from its first line: every Adam training gets its compiled chunk from
# atlasnn.training._train.compiled_chunk, so the moment the first one returns is when training
# can start (everything before it: imports, the config, the checks, the program's load or build).
_PROGRAM = """
import atexit, json, os, sys, time
start = time.perf_counter()
from jax import monitoring
compile_by_function = {}
def duration(event, secs, **kw):  # backend compile (or cache load) seconds per jitted function
    if event.endswith("backend_compile_duration"):
        name = kw.get("fun_name", "?").removeprefix("jit(").removesuffix(")")
        row = compile_by_function.setdefault(name, [0, 0.0])
        row[0] += 1
        row[1] += secs
monitoring.register_event_duration_secs_listener(duration)
import atlasnn.cli, atlasnn.experiments, atlasnn.report  # what every run imports
imports = time.perf_counter() - start
import atlasnn.training._train as train_module
build, seen = train_module.compiled_chunk, []
def timed(*args, **kwargs):
    out = build(*args, **kwargs)
    if not seen:
        seen.append(1)
        print(f"first training program ready after {time.perf_counter() - start:.2f} s", file=sys.stderr)
    return out
train_module.compiled_chunk = timed
def dump():
    rows = sorted(compile_by_function.items(), key=lambda kv: -kv[1][1])
    json.dump({"import_seconds": imports, "compile_by_function": {k: {"programs": n, "seconds": t} for k, (n, t) in rows}},
              open(os.environ["COLD_START_PARTS"], "w"))
atexit.register(dump)
from atlasnn.cli import main
sys.exit(main(sys.argv[1:]))
"""


def one_run(src: str, config: Path, cache: Path, out: Path, core: int, figures: str, xla_flags: str | None) -> dict:
    parts = out.with_name(out.name + "-parts.json")
    env = {**os.environ, "ATLASNN_CACHE_DIR": str(cache), "PYTHONPATH": src, "COLD_START_PARTS": str(parts)}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    cmd = ["taskset", "-c", str(core), sys.executable, "-c", _PROGRAM,
           "run", str(config), "--no-progress", "--out", str(out), "--figures", figures]
    start = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"cold_start: the run failed:\n{proc.stderr[-2000:]}")
    m = LINE.search(proc.stdout)
    if not m:
        raise SystemExit(f"cold_start: no training line in the run's output:\n{proc.stdout[-2000:]}")
    training, compiling = float(m.group(1)), float(m.group(2))
    ready = READY.search(proc.stderr)
    return {"wall_seconds": wall, "training_seconds": training, "training_compile_seconds": compiling,
            "outside_training_seconds": wall - training, "outside_over_training": (wall - training) / training,
            "before_training_seconds": float(ready.group(1)) if ready else None,
            **json.loads(parts.read_text(encoding="utf-8"))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.cold_start", description=__doc__.split("\n")[0])
    ap.add_argument("--src", default=str(Path(__file__).resolve().parents[1] / "src"))
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--figures", default="all")
    ap.add_argument("--xla-flags", default=None, help="XLA_FLAGS for both runs (e.g. --xla_backend_optimization_level=0)")
    ap.add_argument("--repeat", type=int, default=1, help="cold-then-warm pairs; the median one is reported")
    ap.add_argument("--out", default="docs/benchmarks/cold_start.json")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        config = tmp / "hhm.toml"
        init = subprocess.run([sys.executable, "-c", "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))",
                               "init", str(config), "--system", "henon_heiles", "--T", "24*pi", "--march"],
                              env={**os.environ, "PYTHONPATH": args.src}, capture_output=True, text=True)
        if init.returncode != 0:
            raise SystemExit(f"cold_start: init failed: {init.stderr}")
        pairs = []
        for i in range(max(args.repeat, 1)):
            cache = tmp / f"cache{i}"
            pairs.append({"cold": one_run(args.src, config, cache, tmp / f"run{i}a", args.core, args.figures, args.xla_flags),
                          "warm": one_run(args.src, config, cache, tmp / f"run{i}b", args.core, args.figures, args.xla_flags)})
    cold, warm = (sorted((p[k] for p in pairs), key=lambda r: r["outside_training_seconds"])[len(pairs) // 2]
                  for k in ("cold", "warm"))
    result = {"case": "atlasnn init --system henon_heiles --T 24*pi --march; atlasnn run --no-progress, one seed",
              "src": args.src, "figures": args.figures, "core": args.core, "xla_flags": args.xla_flags,
              "cold": cold, "warm": warm, "repeats": pairs if len(pairs) > 1 else None,
              "machine": machine_info(), "command": "python -m benchmarks.cold_start " + " ".join(argv or sys.argv[1:])}
    for i, p in enumerate(pairs if len(pairs) > 1 else []):
        print(f"pair {i + 1}: outside training {p['cold']['outside_training_seconds']:.1f} s cold "
              f"({p['cold']['outside_over_training']:.2f} x), {p['warm']['outside_training_seconds']:.1f} s warm "
              f"({p['warm']['outside_over_training']:.2f} x)")
    for name, r in (("cold", cold), ("warm", warm)):
        print(f"{name}: {r['wall_seconds']:.1f} s in all, training {r['training_seconds']:.1f} s "
              f"(+ {r['training_compile_seconds']:.1f} s compiling), outside training {r['outside_training_seconds']:.1f} s "
              f"= {r['outside_over_training']:.2f} x training; first training program ready after "
              f"{r['before_training_seconds']} s; imports {r['import_seconds']:.2f} s")
        top = list(r["compile_by_function"].items())[:4]
        print("  compiling or loading, costliest: " + "; ".join(f"{k} {v['programs']}x {v['seconds']:.2f} s" for k, v in top))
    write_result(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Cost outside training: `atlasnn run` on a Fermi–Pasta–Ulam β chain of n particles.

The chain (fixed ends, unit masses and springs, β = 1): H = Σ p_i²/2 + Σ_{springs} (Δq²/2 + β Δq⁴/4),
q(0) = 0, p_i(0) = sin(π i/(n + 1)), on [0, 2]; one seed of ATLAS-NN (exp), 64 × 2, 2 000 epochs,
evaluated on 2 000 points with the symplectic Euler baseline, the error estimate, tables and
every figure. Two ways to write H: ``expression`` (one term per spring, as text: about 200
operations at n = 16, refused at n = 64) and ``python`` (a function of q, p arrays in a file:
``[system] python = "chain.py:hamiltonian"``).

Cases: both forms with every figure drawn, and the python form with the overview figure alone
(``--figures overview``). Each case runs twice in fresh processes with one new persistent compilation cache (``first``
fills it, ``second`` is a rerun), timing, inside the process: the imports, reading and checking
the config, the run (trainings, reference and baseline solves, estimates), the tables and
figures. JAX's own monitoring events give the compilation: tracing + lowering + compiling or
loading (``/jax/core/compile/*``). "outside" = the whole process − training − compilation.

    python -m benchmarks.chain_cost [--particles 16 64] [--before OTHER/src] [--out docs/benchmarks/chain_cost.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import machine_info

CHAIN_PY = '''import jax.numpy as jnp


def hamiltonian(q, p, beta):
    """FPU beta chain with fixed ends."""
    dq = jnp.diff(jnp.concatenate([jnp.zeros(1, q.dtype), q, jnp.zeros(1, q.dtype)]))
    return jnp.sum(p**2) / 2 + jnp.sum(dq**2 / 2 + beta * dq**4 / 4)
'''

CHILD = r"""
import time
start = time.perf_counter()
import json, sys
from jax import monitoring
events = {}
def duration(event, secs, **kw):
    events[event] = events.get(event, 0.0) + secs
monitoring.register_event_duration_secs_listener(duration)
from atlasnn.experiments import run_experiment
from atlasnn.experiments.config import load_config
from atlasnn.report import write_report
t_import = time.perf_counter()
cfg = load_config(sys.argv[1])
t_config = time.perf_counter()
run_experiment(cfg, sys.argv[2], jobs=1, progress=False, report=False, log=lambda *a: None, overwrite=True)
t_run = time.perf_counter()
write_report(sys.argv[2], figures=sys.argv[3])
t_report = time.perf_counter()
res = json.load(open(sys.argv[2] + "/results.json"))
print(json.dumps({"import": t_import - start, "config": t_config - t_import, "run": t_run - t_config,
                  "report": t_report - t_run, "total": t_report - start, "events": events,
                  "train": sum(r.get("wall_time") or 0.0 for r in res["runs"]),
                  "train_compile": sum(r.get("compile_time") or 0.0 for r in res["runs"])}))
"""

COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                  "/jax/core/compile/backend_compile_duration")


def chain_expression(n: int) -> str:
    """H of the n-particle chain as one expression (one term per spring)."""
    q = [f"q{i}" for i in range(1, n + 1)]
    springs = [q[0]] + [f"({q[i]} - {q[i - 1]})" for i in range(1, n)] + [f"(-{q[-1]})"]
    kinetic = " + ".join(f"p{i}**2" for i in range(1, n + 1))
    return f"({kinetic})/2 + " + " + ".join(f"{s}**2/2 + beta*{s}**4/4" for s in springs)


def chain_config(n: int, form: str, folder: Path) -> Path:
    """Write the chain's config (and chain.py for the python form) into ``folder``."""
    z0 = [0.0] * n + [round(math.sin(math.pi * i / (n + 1)), 12) for i in range(1, n + 1)]
    if form == "python":
        (folder / "chain.py").write_text(CHAIN_PY)
        system = 'python = "chain.py:hamiltonian"'
    else:
        names = [f"q{i}" for i in range(1, n + 1)], [f"p{i}" for i in range(1, n + 1)]
        system = (f'hamiltonian = "{chain_expression(n)}"\ncoordinates = {json.dumps(names[0])}\n'
                  f'momenta = {json.dumps(names[1])}')
    path = folder / f"fpu-{n}-{form}.toml"
    path.write_text(f'''name = "fpu-{n}"
kind = "short"
description = "FPU beta chain, {n} particles ({form})"
models = ["atlas_exp"]
seeds = [0]

[system]
name = "fpu-{n}"
{system}
separable = true
params = {{ beta = 1.0 }}
z0 = {json.dumps(z0)}

[network]
width = 64
depth = 2
activation = "sin"

[interval]
t0 = 0.0
T = 2.0

[train]
epochs = 2000
lr = 5e-3
n_points = 200
chunk = 2000

[evaluation]
eval_points = 2000
''')
    return path


def run_once(config: Path, out: Path, cache: Path, figures: str, src: str | None = None) -> dict:
    env = dict(os.environ, ATLASNN_CACHE_DIR=str(cache))
    if src is not None:  # another checkout's package (e.g. the version before a change)
        env["PYTHONPATH"] = src
    proc = subprocess.run([sys.executable, "-c", CHILD, str(config), str(out), figures], env=env,
                          capture_output=True, text=True)
    if proc.returncode:
        raise SystemExit(f"{config.name}: the run failed:\n{proc.stderr[-2000:]}")
    data = json.loads(proc.stdout.strip().splitlines()[-1])
    compile_s = sum(data["events"].get(e, 0.0) for e in COMPILE_EVENTS)
    row = {k: data[k] for k in ("import", "config", "run", "report", "total", "train", "train_compile")}
    row["compile"] = compile_s
    row["outside"] = data["total"] - data["train"] - compile_s
    return row


def _table(rows: list[dict]) -> list[str]:
    out = ["| particles (d) | H as | figures | compile cache | whole process | training | compilation | outside "
           "| of which: imports | config | run | tables and figures |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['particles']} ({r['state_dim']}) | {r['form']} | {r['figures']} | {r['cache']} | "
                   f"{r['total']:.1f} | {r['train']:.1f} | {r['compile']:.1f} | **{r['outside']:.1f}** | "
                   f"{r['import']:.1f} | {r['config']:.1f} | {r['run']:.1f} | {r['report']:.1f} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.chain_cost", description=__doc__.split("\n")[0])
    ap.add_argument("--particles", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--out", default="docs/benchmarks/chain_cost.json")
    ap.add_argument("--before", default=None, metavar="SRC",
                    help="also run the expression case (all figures) and the python case (overview) with the "
                         "package in SRC (another checkout's src/, e.g. a git worktree of the previous commit), "
                         "labelled 'before'")
    ap.add_argument("--doc", default=None, help="also write the table into this page's generated:chain_cost section")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.particles:
            forms = ("expression", "python") if n <= 16 else ("python",)
            cases = [(form, "all", None) for form in forms] + [("python", "overview", None)]
            if args.before and n <= 16:  # the same cases with the other package, run first
                cases[:0] = [("expression", "all", args.before), ("python", "overview", args.before)]
            for form, figures, src in cases:
                folder = Path(tmp) / f"{n}-{form}-{figures}-{'before' if src else 'now'}"
                folder.mkdir()
                config = chain_config(n, form, folder)
                for attempt in ("first", "second"):
                    row = {"particles": n, "state_dim": 2 * n, "form": form + (" (before)" if src else ""),
                           "figures": figures, "cache": attempt,
                           **run_once(config, folder / f"run-{attempt}", folder / "cache", figures, src)}
                    rows.append(row)
                    print(f"n = {n:3d} {form:10s} figures {figures:8s} {attempt:6s}: total {row['total']:5.1f} s = training "
                          f"{row['train']:4.1f} + compilation {row['compile']:4.1f} + outside {row['outside']:4.1f} "
                          f"(imports {row['import']:.1f}, config {row['config']:.1f}, run {row['run']:.1f}, "
                          f"tables and figures {row['report']:.1f})", flush=True)
    if args.doc:
        from benchmarks.common import replace_generated

        replace_generated(args.doc, "chain_cost", f"(generated by `python -m benchmarks.chain_cost --particles "
                          f"{' '.join(map(str, args.particles))}{' --before PREVIOUS/src' if args.before else ''} --doc {args.doc}`; "
                          "seconds, one process each)\n\n"
                          + "\n".join(_table(rows)))
    Path(args.out).write_text(json.dumps({"machine": machine_info(), "command": "python -m benchmarks.chain_cost "
                                          + " ".join(sys.argv[1:]), "rows": rows}, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""How long a Hamiltonian expression of n operations takes before the first training epoch.

For each size, in a fresh process: the config checks (parse, H and J∇H finite at z0, the
separability check for a separable H), the compiled reference solver, symplectic Euler (separable
only) and the first compiled training step of one HNN (8×1 network, K = 8). Wall and CPU seconds
are printed per phase; on a busy machine the CPU seconds are the figure to trust (they are what
an idle machine's wall clock would show). The limit MAX_OPERATIONS is lifted inside the
measurement (in atlasnn.systems._parse, where the parser reads it) so that sizes beyond it can be
timed.

    python -m benchmarks.expression_size                   # default sizes (~5 min)
    python -m benchmarks.expression_size --terms 100 200 --kind nonsep
"""

from __future__ import annotations

import argparse
import ast
import json
import subprocess
import sys
import time


def expression(n: int, separable: bool) -> str:
    """p²/2 + q²/2 plus n small terms: q- or p-only powers (separable) or mixed q^a p^b."""
    if separable:
        terms = [f"{1e-3 * (i % 7 + 1):g}*{'q' if i % 2 else 'p'}**{i % 3 + 2}" for i in range(n)]
    else:
        terms = [f"{1e-3 * (i % 7 + 1):g}*q**{i % 3 + 1}*p**{i % 2 + 1}" for i in range(n)]
    return "p**2/2 + q**2/2 + " + " + ".join(terms)


def operations(text: str) -> int:
    return sum(isinstance(x, (ast.BinOp, ast.UnaryOp, ast.Call)) for x in ast.walk(ast.parse(text, mode="eval")))


def measure(n: int, separable: bool) -> dict:
    """Run in the current process (call it in a fresh one)."""
    import numpy as np

    import atlasnn.systems._parse

    atlasnn.systems._parse.MAX_OPERATIONS = 10**9
    text = expression(n, separable)
    out = {"terms": n, "operations": operations(text), "characters": len(text), "separable": separable}
    clock = [time.perf_counter(), time.process_time()]

    def lap(name):
        now = [time.perf_counter(), time.process_time()]
        out[name] = [round(now[0] - clock[0], 2), round(now[1] - clock[1], 2)]
        clock[:] = now

    from atlasnn.experiments.config import parse_config
    from atlasnn.evaluation import integrate, reference_solution
    from atlasnn.nn import make_model
    from atlasnn.training import TrainConfig, train

    lap("import")
    data = {"system": {"hamiltonian": text, "coordinates": ["q"], "momenta": ["p"], "separable": separable,
                       "z0": [0.5, 0.1]},
            "interval": {"T": 0.5}, "models": ["hnn"], "network": {"width": 8, "depth": 1},
            "train": {"epochs": 2, "n_points": 8, "chunk": 2}}
    cfg = parse_config(data)
    system = cfg.system.build()
    lap("config")
    reference_solution(system, system.z0, np.linspace(0, 0.5, 8))
    lap("reference")
    if separable:
        integrate("symplectic_euler", system, system.z0, 0.0, 0.5, 7)
        lap("symplectic_euler")
    train(make_model(system.z0, scaling="exp_decay", width=8, depth=1), system, 0.5,
          TrainConfig(epochs=2, n_points=8, chunk=2, progress=False))
    lap("first_training_step")
    phases = [v for k, v in out.items() if isinstance(v, list) and k != "import"]
    out["total"] = [round(sum(p[0] for p in phases), 1), round(sum(p[1] for p in phases), 1)]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--terms", type=int, nargs="*", default=[25, 50, 100, 200, 400])
    ap.add_argument("--kind", choices=["sep", "nonsep", "both"], default="both")
    ap.add_argument("--one", nargs=2, metavar=("N", "KIND"), help=argparse.SUPPRESS)  # the child process
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(measure(int(args.one[0]), args.one[1] == "sep")))
        return
    kinds = ["nonsep", "sep"] if args.kind == "both" else [args.kind]
    print("terms  ops  separable  total wall/CPU s  (phases: wall/CPU s)")
    for n in args.terms:
        for kind in kinds:
            done = subprocess.run([sys.executable, "-m", "benchmarks.expression_size", "--one", str(n), kind],
                                  capture_output=True, text=True)
            lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
            if done.returncode != 0 or not lines:
                print(f"{n:5d}  {kind}: failed: {done.stderr.strip().splitlines()[-1:]}")
                continue
            r = json.loads(lines[-1])
            phases = ", ".join(f"{k} {v[0]}/{v[1]}" for k, v in r.items()
                               if isinstance(v, list) and k not in ("total", "import"))
            print(f"{n:5d} {r['operations']:4d}  {str(r['separable']):9s}  {r['total'][0]:6.1f} / {r['total'][1]:5.1f}"
                  f"   ({phases})", flush=True)


if __name__ == "__main__":
    main()

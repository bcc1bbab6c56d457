"""Programs a seed batch compiles: two seeds of Hénon–Heiles trained as one program (``train_batch``,
60 Adam epochs) and polished as one (``lm_batch``, 6 Levenberg–Marquardt trials), in a fresh process
with the compilation cache off, on one or more source trees. Recorded per tree: JAX's count of
programs compiled and its tracing, lowering and compiling seconds, and a hash of every loss and
parameter the two phases return (equal hashes: the same bits).

    python -m benchmarks.batch_programs --tree before=WORKTREE/src --tree now=src [--core 1] [--out docs/benchmarks/batch_programs.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

from benchmarks.common import machine_info, write_result

_PROGRAM = """
import hashlib, json
import jax, numpy as np
from atlasnn.compile_cache import jax_time
from atlasnn.nn import make_model
from atlasnn.systems import henon_heiles
from atlasnn.training import LMConfig, TrainConfig, lm_batch, train_batch

system, z0 = henon_heiles(), [0.3, -0.3, 0.3, 0.15]
models = [make_model(z0, width=9, depth=2, seed=s) for s in (0, 1)]
configs = [TrainConfig(epochs=60, n_points=40, chunk=30, progress=False, seed=s) for s in (0, 1)]
with jax_time() as spent:
    adam = train_batch(models, system, 2.0, configs)
    lm = lm_batch([r.model for r in adam], system, 2.0, LMConfig(steps=6))
h = hashlib.sha256()
for losses, model in [(r.history.loss, r.model) for r in adam] + [(r.loss, r.model) for r in lm]:
    h.update(np.asarray(losses).tobytes())
    for leaf in jax.tree_util.tree_leaves(model):
        h.update(np.asarray(leaf).tobytes())
print(json.dumps({**spent.summary(), "result_hash": h.hexdigest()[:16],
                  "lm_final_loss": [r.final_loss for r in lm]}))
"""


def one_tree(src: str, core: int) -> dict:
    env = {**os.environ, "PYTHONPATH": src, "ATLASNN_CACHE_DIR": "off"}
    proc = subprocess.run(["taskset", "-c", str(core), sys.executable, "-c", _PROGRAM],
                          env=env, capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.batch_programs", description=__doc__.split("\n")[0])
    ap.add_argument("--tree", action="append", required=True, help="NAME=PATH/src (repeat for each tree)")
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--out", default="docs/benchmarks/batch_programs.json")
    args = ap.parse_args(argv)
    trees = dict(t.split("=", 1) for t in args.tree)
    results = {}
    for name, src in trees.items():
        results[name] = one_tree(src, args.core)
        r = results[name]
        print(f"{name}: {r['programs']} programs, tracing {r['trace_seconds']:.2f} s, lowering "
              f"{r['lower_seconds']:.2f} s, compiling {r['compile_or_load_seconds']:.2f} s; results {r['result_hash']}")
    write_result(args.out, {"case": "train_batch + lm_batch, two seeds of henon_heiles, cache off",
                            "trees": trees, "results": results, "machine": machine_info(),
                            "command": "python -m benchmarks.batch_programs " + " ".join(sys.argv[1:])})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The first hour's case (:mod:`benchmarks.cold_start`) on several source trees, interleaved: round
after round, each tree gets one cold-then-warm pair (an empty cache of its own, then the cache it
filled), so that a drift of the machine's speed over the minutes of the benchmark falls on every
tree alike (between sittings the same commit measured up to 1 s apart). Recorded per tree: every
pair, and the median of each figure over the rounds.

    python -m benchmarks.cold_start_compare --tree before=WORKTREE/src --tree now=src [--rounds 4] [--core 1] [--out docs/benchmarks/cold_start_compare.json]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.cold_start import one_run
from benchmarks.common import machine_info, write_result

FIGURES = ("wall_seconds", "training_seconds", "training_compile_seconds", "outside_training_seconds",
           "outside_over_training", "before_training_seconds", "import_seconds")


def _medians(pairs: list[dict]) -> dict:
    out = {}
    for phase in ("cold", "warm"):
        runs = [p[phase] for p in pairs]
        out[phase] = {k: statistics.median(r[k] for r in runs) for k in FIGURES}
        out[phase]["programs"] = statistics.median(sum(v["programs"] for v in r["compile_by_function"].values()) for r in runs)
        out[phase]["compile_seconds"] = statistics.median(sum(v["seconds"] for v in r["compile_by_function"].values())
                                                          for r in runs)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.cold_start_compare", description=__doc__.split("\n")[0])
    ap.add_argument("--tree", action="append", required=True, help="NAME=PATH/src (repeat for each tree)")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--figures", default="all")
    ap.add_argument("--out", default="docs/benchmarks/cold_start_compare.json")
    args = ap.parse_args(argv)
    trees = dict(t.split("=", 1) for t in args.tree)
    results: dict[str, list] = {name: [] for name in trees}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        config = tmp / "hhm.toml"
        init = subprocess.run([sys.executable, "-c", "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))",
                               "init", str(config), "--system", "henon_heiles", "--T", "24*pi", "--march"],
                              env={**os.environ, "PYTHONPATH": next(iter(trees.values()))}, capture_output=True, text=True)
        if init.returncode != 0:
            raise SystemExit(f"cold_start_compare: init failed: {init.stderr}")
        for i in range(max(args.rounds, 1)):
            for name, src in trees.items():
                cache, run = tmp / f"cache-{name}-{i}", tmp / f"run-{name}-{i}"
                pair = {"cold": one_run(src, config, cache, run.with_suffix(".a"), args.core, args.figures, None),
                        "warm": one_run(src, config, cache, run.with_suffix(".b"), args.core, args.figures, None)}
                results[name].append(pair)
                print(f"round {i + 1}, {name}: outside training {pair['cold']['outside_training_seconds']:.1f} s cold, "
                      f"{pair['warm']['outside_training_seconds']:.1f} s warm; training {pair['cold']['training_seconds']:.1f} s; "
                      f"ready {pair['warm']['before_training_seconds']} s warm", flush=True)
    medians = {name: _medians(pairs) for name, pairs in results.items()}
    short = ("wall", "train", "+compile", "outside", "ratio", "ready", "imports", "programs", "compiling")
    print(f"{'tree':<14}{'phase':<6}" + "".join(f"{k:>10}" for k in short))
    for name, m in medians.items():
        for phase in ("cold", "warm"):
            print(f"{name:<14}{phase:<6}" + "".join(f"{m[phase][k]:>10.2f}" for k in (*FIGURES, "programs", "compile_seconds")))
    result = {"case": "atlasnn init --system henon_heiles --T 24*pi --march; atlasnn run --no-progress, one seed",
              "trees": trees, "rounds": args.rounds, "core": args.core, "figures": args.figures,
              "medians": medians, "pairs": results, "machine": machine_info(),
              "command": "python -m benchmarks.cold_start_compare " + " ".join(argv or sys.argv[1:])}
    write_result(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

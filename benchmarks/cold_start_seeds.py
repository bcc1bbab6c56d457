"""The first hour's case (:mod:`benchmarks.cold_start`) over several seeds, on several source trees:
for each seed, each tree runs it once with an empty cache (a fresh process pinned to one core,
``--figures none``), the trees interleaved seed after seed. One seed's cold start depends on its
march (a run whose windows need one more compiled program pays 2–3 s more), so a change to what is
compiled is judged over seeds. Recorded per run: wall seconds, the training's seconds and
compiling seconds as its console line prints them, JAX's compiling seconds and program count,
epochs, windows, and the max error over the state's range with its verdict (from results.json).

    python -m benchmarks.cold_start_seeds --tree before=WORKTREE/src --tree now=src [--seeds 8] [--first-seed 0] [--core 1] [--out docs/benchmarks/cold_start_seeds.json]
    python -m benchmarks.cold_start_seeds --merge PART1.json PART2.json ... --out docs/benchmarks/cold_start_seeds.json
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import machine_info, write_result

_CLI = "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))"
_LINE = re.compile(r"seed (\d+): (\d+) epochs \(\w+\), loss (\S+), ([\d.]+) s \+ ([\d.]+) s compiling")
_JAX = re.compile(r"compiling or loading ([\d.]+) s \((\d+) programs")
_FIGURES = ("wall_seconds", "training_seconds", "training_compile_seconds", "jax_compile_seconds", "programs",
            "outside_training_seconds")


def one_run(src: str, config_text: str, seed: int, core: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        config = tmp / "hh.toml"
        config.write_text(config_text.replace("seeds = [0]", f"seeds = [{seed}]"), encoding="utf-8")
        env = {**os.environ, "PYTHONPATH": src, "ATLASNN_CACHE_DIR": str(tmp / "cache")}
        start = time.perf_counter()
        proc = subprocess.run(["taskset", "-c", str(core), sys.executable, "-c", _CLI, "run", str(config),
                               "--no-progress", "--figures", "none", "--out", str(tmp / "run")],
                              env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        if proc.returncode != 0:
            raise SystemExit(f"cold_start_seeds: seed {seed} failed:\n{proc.stderr[-2000:]}")
        line, jax_line = _LINE.search(proc.stdout), _JAX.search(proc.stdout)
        record = json.loads((tmp / "run" / "results.json").read_text(encoding="utf-8"))["runs"][0]
    return {"seed": seed, "wall_seconds": wall, "epochs": int(line.group(2)), "loss": float(line.group(3)),
            "training_seconds": float(line.group(4)), "training_compile_seconds": float(line.group(5)),
            "outside_training_seconds": wall - float(line.group(4)),
            "jax_compile_seconds": float(jax_line.group(1)), "programs": int(jax_line.group(2)),
            "windows": record.get("n_windows"), "relative_max": record["metrics"].get("relative_max"),
            "quality": record.get("quality")}


def summary(runs: dict[str, list[dict]]) -> dict:
    """Medians per tree; the verdicts seen; and the first tree's max errors against the last's, seed
    by seed (a Wilcoxon signed-rank test of the log ratios: whether a difference is resolved)."""
    import numpy as np
    from scipy.stats import wilcoxon

    medians = {name: {k: statistics.median(r[k] for r in rows) for k in _FIGURES + ("windows", "epochs", "relative_max")}
               for name, rows in runs.items()}
    first, last = list(runs.values())[0], list(runs.values())[-1]
    a, b = (np.array([r["relative_max"] for r in rows]) for rows in (first, last))
    out = {"medians": medians, "verdicts": {name: sorted({str((r["quality"] or {}).get("status")) for r in rows})
                                            for name, rows in runs.items()}}
    if len(runs) > 1 and len(a) == len(b) and len(a) > 1:
        test = wilcoxon(np.log(b), np.log(a))
        out["max_error_last_against_first"] = {
            "seeds": len(a), "last_lower_in": int((b < a).sum()),
            "geometric_means": [float(np.exp(np.log(a).mean())), float(np.exp(np.log(b).mean()))],
            "ratio_range": [float((b / a).min()), float((b / a).max())],
            "wilcoxon_log_ratio": {"statistic": float(test.statistic), "pvalue": float(test.pvalue)}}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.cold_start_seeds", description=__doc__.split("\n")[0])
    ap.add_argument("--tree", action="append", default=[], help="NAME=PATH/src (repeat for each tree)")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--merge", nargs="+", default=None, help="JSON files of earlier runs (other seeds) to join into --out")
    ap.add_argument("--out", default="docs/benchmarks/cold_start_seeds.json")
    args = ap.parse_args(argv)
    if args.merge:
        parts = [json.loads(Path(f).read_text(encoding="utf-8")) for f in args.merge]
        runs = {name: [r for p in parts for r in p["runs"][name]] for name in parts[0]["runs"]}
        write_result(args.out, {"case": parts[0]["case"], "trees": parts[0]["trees"], **summary(runs), "runs": runs,
                                "machine": parts[0]["machine"], "commands": [c for p in parts for c in p["commands"]]})
        return 0
    if not args.tree:
        ap.error("give --tree NAME=PATH/src (or --merge FILES)")
    trees = dict(t.split("=", 1) for t in args.tree)
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "hh.toml"
        first = next(iter(trees.values()))
        subprocess.run([sys.executable, "-c", _CLI, "init", str(config), "--system", "henon_heiles", "--T", "24*pi",
                        "--march"], env={**os.environ, "PYTHONPATH": first}, check=True, capture_output=True)
        config_text = config.read_text(encoding="utf-8")
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for name, src in trees.items():
            r = one_run(src, config_text, seed, args.core)
            runs[name].append(r)
            print(f"seed {seed} {name}: {r['wall_seconds']:.1f} s, training {r['training_seconds']:.1f} s "
                  f"+ {r['training_compile_seconds']:.1f} s compiling, {r['programs']} programs, {r['windows']} windows, "
                  f"max err/range {r['relative_max']:.2e}", flush=True)
    result = summary(runs)
    for name, m in result["medians"].items():
        print(f"{name}, medians over {args.seeds} seeds: " + ", ".join(f"{k} {v:.3g}" for k, v in m.items()))
    write_result(args.out, {"case": "atlasnn init --system henon_heiles --T 24*pi --march; atlasnn run --figures none, "
                                    "one seed a run, empty cache", "trees": trees, **result, "runs": runs,
                            "machine": machine_info(),
                            "commands": ["python -m benchmarks.cold_start_seeds " + " ".join(argv or sys.argv[1:])]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

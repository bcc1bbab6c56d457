"""Evaluation time of the committed bundle(s): 10⁵ members × 100 times, the issue's target (≤ 2 s).

    python -m benchmarks.bundle_eval [--run docs/runs/families/oscillator-bundle] [--out docs/benchmarks/bundle_eval.json]

Every ``models/bundle_seed*.npz`` of the run is loaded (``atlasnn.load``), 10⁵ members are drawn
from its box, and ``sol(t, z0, lam)`` at 100 times on [t0, T] is timed three times after a first
call that compiles; the machine should be otherwise quiet.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from atlasnn import load
from benchmarks.common import machine_info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bundle_eval", description=__doc__.split("\n")[0])
    ap.add_argument("--run", default="docs/runs/families/oscillator-bundle")
    ap.add_argument("--out", default="docs/benchmarks/bundle_eval.json")
    args = ap.parse_args(argv)
    rows = []
    for path in sorted(Path(args.run, "models").glob("bundle_seed*.npz")):
        sol = load(path)
        z0, lam = sol.box.draw(np.random.default_rng(12346), 100_000)
        t = np.linspace(sol.box.t0, sol.box.T, 100)
        seconds = []
        for _ in range(4):
            start = time.perf_counter()
            sol(t, z0, lam)
            seconds.append(time.perf_counter() - start)
        rows.append({"model": path.name, "windows": len(sol.windows), "first_call_s": seconds[0],
                     "best_of_three_s": min(seconds[1:])})
        print(f"{path.name}: {len(sol.windows)} windows, first call {seconds[0]:.2f} s, then best "
              f"{min(seconds[1:]):.2f} s for 100000 members x 100 times", flush=True)
    Path(args.out).write_text(json.dumps({"machine": machine_info(), "run": args.run, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

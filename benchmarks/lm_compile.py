"""What the Levenberg–Marquardt program costs to compile, and which part: the march's LM loop for
the first hour's case (Hénon–Heiles, the default 50×2 sin network, a window of length 2, its
default collocation count), compiled with the persistent cache off, with and without the
geodesic acceleration (whose second directional derivative of the residual is forward mode over
forward mode over the residual's own time derivative). Each figure is the median of three fresh
processes; the compile seconds include tracing and lowering.

    taskset -c 1 python -m benchmarks.lm_compile [--out docs/benchmarks/lm_compile.json]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys

from benchmarks.common import machine_info, write_result

_CHILD = """
import sys
from atlasnn.nn import make_model
from atlasnn.systems import henon_heiles
from atlasnn.training import LMConfig, levenberg_marquardt
model = make_model([0.3, -0.3, 0.3, 0.15], scaling="rational_exp", width=50, depth=2, activation="sin", seed=0)
result = levenberg_marquardt(model, henon_heiles(), 2.0, LMConfig(steps=3, geodesic=sys.argv[1] == "1"))
print(result.compile_time, result.config.n_points or "default")
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.lm_compile", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="docs/benchmarks/lm_compile.json")
    args = ap.parse_args(argv)
    env = {**os.environ, "ATLASNN_CACHE_DIR": "off"}
    result = {}
    for geodesic in (True, False):
        times = []
        for _ in range(3):
            out = subprocess.run([sys.executable, "-c", _CHILD, "1" if geodesic else "0"], env=env,
                                 capture_output=True, text=True, check=True).stdout.split()
            times.append(float(out[0]))
        result["geodesic" if geodesic else "no_geodesic"] = {"compile_seconds": times,
                                                             "median": statistics.median(times)}
        print(f"geodesic={geodesic}: compile {statistics.median(times):.2f} s (median of {times})")
    share = result["geodesic"]["median"] - result["no_geodesic"]["median"]
    print(f"the geodesic acceleration: {share:.2f} s of {result['geodesic']['median']:.2f} s")
    payload = {"case": "LM loop of the march, Hénon–Heiles, 50x2 sin network, window length 2, cache off",
               **result, "geodesic_share_seconds": share, "machine": machine_info(),
               "command": "python -m benchmarks.lm_compile " + " ".join(argv or sys.argv[1:])}
    write_result(args.out, payload)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

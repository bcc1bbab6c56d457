"""What XLA's loop emitters (``training.training_compiler_options``) do to the two training programs:
the first hour's case (`atlasnn init --system henon_heiles --T "24*pi" --march`, one seed) is run
once with an empty cache of its own (``--figures none``) to keep its Adam chunk and its
Levenberg–Marquardt program on disk (``<cache>/exported/``); each is then read back and compiled
in fresh processes (the persistent cache off), alternately with XLA's defaults and with the
training options, ``--rounds`` times, on one core. Also: XLA's sin, cos, tanh and exp on 2·10⁶
float32 inputs compiled both ways, against float64 NumPy.

    python -m benchmarks.compile_options [--rounds 3] [--core 1] [--out docs/benchmarks/compile_options.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import machine_info, write_result

_CLI = "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))"

_COMPILE = """
import json, sys, time
import jax
jax.config.update("jax_enable_compilation_cache", False)
from atlasnn.compile_cache import compile_lowered
from atlasnn.training import training_compiler_options
exp = jax.export.deserialize(bytearray(open(sys.argv[1], "rb").read()))
lowered = jax.jit(exp.call).lower(*[jax.ShapeDtypeStruct(a.shape, a.dtype) for a in exp.in_avals])
start = time.perf_counter()
compile_lowered(lowered, training_compiler_options() if sys.argv[2] == "training" else None)
print(json.dumps(time.perf_counter() - start))
"""

_ELEMENTWISE = """
import json
import jax, jax.numpy as jnp, numpy as np
from atlasnn.compile_cache import compile_lowered
from atlasnn.training import training_compiler_options
x = np.random.default_rng(0).uniform(-60, 60, 2_000_000).astype(np.float32)
fns = {"sin": jnp.sin, "cos": jnp.cos, "tanh": jnp.tanh, "exp": lambda v: jnp.exp(-jnp.abs(v) / 10)}
ref = {"sin": np.sin, "cos": np.cos, "tanh": np.tanh, "exp": lambda v: np.exp(-np.abs(v) / 10)}
out = {}
for name, f in fns.items():
    lowered = jax.jit(f).lower(x)
    a = np.asarray(compile_lowered(lowered, None)(x))
    b = np.asarray(compile_lowered(lowered, training_compiler_options())(x))
    truth = ref[name](x.astype(np.float64))
    out[name] = {"max_abs_error_defaults": float(np.abs(a - truth).max()),
                 "max_abs_error_training_options": float(np.abs(b - truth).max()), "identical": bool((a == b).all())}
print(json.dumps(out))
"""


def _python(code: str, *args: str, core: int, env: dict) -> str:
    proc = subprocess.run(["taskset", "-c", str(core), sys.executable, "-c", code, *args], env=env,
                          capture_output=True, text=True, check=True)
    return proc.stdout.strip().splitlines()[-1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.compile_options", description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--out", default="docs/benchmarks/compile_options.json")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        env = {**os.environ, "ATLASNN_CACHE_DIR": str(tmp / "cache")}
        config = tmp / "hh.toml"
        for cmd in (["init", str(config), "--system", "henon_heiles", "--T", "24*pi", "--march"],
                    ["run", str(config), "--no-progress", "--figures", "none", "--out", str(tmp / "run")]):
            subprocess.run([sys.executable, "-c", _CLI, *cmd], env=env, check=True, capture_output=True)
        programs = {p.name.split("-")[0]: p for p in sorted((tmp / "cache" / "exported").glob("*.bin"))}
        seconds = {name: {"defaults": [], "training": []} for name in ("adam", "lm")}
        for _ in range(args.rounds):
            for name in seconds:
                for options in ("defaults", "training"):
                    seconds[name][options].append(json.loads(_python(_COMPILE, str(programs[name]), options,
                                                                     core=args.core, env=env)))
        elementwise = json.loads(_python(_ELEMENTWISE, core=args.core, env=env))
    medians = {name: {k: statistics.median(v) for k, v in by.items()} for name, by in seconds.items()}
    for name, m in medians.items():
        print(f"{name}: compiles in {m['defaults']:.2f} s with XLA's defaults, {m['training']:.2f} s with the "
              f"training options (medians of {args.rounds})")
    for name, e in elementwise.items():
        print(f"{name}: max abs error {e['max_abs_error_defaults']:.2e} / {e['max_abs_error_training_options']:.2e}, "
              f"identical: {e['identical']}")
    write_result(args.out, {"case": "the first hour's case's Adam chunk and LM program, read back and compiled",
                            "seconds": seconds, "median_seconds": medians, "elementwise": elementwise,
                            "machine": machine_info(),
                            "command": "python -m benchmarks.compile_options " + " ".join(argv or sys.argv[1:])})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

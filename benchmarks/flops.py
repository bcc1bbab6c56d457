"""How close is a training epoch to this CPU's float32 arithmetic limit?

Counts the floating-point operations of one epoch of the MLP at K collocation points (forward
values, forward-mode time derivatives, reverse pass for the parameter gradient), measures the
float32 matrix-product rate of this machine on the step's own shapes (XLA through JAX, and
NumPy), and, given a throughput JSON, compares.

Count (multiply and add = 2 flops; one hidden W×W layer per depth step beyond the first):

- each dense product of K rows, n_in → n_out, costs 2·K·n_in·n_out;
- forward: the values h and their time derivatives dh/dt go through every product (2 products
  per layer); reverse: each of those products needs the gradient of its input and of its weight
  (2 more each, except the input gradient of the first layer, whose input t needs none);
- so per layer (n_in → n_out): 6 · 2·K·n_in·n_out for the hidden and output layers; the first
  layer (1 → W) is elementwise (a few K·W);
- elementwise work (sin/cos, products with σ', the loss, Adam) is counted apart and is small.

Usage::

    python -m benchmarks.flops [--throughput FILE.json] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from benchmarks.common import CONFIGS


def epoch_flops(K: int, width: int, depth: int, out: int) -> dict:
    dense = 0
    sizes = [width] * depth + [out]
    for n_in, n_out in zip(sizes[:-1], sizes[1:]):
        dense += 6 * 2 * K * n_in * n_out
    # elementwise, per hidden unit and point: sin/cos kernel (~60 flops for both, counted as 60),
    # forward products and sums (~4), reverse (~10); first layer ~6 more
    elementwise = K * width * depth * (60 + 4 + 10) + 6 * K * width
    return {"dense": dense, "elementwise_approx": elementwise, "total": dense + elementwise}


def _best_time(fn, reps: int) -> float:
    best = float("inf")
    for _ in range(reps):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def matmul_rates(shapes, loops: int = 300, reps: int = 5) -> list[dict]:
    """GFLOP/s of [K, n] @ [n, m] products in float32, XLA (jit loop) and NumPy."""
    import jax

    rows = []
    rng = np.random.default_rng(0)
    for K, n, m in shapes:
        a = rng.standard_normal((K, n)).astype(np.float32)
        b = (rng.standard_normal((n, m)) * 0.01).astype(np.float32)
        c = rng.standard_normal((K, m)).astype(np.float32)

        def loop(x, w, g):
            def body(carry, _):
                w = carry
                y = x @ w  # forward product
                dw = x.T @ (y * 1e-9 + g)  # weight-gradient product (contraction over K)
                return w - 1e-9 * dw, None

            return jax.lax.scan(body, w, None, length=loops)[0]

        f = jax.jit(loop).lower(a, b, c).compile()
        f(a, b, c).block_until_ready()
        t_xla = _best_time(lambda: f(a, b, c).block_until_ready(), reps) / (2 * loops)
        t_np = _best_time(lambda: [np.dot(a, b) for _ in range(loops // 3)], reps) / (loops // 3)
        flops = 2 * K * n * m
        rows.append({"shape": [K, n, m], "flops": flops, "xla_us": t_xla * 1e6, "xla_gflops": flops / t_xla / 1e9,
                     "numpy_us": t_np * 1e6, "numpy_gflops": flops / t_np / 1e9})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.flops", description=__doc__.split("\n")[0])
    ap.add_argument("--throughput", default=None, help="a JSON written by benchmarks.throughput --out")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    outs = {"nonlinear_oscillator": 2, "henon_heiles": 4}
    per = {name: epoch_flops(c.n_points, c.width, c.depth, outs[c.system]) for name, c in CONFIGS.items()}
    shapes = sorted({(c.n_points, c.width, c.width) for c in CONFIGS.values()})
    rates = matmul_rates(shapes)
    print("float32 matrix products on this machine (best of 5; XLA: forward and weight-gradient products in a loop):")
    for r in rates:
        K, n, m = r["shape"]
        print(f"  [{K},{n}]x[{n},{m}]: XLA {r['xla_us']:.1f} us = {r['xla_gflops']:.1f} GFLOP/s, "
              f"NumPy {r['numpy_us']:.1f} us = {r['numpy_gflops']:.1f} GFLOP/s")
    thr = None
    if args.throughput:
        with open(args.throughput) as fh:
            thr = {row["config"]: row for row in json.load(fh)["rows"]}
    print()
    print("config | MFLOP/epoch (dense) | MFLOP/epoch (all) | XLA GFLOP/s on its shape | floor ms/epoch | "
          "measured ms/epoch | achieved GFLOP/s | fraction of matmul rate")
    print("--- | --- | --- | --- | --- | --- | --- | ---")
    table = []
    for name, c in CONFIGS.items():
        f = per[name]
        rate = next(r for r in rates if r["shape"] == [c.n_points, c.width, c.width])["xla_gflops"]
        floor_ms = f["total"] / (rate * 1e9) * 1e3
        row = {"config": name, **f, "matmul_gflops": rate, "floor_ms": floor_ms}
        line = (f"{name} | {f['dense'] / 1e6:.1f} | {f['total'] / 1e6:.1f} | {rate:.1f} | {floor_ms:.3f}")
        if thr and name in thr:
            ms = thr[name]["atlas_ms"]
            achieved = f["total"] / (ms * 1e-3) / 1e9
            row.update(measured_ms=ms, achieved_gflops=achieved, fraction=achieved / rate)
            line += f" | {ms:.3f} | {achieved:.1f} | {achieved / rate:.2f}"
        else:
            line += " | n/a | n/a | n/a"
        print(line)
        table.append(row)
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"benchmark": "flops", "matmul": rates, "configs": table}, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

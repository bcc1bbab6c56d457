"""Accuracy and speed of atlasnn's float32 sin/cos kernel against XLA's jnp.sin/jnp.cos.

Errors are measured against float64 NumPy on uniform random float32 arguments in ±limit, in
ulps of the float32 result and in absolute terms; speed on a [500, 80] array (one hidden layer of
the oscillator-transfer target) in a compiled loop.

Usage::

    python -m benchmarks.sincos_accuracy [--n 2000000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def ulp_error(y: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return np.abs(y.astype(np.float64) - ref) / np.spacing(np.abs(ref).astype(np.float32)).astype(np.float64)


def main(argv: list[str] | None = None) -> int:
    import jax
    import jax.numpy as jnp

    from atlasnn.nn import SINCOS_FAST_LIMIT, sin_cos

    ap = argparse.ArgumentParser(prog="python -m benchmarks.sincos_accuracy", description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=2_000_000)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    fast = jax.jit(sin_cos)
    xla = jax.jit(lambda x: (jnp.sin(x), jnp.cos(x)))
    print(f"fast path for |x| <= {SINCOS_FAST_LIMIT:g}; beyond it jnp.sin/jnp.cos are used")
    print("range | kernel sin max/mean ulp | kernel cos max/mean ulp | kernel max abs err | "
          "XLA sin max/mean ulp | XLA max abs err")
    print("--- | --- | --- | --- | --- | ---")
    for limit in (1.0, 4.0, 100.0, 1000.0, 8192.0):
        x = rng.uniform(-limit, limit, args.n).astype(np.float32)
        rs, rc = np.sin(x.astype(np.float64)), np.cos(x.astype(np.float64))
        s, c = map(np.asarray, fast(jnp.asarray(x)))
        xs, xc = map(np.asarray, xla(jnp.asarray(x)))
        us, uc, ux = ulp_error(s, rs), ulp_error(c, rc), ulp_error(xs, rs)
        abs_k = max(np.abs(s - rs).max(), np.abs(c - rc).max())
        abs_x = max(np.abs(xs - rs).max(), np.abs(xc - rc).max())
        print(f"±{limit:g} | {us.max():.2f} / {us.mean():.3f} | {uc.max():.2f} / {uc.mean():.3f} | {abs_k:.1e} | "
              f"{ux.max():.2f} / {ux.mean():.3f} | {abs_x:.1e}")

    x0 = jnp.asarray(rng.uniform(-60, 60, (500, 80)).astype(np.float32))

    def loop(f):
        def run(x):
            def body(carry, _):
                s, c = f(carry)
                return carry + 1e-7 * (s + c), None

            return jax.lax.scan(body, x, None, length=200)[0]

        return jax.jit(run)

    timings = {}
    for name, f in (("kernel sin_cos", sin_cos), ("XLA sin + cos", lambda x: (jnp.sin(x), jnp.cos(x)))):
        g = loop(f)
        g(x0).block_until_ready()
        best = float("inf")
        for _ in range(5):
            start = time.perf_counter()
            g(x0).block_until_ready()
            best = min(best, time.perf_counter() - start)
        timings[name] = best / 200 * 1e6
    print("\n[500, 80] array, best of 5: " + ", ".join(f"{k} {v:.1f} us" for k, v in timings.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

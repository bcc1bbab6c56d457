"""Many trajectories in one program: ``atlasnn.solve_batch`` over B Hénon–Heiles initial states
(energy below the escape energy 1/6, drawn from a seeded box) against solving them one by one and
against Diffrax's Dopri8 vmapped over the same members (the ``bench`` extra), on this machine's CPU.
Time after compilation (best of 2), worst member's max error at 500 times relative to its range
(DOP853 at 1e-13 per member).

    python -m benchmarks.solver_batch --out docs/benchmarks/solver_batch.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn import solve, solve_batch
from atlasnn.evaluation import reference_solution
from atlasnn.systems import henon_heiles

from benchmarks.common import machine_info
from benchmarks.solver_workprecision import timed  # noqa: F401


def members(count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    system, out = henon_heiles(), []
    while len(out) < count:
        z = rng.uniform([-0.3, -0.3, -0.3, -0.3], [0.3, 0.3, 0.3, 0.3])
        if float(system.energy64(z)) < 0.12:
            out.append(z)
    return np.array(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/solver_batch.json")
    ap.add_argument("--sizes", type=int, nargs="*", default=[1, 8, 32])
    ap.add_argument("--T", type=float, default=6 * np.pi)
    args = ap.parse_args(argv)
    system, T = henon_heiles(), args.T
    t = np.linspace(0.0, T, 500)
    rows = []
    for b in args.sizes:
        z0s = members(b)
        refs = [reference_solution(system, z, t, rtol=1e-13, atol=1e-13) for z in z0s]
        scale = [float(np.ptp(r, axis=0).max()) for r in refs]

        def worst(zs):
            return max(float(np.abs(z - r).max()) / s for z, r, s in zip(zs, refs, scale))

        solve_batch(system, z0s, (0.0, T), rtol=1e-10, atol=1e-12)
        sols, batched, _ = timed(lambda: [s(t) for s in solve_batch(system, z0s, (0.0, T), rtol=1e-10, atol=1e-12)], 2)
        solve(system, z0s[0], (0.0, T), rtol=1e-10, atol=1e-12)
        alone, one_by_one, _ = timed(lambda: [solve(system, z, (0.0, T), rtol=1e-10, atol=1e-12)(t) for z in z0s], 2)
        row = {"members": b, "batched_seconds": batched, "one_by_one_seconds": one_by_one,
               "batched_worst_error": worst(sols), "one_by_one_worst_error": worst(alone)}
        try:
            import diffrax

            with jax.enable_x64(True):
                field = lambda tt, y, a: system.vector_field(y[None])[0]  # noqa: E731

                @jax.jit
                def run(y0s):
                    def one(y0):
                        return diffrax.diffeqsolve(diffrax.ODETerm(field), diffrax.Dopri8(), 0.0, T, None, y0,
                                                   saveat=diffrax.SaveAt(ts=jnp.asarray(t)), max_steps=100_000,
                                                   stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12)).ys
                    return jax.vmap(one)(y0s)

                y = jnp.asarray(z0s)
                jax.block_until_ready(run(y))
                zs, dsec, _ = timed(lambda: np.asarray(run(y)), 2)
            row.update(diffrax_dopri8_seconds=dsec, diffrax_worst_error=worst(list(zs)))
        except ImportError:
            pass
        rows.append(row)
        print(row, flush=True)
    Path(args.out).write_text(json.dumps({"command": "python -m benchmarks.solver_batch", "machine": machine_info(),
                                          "T": T, "rtol": 1e-10, "atol": 1e-12, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()

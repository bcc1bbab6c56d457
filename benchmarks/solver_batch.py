"""Many trajectories: ``atlasnn.solve_batch`` (the Gauss collocation, one compiled program for all
members) over B Hénon–Heiles initial states (energy below 0.12 < the escape energy 1/6, drawn from
a seeded box), against Diffrax's Tsit5 and Dopri8 ``vmap``-ed over the same members (the ``bench``
extra), on this machine's CPU. Time after compilation (best of 2) for the solutions and their
values at 100 times per member; the worst member's max error relative to its range, over a sample
of up to 50 members (reference: DOP853 at rtol 2.3e-14 per member).

    python -m benchmarks.solver_batch --out docs/benchmarks/solver_batch.json
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn import solve_batch
from atlasnn.evaluation import reference_solution
from atlasnn.solver import GaussCollocation
from atlasnn.systems import henon_heiles

from benchmarks.common import machine_info, write_result
from benchmarks.problems import timed


def members(count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    system, out = henon_heiles(), []
    while len(out) < count:
        z = rng.uniform(-0.3, 0.3, (4 * count, 4))
        out.extend(z[system.energy64(z) < 0.12])
    return np.array(out[:count])


def diffrax_run(system, T, t, method, rtol):
    import diffrax

    field = lambda tt, y, a: system.vector_field(y[None])[0]  # noqa: E731

    @jax.jit
    def run(y0s):
        def one(y0):
            return diffrax.diffeqsolve(diffrax.ODETerm(field), method, 0.0, T, None, y0,
                                       saveat=diffrax.SaveAt(ts=jnp.asarray(t)), max_steps=100_000,
                                       stepsize_controller=diffrax.PIDController(rtol=rtol, atol=rtol / 100)).ys
        return jax.vmap(one)(y0s)

    return run


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/solver_batch.json")
    ap.add_argument("--sizes", type=int, nargs="*", default=[1, 100, 1000, 10000])
    ap.add_argument("--T", type=float, default=6 * np.pi)
    args = ap.parse_args(argv)
    system, T = henon_heiles(), args.T
    t = np.linspace(0.0, T, 100)
    solver = GaussCollocation()
    rows = []
    for b in args.sizes:
        z0s = members(b)
        check = np.linspace(0, b - 1, min(b, 50)).astype(int)
        refs = {int(i): reference_solution(system, z0s[i], t, rtol=2.3e-14, atol=1e-16) for i in check}

        def worst(zs):
            return max(float(np.abs(zs[i] - r).max() / np.ptp(r, axis=0).max()) for i, r in refs.items())

        solve_batch(system, z0s, (0.0, T), solver=solver)  # compiles the batched program for this many members
        zs, gauss_s, _ = timed(lambda: [s(t) for s in solve_batch(system, z0s, (0.0, T), solver=solver)], 2)
        row = {"members": b, "gauss_seconds": gauss_s, "gauss_worst_error": worst(zs)}
        try:
            import diffrax
        except ImportError:
            diffrax = None
        if diffrax is not None:
            with jax.enable_x64(True):
                y = jnp.asarray(z0s)
                for label, method in (("tsit5", diffrax.Tsit5()), ("dopri8", diffrax.Dopri8())):
                    for rtol in (1e-10, 1e-12, 1e-14):
                        run = diffrax_run(system, T, t, method, rtol)
                        jax.block_until_ready(run(y))
                        out, sec, _ = timed(lambda: np.asarray(run(y)), 2)
                        row[f"{label}_{rtol:g}_seconds"] = sec
                        row[f"{label}_{rtol:g}_worst_error"] = worst(out)
        rows.append(row)
        print({k: (f"{v:.3g}" if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
        write_result(args.out, {"command": "python -m benchmarks.solver_batch " + " ".join(argv or []),
                                "machine": machine_info(), "T": T, "solver": solver.settings(), "rows": rows})


if __name__ == "__main__":
    main()

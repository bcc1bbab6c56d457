"""What a training step of ``learn_hamiltonian`` costs, by method, at equal data: an HNN, through
the Gauss solver (the default ``ThroughSolver``), and through an explicit splitting (leapfrog, one
step per observation interval, segments end to end), on a chain of 10 unit masses with quartic
springs (fixed ends) observed every 0.5 over [0, 12] from six states, noise σ = 0.01; the same
separable network (T_θ(p) + V_θ(q), two 2 × 32 softplus MLPs) and Adam steps for each. One core.

Reported per method: the wall time per training step after compilation (between the training's
first and last progress reports, held-out checks included; the Gauss solver trains a tenth as many
steps), the final training loss, and whether it is trusted (the trust rules' verdict). It measures cost, not which method learns the chain best (that is
``benchmarks.learned_h``).

    python -m benchmarks.learned_h_cost --out docs/benchmarks/learned_h_cost.json
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.common import machine_info, write_result

MASSES = 10


def chain_h(q, p):
    d = jnp.diff(jnp.concatenate([jnp.zeros(1), q, jnp.zeros(1)]))
    return 0.5 * jnp.sum(p ** 2) + 0.5 * jnp.sum(d ** 2) + 0.125 * jnp.sum(d ** 4)


class Separable(eqx.Module):
    kinetic: eqx.nn.MLP
    potential: eqx.nn.MLP

    def __call__(self, q, p):
        return self.kinetic(p)[0] + self.potential(q)[0]


def model(seed: int = 0) -> Separable:
    k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
    return Separable(eqx.nn.MLP(MASSES, 1, 32, 2, activation=jax.nn.softplus, key=k1),
                     eqx.nn.MLP(MASSES, 1, 32, 2, activation=jax.nn.softplus, key=k2))


def data(spacing: float = 0.5, sigma: float = 0.01, span: float = 12.0, count: int = 6) -> list:
    import atlasnn

    truth = atlasnn.HamiltonianSystem(chain_h, MASSES, separable=True)
    times = np.arange(0.0, span + 1e-9, spacing)
    rng = np.random.default_rng(0)
    out = []
    for _ in range(count):
        z0 = np.concatenate([0.5 * rng.standard_normal(MASSES), 0.3 * rng.standard_normal(MASSES)])
        z = atlasnn.solve(truth, z0, (0.0, span))(times)
        out.append((times, z + sigma * rng.standard_normal(z.shape)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--out", default="docs/benchmarks/learned_h_cost.json")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    from atlasnn import learn_hamiltonian
    from atlasnn.inverse import HNN, ThroughSolver
    from atlasnn.solver import SplittingComposition

    trajectories = data()
    leapfrog = SplittingComposition(scheme="leapfrog", steps=5)
    methods = {"HNN": lambda n: HNN(steps=n),
               "through leapfrog (5 steps a segment, end to end)":
                   lambda n: ThroughSolver(steps=n, stride=5, solver=leapfrog),
               "through the Gauss solver (default)": lambda n: ThroughSolver(steps=max(2, n // 10))}
    rows = []
    for name, method in methods.items():
        tic, marks = time.perf_counter(), []
        result = learn_hamiltonian(model(), trajectories, method(args.steps), noise=0.01,
                                   progress=lambda k, loss: marks.append((k, time.perf_counter())))
        (k0, t0), (k1, t1) = marks[0], marks[-1]
        row = {"method": name, "step_ms": 1e3 * (t1 - t0) / (k1 - k0), "steps": result.steps,
               "wall_seconds": time.perf_counter() - tic, "loss": result.loss, "trusted": result.trusted}
        print(f"  {name:52s} {row['step_ms']:8.2f} ms a step, loss {row['loss']:.2e}, trusted {row['trusted']}")
        rows.append(row)
    hnn = rows[0]["step_ms"]
    for row in rows:
        row["over_hnn"] = row["step_ms"] / hnn
    write_result(args.out, {"command": f"python -m benchmarks.learned_h_cost --steps {args.steps}",
                            "machine": machine_info(), "rows": rows})


if __name__ == "__main__":
    main()

"""Learn a pendulum's Hamiltonian from three noisy trajectories with ``atlasnn.learn_hamiltonian``,
two ways — through the solver, and as a Hamiltonian neural network (HNN, Greydanus et al. 2019) —
with the same network, data and Adam steps; then predict a held-out start over ten times the
training span with each learned H and draw both against the truth.

    python examples/learn_hamiltonian.py --steps 1000 --figure pendulum-learned.png
    python examples/learn_hamiltonian.py --steps 50                      # a quick check

The comparison over five systems and three noise levels, with RK4 rollouts as a third way:
``python -m benchmarks.learned_h`` (docs/howto/LEARN_H.md).
"""

from __future__ import annotations

import argparse

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import atlasnn
from atlasnn import learn_hamiltonian
from atlasnn.inverse import HNN, ThroughSolver

jax.config.update("jax_enable_x64", True)

SPAN, HORIZON = 3.0, 30.0
STARTS = [[1.0, 0.0], [0.0, 1.2], [-0.5, -0.6]]
HELD_OUT = [0.7, -0.4]


class NetworkH(eqx.Module):
    """H_θ(q, p): an MLP of (q, p) to a scalar."""

    mlp: eqx.nn.MLP

    def __call__(self, q, p):
        return self.mlp(jnp.concatenate([q, p]))[0]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="Adam steps of each training")
    parser.add_argument("--sigma", type=float, default=0.01, help="noise of the observations")
    parser.add_argument("--figure", help="draw the held-out prediction here (PNG)")
    args = parser.parse_args(argv)
    truth = atlasnn.HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 - jnp.cos(q[0]), 1, name="pendulum")
    times = np.arange(0.0, SPAN + 0.05, 0.1)
    rng = np.random.default_rng(0)
    data = [(times, atlasnn.solve(truth, z, (0.0, SPAN))(times) + args.sigma * rng.standard_normal((times.size, 2)))
            for z in STARTS]
    t = np.linspace(0.0, HORIZON, 601)
    reference = atlasnn.solve(truth, HELD_OUT, (0.0, HORIZON))(t)
    predictions = {}
    for method in (ThroughSolver(steps=args.steps), HNN(steps=args.steps)):
        net = NetworkH(eqx.nn.MLP(2, 1, 32, 2, activation=jax.nn.softplus, key=jax.random.PRNGKey(0)))
        learned = learn_hamiltonian(net, data, method, noise=args.sigma)
        z = atlasnn.solve(learned.system, HELD_OUT, (0.0, HORIZON))(t)
        predictions[method.name] = z
        print(f"{method.name:20s} loss {learned.loss:.2e} (held-out part {learned.held_out_loss:.2e}), "
              f"{learned.seconds:.0f} s, trusted: {learned.trusted}; from {HELD_OUT} over [0, {HORIZON:g}]: "
              f"largest state error {np.abs(z - reference).max():.2e}")
        for note in learned.notes:
            print("   ", note)
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(8, 3.4))
        ax.plot(t, reference[:, 0], "k", lw=2.5, alpha=0.35, label="true")
        for (name, z), style in zip(predictions.items(), ("C0", "C3--")):
            ax.plot(t, z[:, 0], style, lw=1, label=f"learned {name}")
        ax.axvline(SPAN, color="gray", lw=0.8)
        ax.set(xlabel="t", ylabel="q", title=f"held-out start {HELD_OUT} (training data end at t = {SPAN:g})")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.figure, dpi=110)
        print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()

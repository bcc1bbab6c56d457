"""A learned Hamiltonian: a pendulum of unknown mass and gravity, H = a·p²/2 − g·cos q with a = 1/m
and g unknown (truth a = 1, g = 2), learned from three noisy trajectories (σ = 0.01, observed every
0.1 over [0, 3]) by ``atlasnn.learn_hamiltonian`` through the solver (``ThroughSolver``: gradients
by ``jax.grad`` through the Gauss solver), from the guess a = 0.6, g = 1.2. The training loss
against the noise's own, the parameters found, and the learned H solved from a start not trained on
over ten times the training span, against the truth; checked: the parameters within 2 % of the
truth and the result trusted.

    python examples/gallery/learned_hamiltonian.py --steps 300 --figure docs/figures/gallery/learned_hamiltonian.png
"""

from __future__ import annotations

import argparse

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import atlasnn
from atlasnn import learn_hamiltonian
from atlasnn.inverse import ThroughSolver

jax.config.update("jax_enable_x64", True)

SIGMA, SPAN, HORIZON = 0.01, 3.0, 30.0
HELD_OUT = [0.7, -0.4]


# --8<-- [start:learn]
class Pendulum(eqx.Module):
    """H = a·p²/2 − g·cos q: a known form; its floating-point fields a and g are what is learned."""

    a: jax.Array
    g: jax.Array

    def __call__(self, q, p):
        return self.a * p[0] ** 2 / 2 - self.g * jnp.cos(q[0])


def learn(steps: int):
    """Three noisy trajectories of the truth (a = 1, g = 2), and H learned from them."""
    truth = atlasnn.HamiltonianSystem(Pendulum(jnp.array(1.0), jnp.array(2.0)), 1, name="pendulum")
    times = np.arange(0.0, SPAN + 0.05, 0.1)
    rng = np.random.default_rng(0)
    data = [(times, atlasnn.solve(truth, z0, (0.0, SPAN))(times) + SIGMA * rng.standard_normal((times.size, 2)))
            for z0 in ([1.0, 0.0], [0.0, 1.5], [-0.5, -0.8])]
    learned = learn_hamiltonian(Pendulum(jnp.array(0.6), jnp.array(1.2)), data,
                                ThroughSolver(steps=steps, rate=0.05), noise=SIGMA)
    return truth, learned
# --8<-- [end:learn]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=300, help="Adam steps")
    parser.add_argument("--figure", default="learned_hamiltonian.png")
    args = parser.parse_args(argv)
    truth, learned = learn(args.steps)
    a, g = float(learned.model.a), float(learned.model.g)
    t = np.linspace(0.0, HORIZON, 601)
    reference = atlasnn.solve(truth, HELD_OUT, (0.0, HORIZON))(t)
    predicted = atlasnn.solve(learned.system, HELD_OUT, (0.0, HORIZON))(t)  # an ordinary system
    floor = 2 * SIGMA ** 2  # the noise's own loss: the start's noise carried forward, and the target's
    print(f"{learned.steps} Adam steps in {learned.seconds:.1f} s: loss {learned.curve[0]:.1e} → {learned.loss:.1e} "
          f"(the noise's own {floor:.0e}), held-out part {learned.held_out_loss:.1e}, trusted: {learned.trusted}")
    print(f"a = {a:.4f} (truth 1), g = {g:.4f} (truth 2); from {HELD_OUT} over [0, {HORIZON:g}]: "
          f"largest state error {np.abs(predicted - reference).max():.1e}")
    for note in learned.notes:
        print("   ", note)
    worst = max(abs(a - 1.0), abs(g - 2.0) / 2.0)
    assert learned.trusted and worst < 0.02, "the parameters are not recovered within 2 %"

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.4), gridspec_kw={"width_ratios": [1, 1.6]})
    left.semilogy(np.arange(1, len(learned.curve) + 1), learned.curve, lw=1, label="training loss")
    left.axhline(floor, color="0.5", ls="--", lw=0.8, label="the noise's own, 2σ²")
    left.set_xlabel("Adam step")
    left.set_title(f"a = {a:.3f}, g = {g:.3f} (truth 1, 2)")
    left.legend(fontsize=8)
    right.plot(t, reference[:, 0], "k", lw=2.5, alpha=0.35, label="truth")
    right.plot(t, predicted[:, 0], "C0", lw=1, label="learned H")
    right.axvspan(0.0, SPAN, color="0.93", lw=0, label="training span")
    right.set(xlabel="t", ylabel="q", ylim=(-1.25, 1.0),
              title=f"from {HELD_OUT}, not trained on: largest error {np.abs(predicted - reference).max():.0e}")
    right.legend(fontsize=8, loc="lower center", ncol=3)
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()

"""A gradient through the solver: the pendulum H = p²/2 − cos q released from rest at q0, its angle
at T = 10 and ∂q(T)/∂q0 by ``jax.grad`` through ``atlasnn.solve`` (the adjoint of the Gauss march,
batched over q0 by ``jax.vmap``), against central differences of the host solve.

    python examples/gallery/pendulum_gradient.py --points 40 --figure docs/figures/gallery/pendulum_gradient.png
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

import atlasnn

jax.config.update("jax_enable_x64", True)
T = 10.0


# --8<-- [start:gradient]
pendulum = atlasnn.HamiltonianSystem(lambda q, p: 0.5 * jnp.sum(p ** 2) - jnp.sum(jnp.cos(q)), 1, name="pendulum")


def angle(q0):
    """q(T) of the pendulum released from rest at q0: a JAX function of q0."""
    return atlasnn.solve(pendulum, jnp.stack([q0, 0.0 * q0]), (0.0, T))(T)[0]


angle_and_slope = jax.jit(jax.vmap(jax.value_and_grad(angle)))  # q(T) and ∂q(T)/∂q0 at many q0 at once
# --8<-- [end:gradient]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=12)
    parser.add_argument("--figure", default="pendulum_gradient.png")
    args = parser.parse_args(argv)
    q0s = np.linspace(0.2, 3.0, args.points)
    value, slope = angle_and_slope(jnp.asarray(q0s))
    eps = 1e-6
    host = lambda q0: atlasnn.solve(pendulum, [q0, 0.0], (0.0, T))(T)[0]  # noqa: E731
    central = np.array([(host(q + eps) - host(q - eps)) / (2 * eps) for q in q0s])
    gap = np.max(np.abs(np.asarray(slope) - central) / np.maximum(1.0, np.abs(central)))
    print(f"{args.points} initial angles: max |grad − central difference| / max(1, |∂q/∂q0|) = {gap:.1e}")
    assert gap < 1e-4  # the differences' own error at eps = 1e-6 (rtol 1e-11 / eps, and O(eps²))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    top.plot(q0s, np.asarray(value), "k-", lw=1)
    top.set_ylabel(f"q(T = {T:g})")
    bottom.plot(q0s, np.asarray(slope), "-", lw=1, label="jax.grad through atlasnn.solve")
    bottom.plot(q0s, central, "o", ms=3, mfc="none", label="central differences (ε = 1e-6)")
    bottom.set_yscale("symlog", linthresh=1.0)
    bottom.set_xlabel("initial angle q0 (released from rest)")
    bottom.set_ylabel("∂q(T)/∂q0")
    bottom.legend(fontsize=8)
    top.set_title("The pendulum's final angle and its derivative, through the solver")
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()

"""Solve a user-defined Hamiltonian with ATLAS-NN: the simple pendulum H = p²/2 − cos q.

Nothing in the package knows about the pendulum: the Hamiltonian is a plain JAX-traceable Python
function handed to :class:`atlasnn.systems._hamiltonian.HamiltonianSystem`. The trained network is compared
with the high-accuracy reference solution (SciPy DOP853, rtol = atol = 1e-12).

    python examples/pendulum.py                 # default budget
    python examples/pendulum.py --epochs 2000   # quicker, less accurate
"""

from __future__ import annotations

import argparse
import math
import time

import jax.numpy as jnp
import numpy as np

from atlasnn.evaluation import reference_solution
from atlasnn.nn import make_model
from atlasnn.solutions import Solution
from atlasnn.systems import HamiltonianSystem
from atlasnn.training import TrainConfig, train


def pendulum_hamiltonian(q, p):
    """H(q, p) = p²/2 − cos q, for q, p of shape (1,)."""
    return p[0] ** 2 / 2 - jnp.cos(q[0])


def make_pendulum(z0=(1.0, 0.0)) -> HamiltonianSystem:
    return HamiltonianSystem(
        pendulum_hamiltonian,
        dim=1,
        name="pendulum",
        q_names=("theta",),
        p_names=("p",),
        z0=np.asarray(z0, dtype=float),
        separable=True,  # H = T(p) + V(q)
    )


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=5000, help="training epochs (default 5000)")
    ap.add_argument("--T", type=float, default=2 * math.pi, help="end of the interval [0, T] (default 2π)")
    ap.add_argument("--scaling", default="rational_exp", help="exp_decay (HNN), tanh or rational_exp (default)")
    ap.add_argument("--width", type=int, default=32)
    ap.add_argument("--depth", type=int, default=2)
    ap.add_argument("--n-points", type=int, default=100, help="collocation points K")
    ap.add_argument("--lr", type=float, default=5e-3)
    ap.add_argument("--sigma", type=float, default=0.1, help="jitter, in units of the grid spacing")
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args(argv)


def main(argv=None) -> dict:
    args = parse_args(argv)
    system = make_pendulum()
    z0 = system.z0

    model = make_model(z0, scaling=args.scaling, width=args.width, depth=args.depth, seed=args.seed)
    cfg = TrainConfig(
        epochs=args.epochs, lr=args.lr, n_points=args.n_points, sigma=args.sigma, seed=args.seed, progress=False
    )
    start = time.perf_counter()
    result = train(model, system, args.T, cfg)
    elapsed = time.perf_counter() - start
    sol = Solution(result.model, system, interval=(0.0, args.T))

    t = np.linspace(0.0, args.T, 10 * args.n_points)
    z_ref = reference_solution(system, z0, t)
    z_net = sol(t).astype(np.float64)
    err = z_net - z_ref
    dt = t[1] - t[0]
    max_abs = np.max(np.abs(err), axis=0)
    l2_sum = np.sqrt(np.sum(err**2, axis=0))  # the release's tables: not scaled by Δt
    trapezoid = getattr(np, "trapezoid", None) or np.trapz  # NumPy < 2 has only trapz
    l2_int = np.sqrt(trapezoid(err**2, dx=dt, axis=0))  # the paper's integral definition
    energy_drift = np.max(np.abs(sol.energy(t) - system.energy(jnp.asarray(z0)).item()))

    print(f"pendulum H = p²/2 − cos q, z0 = {z0.tolist()}, t in [0, {args.T:.4f}]")
    print(
        f"model: scaling={args.scaling}, {args.width}x{args.depth} sin MLP; "
        f"{result.epochs_run} epochs in {elapsed:.1f} s (compile {result.compile_time:.1f} s), "
        f"stop: {result.stop_reason}, returned epoch {result.best_epoch}"
    )
    print(f"loss: first {result.history.loss[0]:.3e}, lowest {result.history.loss.min():.3e}")
    print("reference: SciPy solve_ivp DOP853, rtol=atol=1e-12")
    for i, name in enumerate(system.state_names):
        print(
            f"  {name:>5}: max|err| = {max_abs[i]:.3e}   L2 (sqrt Σ err², {t.size} pts) = {l2_sum[i]:.3e}"
            f"   L2 (∫ err² dt)^½ = {l2_int[i]:.3e}"
        )
    print(f"max |H(ẑ(t)) − H(z0)| = {energy_drift:.3e}")
    gamma = sol.gamma
    print("learned gamma: " + (", ".join(f"{k} = {v:.4f}" for k, v in gamma.items()) or "none (HNN)"))
    return {"max_abs": max_abs, "l2_sum": l2_sum, "l2_int": l2_int, "gamma": gamma, "energy_drift": energy_drift}


if __name__ == "__main__":
    main()

"""Hamiltonians learned from noisy trajectories, three ways, on the tasks the HNN literature uses
(mass–spring, pendulum, two-body, double pendulum, Hénon–Heiles), at noise σ ∈ {0, 0.01, 0.05}:

* through the solver — ``atlasnn.learn_hamiltonian(..., ThroughSolver())``: from every observed
  state, the next five observations predicted by the Gauss collocation, differentiated by JAX;
* HNN — ``learn_hamiltonian(..., HNN())`` (Greydanus et al. 2019): J∇H_θ against central
  differences of the observations;
* RK4 rollouts — the same segments as through the solver, predicted by Diffrax's RK4 at four fixed
  steps per observation interval, the same Adam loop.

The same network (2d → 32 → 32 → 1, softplus, the same initial weights), the same data (three
trajectories observed every 0.1 over [0, 3], noise σ on every component), the same Adam steps and
rate. Each learned H is solved (``atlasnn.solve``, defaults) from three held-out initial states over
[0, 30] — ten times the training span — against the true H's solution: the largest state error
over the output and the median relative error of the true energy along the prediction, each the
median over the three states, and the mean squared error of the true energy along the predictions
(Greydanus et al.'s "energy MSE"). Training times are wall times on the machine recorded.

    python -m benchmarks.learned_h --out docs/benchmarks/learned_h.json --figure docs/benchmarks/learned_h.png
    python -m benchmarks.learned_h --systems pendulum --sigmas 0.01 --steps 50   # a quick check

``--merge`` adds the systems and noise levels run now to the rows already in ``--out``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

import atlasnn
from atlasnn import learn_hamiltonian
from atlasnn.inverse import HNN, ThroughSolver

from benchmarks.common import machine_info, write_result

jax.config.update("jax_enable_x64", True)

SPAN, EVERY, HORIZON, AHEAD = 3.0, 0.1, 30.0, 5


def _double_pendulum(q, p):
    d = q[0] - q[1]
    return ((p[0] ** 2 + 2 * p[1] ** 2 - 2 * p[0] * p[1] * jnp.cos(d)) / (2 * (1 + jnp.sin(d) ** 2))
            - 2 * jnp.cos(q[0]) - jnp.cos(q[1]))


#: name -> (true H(q, p), degrees of freedom, training starts, held-out starts)
SYSTEMS = {
    "mass-spring": (lambda q, p: p[0] ** 2 / 2 + q[0] ** 2 / 2, 1,
                    [[1.0, 0.0], [0.0, 0.8], [-0.5, 0.5]], [[0.7, -0.4], [-1.2, 0.3], [0.2, 0.9]]),
    "pendulum": (lambda q, p: p[0] ** 2 / 2 - jnp.cos(q[0]), 1,
                 [[1.0, 0.0], [0.0, 1.2], [-0.5, -0.6]], [[0.7, -0.4], [-1.2, 0.3], [0.2, 0.9]]),
    "two-body": (lambda q, p: jnp.sum(p ** 2) / 2 - 1 / jnp.sqrt(jnp.sum(q ** 2)), 2,
                 [[1.0, 0.0, 0.0, 1.0], [1.2, 0.0, 0.0, 0.85], [0.0, 0.9, -1.1, 0.0]],
                 [[1.1, 0.0, 0.0, 0.95], [0.0, 1.0, -1.05, 0.0], [-1.0, 0.0, 0.0, -1.1]]),
    "double-pendulum": (_double_pendulum, 2,
                        [[0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.3, -0.3, 0.0, 0.0]],
                        [[0.4, 0.2, 0.0, 0.0], [-0.3, 0.4, 0.0, 0.0], [0.2, -0.5, 0.0, 0.0]]),
    "henon-heiles": (lambda q, p: jnp.sum(p ** 2) / 2 + jnp.sum(q ** 2) / 2 + q[0] ** 2 * q[1] - q[1] ** 3 / 3, 2,
                     [[0.3, -0.3, 0.3, 0.15], [0.0, 0.2, 0.35, 0.0], [-0.2, 0.1, 0.0, 0.3]],
                     [[0.1, -0.2, 0.3, 0.2], [0.25, 0.0, 0.0, 0.3], [-0.1, 0.3, 0.2, -0.1]]),
}


class NetworkH(eqx.Module):
    """H_θ(q, p): an MLP of (q, p) to a scalar."""

    mlp: eqx.nn.MLP

    def __call__(self, q, p):
        return self.mlp(jnp.concatenate([q, p]))[0]


def network(dof: int, seed: int) -> NetworkH:
    net = NetworkH(eqx.nn.MLP(2 * dof, 1, 32, 2, activation=jax.nn.softplus, key=jax.random.PRNGKey(seed)))
    return jax.tree_util.tree_map(lambda x: x.astype(jnp.float64) if eqx.is_inexact_array(x) else x, net)


def observations(name: str, sigma: float, seed: int) -> list:
    H, dof, starts, _ = SYSTEMS[name]
    truth = atlasnn.HamiltonianSystem(H, dof, name=name)
    times = np.arange(0.0, SPAN + EVERY / 2, EVERY)
    rng = np.random.default_rng(seed)
    return [(times, atlasnn.solve(truth, z, (0.0, SPAN))(times) + sigma * rng.standard_normal((times.size, 2 * dof)))
            for z in starts]


def classical_rk4():
    """The classical fourth-order Runge–Kutta method as a Diffrax solver (Diffrax ships no RK4 of
    its own): its Butcher tableau in Diffrax's explicit Runge–Kutta class, for constant steps."""
    import diffrax

    class ClassicalRK4(diffrax.AbstractERK):
        tableau: ClassVar[diffrax.ButcherTableau] = diffrax.ButcherTableau(
            c=np.array([0.5, 0.5, 1.0]), b_sol=np.array([1, 2, 2, 1]) / 6, b_error=np.zeros(4),
            a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])))
        interpolation_cls: ClassVar[Callable] = diffrax.ThirdOrderHermitePolynomialInterpolation.from_k

        def order(self, terms):
            return 4

    return ClassicalRK4()


def rk4_rollouts(net, trajectories, dof: int, steps: int, rate: float) -> tuple:
    """The segments of ``ThroughSolver`` predicted by Diffrax's RK4 (four fixed steps per
    observation interval), trained by Adam: (the network of least loss, its loss, seconds)."""
    import diffrax

    starts = jnp.asarray(np.concatenate([z[:-AHEAD] for _, z in trajectories]))
    targets = jnp.asarray(np.concatenate([np.stack([z[j + 1:len(z) - AHEAD + j + 1] for j in range(AHEAD)], axis=1)
                                          for _, z in trajectories]))
    ts = jnp.asarray(EVERY * np.arange(1, AHEAD + 1))
    rk4 = classical_rk4()

    def loss(params, static):
        system = atlasnn.HamiltonianSystem(eqx.combine(params, static), dof, name="learned")
        term = diffrax.ODETerm(lambda t, z, _: system.vector_field(z[None])[0])

        def predict(z0):
            return diffrax.diffeqsolve(term, rk4, 0.0, ts[-1], EVERY / 4, z0, saveat=diffrax.SaveAt(ts=ts),
                                       stepsize_controller=diffrax.ConstantStepSize(), max_steps=4 * AHEAD + 4).ys

        return jnp.mean((jax.lax.map(predict, starts) - targets) ** 2)

    params, static = eqx.partition(net, eqx.is_inexact_array)
    opt = optax.adam(rate)
    state = opt.init(params)

    @jax.jit
    def step(params, state):
        value, grads = jax.value_and_grad(loss)(params, static)
        updates, state = opt.update(grads, state, params)
        return optax.apply_updates(params, updates), state, value

    best, best_loss = params, np.inf
    started = time.perf_counter()
    for _ in range(steps):
        new, state, value = step(params, state)
        if float(value) < best_loss:
            best, best_loss = params, float(value)
        params = new
    return eqx.combine(best, static), best_loss, time.perf_counter() - started


def held_out(name: str, model) -> dict:
    """The learned H solved from the held-out states over [0, HORIZON] against the true H."""
    H, dof, _, starts = SYSTEMS[name]
    truth = atlasnn.HamiltonianSystem(H, dof, name=name)
    learned = atlasnn.HamiltonianSystem(model, dof, name="learned")
    t = np.linspace(0.0, HORIZON, 601)
    states, energies, mse, failures = [], [], [], []
    for z in np.asarray(starts, np.float64):
        ref = atlasnn.solve(truth, z, (0.0, HORIZON))(t)
        try:
            got = atlasnn.solve(learned, z, (0.0, HORIZON))(t)
        except atlasnn.AtlasError as exc:  # a learned H whose orbit leaves the data's region
            failures.append(str(exc)[:160])
            states.append(np.inf)
            energies.append(np.inf)
            mse.append(np.inf)
            continue
        e0, along = float(truth.energy64(z)), truth.energy64(got)
        states.append(float(np.abs(got - ref).max()))
        energies.append(float(np.median(np.abs(along - e0)) / abs(e0)))
        mse.append(float(np.mean((along - e0) ** 2)))  # Greydanus et al.'s "energy MSE" along a rollout
    return {"state_error": statistics.median(states), "energy_error": statistics.median(energies),
            "energy_mse": float(np.mean(mse)),
            "per_state": {"state_error": states, "energy_error": energies, "energy_mse": mse}, "failures": failures}


def run(name: str, sigma: float, steps: int, rate: float, seed: int) -> list[dict]:
    dof = SYSTEMS[name][1]
    data = observations(name, sigma, seed)
    rows = []
    for method in ("through the solver", "HNN", "RK4 rollouts"):
        if method == "RK4 rollouts":
            model, loss, seconds = rk4_rollouts(network(dof, seed), data, dof, steps, rate)
            extra = {}
        else:
            learner = (ThroughSolver(steps=steps, rate=rate, ahead=AHEAD) if method == "through the solver"
                       else HNN(steps=steps, rate=rate))
            result = learn_hamiltonian(network(dof, seed), data, learner, noise=sigma, held_out=0.0)
            model, loss, seconds = result.model, result.loss, result.seconds
            extra = {"stopped": result.stopped}
        row = {"system": name, "sigma": sigma, "method": method, "loss": loss, "train_seconds": seconds,
               **held_out(name, model), **extra}
        print(f"{name:16s} σ = {sigma:<5g} {method:19s} loss {loss:.2e}  training {seconds:6.1f} s  held-out: state "
              f"error {row['state_error']:.2e}, energy error {row['energy_error']:.2e}", flush=True)
        rows.append(row)
    return rows


def figure(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    systems = list(dict.fromkeys(r["system"] for r in rows))
    sigmas = sorted({r["sigma"] for r in rows})
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    for ax, key, label in zip(axes, ("state_error", "energy_error"), ("held-out state error", "held-out energy error")):
        for m, method in enumerate(methods):
            for s, sigma in enumerate(sigmas):
                xs, ys = [], []
                for i, system in enumerate(systems):
                    hit = [r for r in rows if r["system"] == system and r["method"] == method and r["sigma"] == sigma]
                    if hit and np.isfinite(hit[0][key]):
                        xs.append(i + 0.25 * (m - 1) + 0.06 * (s - 1))
                        ys.append(hit[0][key])
                ax.semilogy(xs, ys, "os^"[s], color=f"C{m}", ms=5,
                            label=f"{method}, σ = {sigma:g}" if key == "state_error" else None)
        ax.set_xticks(range(len(systems)), systems, rotation=15)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, axis="y")
    fig.legend(fontsize=7, ncol=len(methods), loc="lower center")
    fig.suptitle(f"Learned H on held-out states over [0, {HORIZON:g}] (trained on [0, {SPAN:g}])")
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    fig.savefig(path, dpi=110)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--systems", nargs="+", default=list(SYSTEMS), choices=list(SYSTEMS))
    ap.add_argument("--sigmas", nargs="+", type=float, default=[0.0, 0.01, 0.05])
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--rate", type=float, default=3e-3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out")
    ap.add_argument("--merge", action="store_true",
                    help="keep the rows of --out for the systems and noise levels not run now")
    ap.add_argument("--figure")
    args = ap.parse_args(argv)
    rows = [row for name in args.systems for sigma in args.sigmas for row in run(name, sigma, args.steps, args.rate,
                                                                               args.seed)]
    command = "python -m benchmarks.learned_h " + " ".join(
        f"--{k} {' '.join(map(str, v)) if isinstance(v, list) else v}" for k, v in vars(args).items()
        if v is not None and not isinstance(v, bool)) + (" --merge" if args.merge else "")
    if args.merge and args.out and Path(args.out).is_file():
        earlier = json.loads(Path(args.out).read_text(encoding="utf-8"))
        done = {(r["system"], r["sigma"]) for r in rows}
        rows = [r for r in earlier["rows"] if (r["system"], r["sigma"]) not in done] + rows
        command = earlier["command"] + "; " + command
    if args.out:
        write_result(args.out, {"command": command, "machine": machine_info(), "span": SPAN, "every": EVERY,
                                "horizon": HORIZON, "ahead": AHEAD, "steps": args.steps, "rate": args.rate,
                                "network": "MLP 2d → 32 → 32 → 1, softplus", "rows": rows})
    if args.figure:
        figure(rows, args.figure)


if __name__ == "__main__":
    main()

"""Learn a Hamiltonian from noisy trajectories by differentiating through ``atlasnn.solve``, and
compare it with a Hamiltonian neural network (HNN, Greydanus et al. 2019) trained on
finite-difference derivatives of the same data, with the same network and the same optimiser.

The true system is the pendulum H = p²/2 − cos q. Three trajectories are observed on [0, 3] every
0.1 with Gaussian noise σ. The network H_θ(q, p) (an MLP, 2 → 32 → 32 → 1, softplus) is trained two
ways, ``--steps`` Adam steps each:

* through the solver: from every observed state, the next five observations predicted by
  ``atlasnn.solve`` with H_θ (the Gauss collocation, differentiated by ``jax.grad``), squared error;
* HNN: J∇H_θ at every observed state against central differences of the observations.

Each learned H is then solved from held-out initial states over [0, 30] (10× the training span)
and compared with the true trajectory: the state error, and the true energy's error along the
prediction.

    python examples/learn_hamiltonian.py --out docs/runs/learned-hamiltonian/pendulum.json \\
        --figure docs/runs/learned-hamiltonian/pendulum.png
    python examples/learn_hamiltonian.py --steps 20     # a quick check
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

import atlasnn
from atlasnn.solver import GaussCollocation

jax.config.update("jax_enable_x64", True)

SPAN, EVERY, AHEAD, HORIZON = 3.0, 0.1, 5, 30.0
TRAIN_STARTS = np.array([[1.0, 0.0], [0.0, 1.2], [-0.5, -0.6]])
HELD_OUT = np.array([[0.7, -0.4], [-1.2, 0.3], [0.2, 0.9]])


def pendulum(q, p):
    return p[0] ** 2 / 2 - jnp.cos(q[0])


class NetworkH(eqx.Module):
    """H_θ(q, p): an MLP of (q, p) to a scalar."""

    mlp: eqx.nn.MLP

    def __call__(self, q, p):
        return self.mlp(jnp.concatenate([q, p]))[0]


def network(seed: int) -> NetworkH:
    net = NetworkH(eqx.nn.MLP(2, 1, 32, 2, activation=jax.nn.softplus, key=jax.random.PRNGKey(seed)))
    return jax.tree_util.tree_map(lambda x: x.astype(jnp.float64) if eqx.is_inexact_array(x) else x, net)


def observations(sigma: float, seed: int):
    """(times, noisy states (trajectories, times, 2)) of the true pendulum."""
    truth = atlasnn.HamiltonianSystem(pendulum, 1, name="pendulum")
    times = np.arange(0.0, SPAN + EVERY / 2, EVERY)
    clean = np.stack([atlasnn.solve(truth, z, (0.0, SPAN))(times) for z in TRAIN_STARTS])
    return times, clean + sigma * np.random.default_rng(seed).standard_normal(clean.shape)


#: the solver the training differentiates through: a loose tolerance (the noise is far larger) and
#: a small window budget (a prediction spans half a time unit)
TRAINING_SOLVER = GaussCollocation(stages=4, rtol=1e-7, atol=1e-9, max_windows=32)


def through_solver_loss(times, data):
    """Squared error of the next AHEAD observations predicted from each observed state."""
    starts = jnp.asarray(data[:, :-AHEAD].reshape(-1, 2))
    targets = jnp.asarray(np.stack([data[:, j + 1:data.shape[1] - AHEAD + j + 1] for j in range(AHEAD)],
                                   axis=2).reshape(-1, AHEAD, 2))
    ahead = jnp.asarray(times[1:AHEAD + 1] - times[0])

    def loss(net):
        system = atlasnn.HamiltonianSystem(net, 1, name="learned")
        predict = lambda z: atlasnn.solve(system, z, (0.0, ahead[-1]), solver=TRAINING_SOLVER)(ahead)  # noqa: E731
        return jnp.mean((jax.lax.map(predict, starts) - targets) ** 2)

    return loss


def hnn_loss(times, data):
    """Squared error of J∇H_θ against central differences of the observations (interior times)."""
    states = jnp.asarray(data[:, 1:-1].reshape(-1, 2))
    rates = jnp.asarray(((data[:, 2:] - data[:, :-2]) / (times[2] - times[0])).reshape(-1, 2))

    def loss(net):
        system = atlasnn.HamiltonianSystem(net, 1, name="learned")
        return jnp.mean((system.vector_field(states) - rates) ** 2)

    return loss


def train(loss, net, steps: int, rate: float):
    """Adam on ``loss``; returns (the network of least loss, its loss, seconds, the loss curve)."""
    opt = optax.adam(rate)
    state = opt.init(eqx.filter(net, eqx.is_inexact_array))

    @eqx.filter_jit
    def step(net, state):
        value, grads = eqx.filter_value_and_grad(loss)(net)
        updates, state = opt.update(grads, state)
        return eqx.apply_updates(net, updates), state, value

    best, best_loss, curve = net, np.inf, []
    started = time.perf_counter()
    for _ in range(steps):
        new, state, value = step(net, state)
        curve.append(float(value))
        if curve[-1] < best_loss:  # the loss is of ``net``, before this step's update
            best, best_loss = net, curve[-1]
        net = new
    return best, best_loss, time.perf_counter() - started, curve


def held_out(net) -> dict:
    """The learned H solved from the held-out states over [0, HORIZON] against the truth."""
    truth = atlasnn.HamiltonianSystem(pendulum, 1, name="pendulum")
    learned = atlasnn.HamiltonianSystem(net, 1, name="learned")
    t = np.linspace(0.0, HORIZON, 601)
    rows = []
    for z in HELD_OUT:
        ref, got = atlasnn.solve(truth, z, (0.0, HORIZON))(t), atlasnn.solve(learned, z, (0.0, HORIZON))(t)
        e0 = float(truth.energy64(z))
        rows.append({"z0": z.tolist(), "state_error": float(np.abs(got - ref).max()),
                     "energy_error_median": float(np.median(np.abs(truth.energy64(got) - e0)) / abs(e0)),
                     "t": t, "ref": ref, "got": got})
    return rows


def figure(path: str, results: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 3.8))
    first = {name: r["held_out"][0] for name, r in results.items()}
    t, ref = first["through the solver"]["t"], first["through the solver"]["ref"]
    ax1.plot(t, ref[:, 0], "k", lw=2.5, alpha=0.35, label="true")
    truth = atlasnn.HamiltonianSystem(pendulum, 1, name="pendulum")
    e0 = float(truth.energy64(HELD_OUT[0]))
    for (name, row), style in zip(first.items(), ("C0", "C3--")):
        ax1.plot(t, row["got"][:, 0], style, label=name)
        ax2.semilogy(t, np.abs(truth.energy64(row["got"]) - e0) / abs(e0) + 1e-16, style, label=name)
    ax1.axvline(SPAN, color="gray", lw=0.8)
    ax1.set(xlabel="t", ylabel="q", title=f"held-out start {HELD_OUT[0].tolist()} (training ends at t = {SPAN:g})")
    ax2.set(xlabel="t", ylabel="|H(ẑ(t)) − H(z0)| / |H(z0)|", title="true energy along the prediction")
    ax1.legend(fontsize=8)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=600, help="Adam steps of each training")
    parser.add_argument("--sigma", type=float, default=0.01, help="noise of the observations")
    parser.add_argument("--rate", type=float, default=3e-3, help="Adam's learning rate")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", help="write the record (JSON) here")
    parser.add_argument("--figure", help="draw the held-out prediction here (PNG)")
    args = parser.parse_args()
    times, data = observations(args.sigma, args.seed)
    results = {}
    for name, loss in (("through the solver", through_solver_loss(times, data)), ("HNN", hnn_loss(times, data))):
        net, value, seconds, curve = train(loss, network(args.seed), args.steps, args.rate)
        rows = held_out(net)
        results[name] = {"loss": value, "train_seconds": seconds, "held_out": rows, "curve": curve}
        print(f"{name:20s} loss {value:.2e}  training {seconds:6.1f} s  held-out over [0, {HORIZON:g}]: "
              f"state error {np.median([r['state_error'] for r in rows]):.2e} (median), true energy error "
              f"{np.median([r['energy_error_median'] for r in rows]):.2e} (median)")
    solver, noise = results["through the solver"]["loss"], 2 * args.sigma ** 2
    if noise > 0:
        print(f"the through-solver loss is {solver / noise:.2f}× the noise's own (2σ² = {noise:.1e}): "
              + ("at the noise" if solver < 2 * noise else "far above the noise: the network or the training falls short"))
    if args.figure:
        figure(args.figure, results)
    if args.out:
        record = {"command": "python examples/learn_hamiltonian.py " + " ".join(
                      f"--{k} {v}" for k, v in vars(args).items() if v is not None and k not in ("out", "figure")),
                  "sigma": args.sigma, "steps": args.steps, "span": SPAN, "horizon": HORIZON, "methods": {
                      name: {"loss": r["loss"], "train_seconds": r["train_seconds"],
                             "held_out": [{k: v for k, v in row.items() if k not in ("t", "ref", "got")}
                                          for row in r["held_out"]]} for name, r in results.items()}}
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(record, indent=1))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

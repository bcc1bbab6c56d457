"""Learned Hamiltonians by regime: observation spacing, noise, and positions only — where training
through a solver pays against an HNN.

For each system, trajectories observed at spacings Δt ∈ {0.1, 0.5, 1} (in units of the fastest
period / 2π, 1/ω_max), 31 observations each, with Gaussian noise of σ ∈ {0, 1 %, 5 %} of each
component's rms over the data, on every component or on the positions only. Of the observed
trajectories (four of the pendulum, seven of the chain, five of the two bodies on bound orbits of
eccentricity up to about 0.35, five of the three bodies near Chenciner and Montgomery's figure
eight, five of the double pendulum released from rest) the last is held out whole where every
component is observed (``held_out_trajectories=1``): the held-out loss and the span check then see
states not trained on. The same separable network H_θ = T_θ(p) + V_θ(q) (two MLPs, softplus, the
same initial weights) and the same Adam steps and rate for every method:

* ``HNN`` — ``learn_hamiltonian(..., HNN())``: J∇H_θ against central differences of the data;
* ``HNN, smoothed`` — the same on the data smoothed first (a Savitzky–Golay filter of 7 points,
  cubic, each component; SciPy), the usual remedy for noisy differences;
* ``through leapfrog`` — ``ThroughSolver(solver=SplittingComposition(scheme="leapfrog", steps=4·ahead))``:
  every segment of ``ahead`` = 5 observations predicted by four leapfrog steps per interval, all
  segments in one batched scan, the loss on the predicted observations;
* ``through leapfrog, end to end`` — the same steps on segments end to end (``stride=ahead``), each
  segment's start trained with θ (``fit_starts=True``), so that each observation is predicted once
  and a start's noise is not carried along: a fifth of the segments.

The double pendulum's H is not separable (its kinetic energy depends on the angles): there the
network is one MLP of (q, p) and both ``through`` methods go through the Gauss solver instead
(``ThroughSolver``'s default, eight stages at rtol 1e-7; for the known form from positions, a
budget of 512 windows rather than 64), labelled ``through Gauss``.

From the positions alone H is fixed only up to a change of the momenta, so a network's H there has
momenta of its own; what positions do determine is a known form's parameters with the masses given:
the pendulum's g in p²/2 − g·cos q, the chain's k and β in Σ p²/2 + Σ (k s²/2 + β s⁴/4), the two
bodies' μ in |p|²/2 − μ/|q|, the three bodies' G in Σ |p|²/2 − G Σ 1/r, the double pendulum's g,
learned through leapfrog (the double pendulum: the Gauss solver) on end-to-end segments of 10
observations, each segment's starting momentum an unknown (the HNN needs every component), at
Adam's rate 0.05.
Their relative error and standard errors are recorded beside the held-out errors.

Each learned H is solved (``atlasnn.solve``, defaults) from held-out initial states over ten times
the training span, against the true H's solution: the largest state error over the output relative
to the state's range (median over the held-out states) and the median relative energy error.
Training wall time (its first step compiles) and the time per Adam step after the first (from the
progress calls) are recorded.

    python -m benchmarks.learned_h_regimes --out docs/benchmarks/learned_h_regimes.json
    python -m benchmarks.learned_h_regimes --systems pendulum --spacings 0.5 --sigmas 0.01 --steps 100  # quick
    # one system again, the record's other rows kept (or one system at some spacings, its rows at
    # the others kept):
    python -m benchmarks.learned_h_regimes --systems two-body --update --out docs/benchmarks/learned_h_regimes.json
    # more data: 31 trajectories of the chain and of the three bodies (the last held out), a record of its own
    python -m benchmarks.learned_h_regimes --systems spring-chain three-body --spacings 0.5 --sigmas 0.01 \
        --observed all --trajectories 31 --out docs/benchmarks/learned_h_more_data.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import atlasnn
from atlasnn import learn_hamiltonian
from atlasnn.inverse import HNN, ThroughSolver
from atlasnn.solver import SplittingComposition

from benchmarks.common import machine_info, write_result

jax.config.update("jax_enable_x64", True)

OBSERVATIONS, HORIZON_FACTOR, AHEAD, LEAPFROG_PER_INTERVAL = 31, 10, 5, 4
#: the solver a model that is not separable is trained through: ThroughSolver's default
GAUSS = ThroughSolver().solver
#: the same through segments of POSITION_AHEAD observations with their momenta fitted: more windows
#: (at four stages ThroughSolver's 64 were spent by the sixth step at Δt = 0.5 from the guess g = 0.6;
#: 512 took the double pendulum's g to 0.3 % of its value in 60 steps there; at eight, 64 lasted 200
#: steps at Δt = 0.5 and 1). The budget changes no window's numbers.
GAUSS_POSITIONS = dataclasses.replace(GAUSS, max_windows=512)
#: positions only: segments of this many observations end to end (each segment's momentum is fitted:
#: short overlapping segments would let the fitted momenta absorb the force)
POSITION_AHEAD = 10
#: Adam's rate for the known forms (a few parameters of order 1; the networks' rate would leave them short)
KNOWN_RATE = 0.05
CHAIN = 10
#: trajectories held out whole (the last observed one) where every component is observed: the span check and
#: the held-out loss see states not trained on
HELD_WHOLE = 1


def _chain(q, p):
    """Ten unit masses between fixed walls, linear springs of unit stiffness, a quartic part (FPUT-β)."""
    return _chain_form(q, p)


def _chain_starts(seed: int, count: int) -> list:
    rng = np.random.default_rng(seed)
    return [np.concatenate([0.4 * rng.standard_normal(CHAIN), 0.4 * rng.standard_normal(CHAIN)]) for _ in range(count)]


def _three_body(q, p, G=1.0):
    """Three unit masses in the plane, gravitation (G = 1): q = (x₁, y₁, x₂, y₂, x₃, y₃)."""
    r = q.reshape(3, 2)
    pairs = [(0, 1), (0, 2), (1, 2)]
    return jnp.sum(p ** 2) / 2 - G * sum(1.0 / jnp.sqrt(jnp.sum((r[i] - r[j]) ** 2)) for i, j in pairs)


#: Chenciner and Montgomery's figure eight (period 6.3259), the orbit every three-body start is near
_EIGHT = np.array([0.97000436, -0.24308753, -0.97000436, 0.24308753, 0.0, 0.0,
                   0.466203685, 0.43236573, 0.466203685, 0.43236573, -0.93240737, -0.86473146])
EIGHT_PERIOD = 6.3259


def _eight_starts(seed: int, count: int) -> list:
    """Starts near the figure eight: each coordinate moved by 0.5 % of its size (at 2 % an orbit
    reached a collision within ten spans), the total momentum kept zero."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        z = _EIGHT * (1.0 + 0.005 * rng.standard_normal(12))
        z[6:] -= np.tile(z[6:].reshape(3, 2).mean(axis=0), 3)
        out.append(z)
    return out


def _two_body(q, p, mu=1.0):
    """Two bodies in the plane in their relative coordinate (the centre of mass at rest), reduced
    mass 1: H = |p|²/2 − μ/|q|, μ = G(m₁ + m₂) = 1."""
    return jnp.sum(p ** 2) / 2 - mu / jnp.sqrt(jnp.sum(q ** 2))


def _kepler_starts(seed: int, count: int) -> list:
    """Bound orbits through r = 1 at a random angle, the speed 0.85–1.15 of the circular one and a
    small radial part: eccentricities up to about 0.35."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        phi, speed, radial = rng.uniform(0, 2 * np.pi), rng.uniform(0.85, 1.15), rng.uniform(-0.1, 0.1)
        r = np.array([np.cos(phi), np.sin(phi)])
        out.append(np.concatenate([r, speed * np.array([-r[1], r[0]]) + radial * r]))
    return out


def _double_pendulum(q, p, g=1.0):
    """Two unit masses on unit rods (angles q from the vertical): not separable, the kinetic
    energy depends on q₁ − q₂."""
    d = q[0] - q[1]
    return ((p[0] ** 2 + 2 * p[1] ** 2 - 2 * p[0] * p[1] * jnp.cos(d)) / (2 * (1 + jnp.sin(d) ** 2))
            - g * (2 * jnp.cos(q[0]) + jnp.cos(q[1])))


def _swing_starts(seed: int, count: int) -> list:
    """Both rods released from rest at angles of 0.2–0.6 rad, either sign."""
    rng = np.random.default_rng(seed)
    return [np.concatenate([rng.choice([-1.0, 1.0], 2) * rng.uniform(0.2, 0.6, 2), np.zeros(2)]) for _ in range(count)]


def _pendulum(q, p, g=1.0):
    return p[0] ** 2 / 2 - g * jnp.cos(q[0])


def _chain_form(q, p, k=1.0, beta=1.0):
    stretch = jnp.diff(jnp.concatenate([jnp.zeros(1), q, jnp.zeros(1)]))
    return jnp.sum(p ** 2) / 2 + k * jnp.sum(stretch ** 2) / 2 + beta * jnp.sum(stretch ** 4) / 4


#: name -> (true H, degrees of freedom, ω_max (the fastest linear frequency), observed starts (the last one's
#: trajectory held out whole where every component is observed), held-out starts of the final solves)
SYSTEMS = {
    "pendulum": (_pendulum, 1, 1.0,
                 [[1.0, 0.0], [0.0, 1.2], [-0.5, -0.6], [0.4, 0.8]], [[0.7, -0.4], [-1.2, 0.3], [0.2, 0.9]]),
    "spring-chain": (_chain, CHAIN, 2 * np.sin(np.pi * CHAIN / (2 * (CHAIN + 1))),
                     _chain_starts(1, 7), _chain_starts(2, 3)),
    # ω_max: the circular orbit's frequency at r = 1
    "two-body": (_two_body, 2, 1.0, _kepler_starts(1, 5), _kepler_starts(2, 3)),
    # ω_max: the figure eight's own frequency, 2π over its period
    "three-body": (_three_body, 6, 2 * np.pi / EIGHT_PERIOD, _eight_starts(1, 5), _eight_starts(2, 3)),
    # ω_max: the faster normal mode's, √(2 + √2)
    "double-pendulum": (_double_pendulum, 2, np.sqrt(2 + np.sqrt(2)), _swing_starts(1, 5), _swing_starts(2, 3)),
}
#: name -> the maker of its observed starts (seed 1, as SYSTEMS'), for ``--trajectories``: the first
#: of them are SYSTEMS' own (the pendulum's four are chosen by hand: none)
MORE_STARTS = {"spring-chain": _chain_starts, "two-body": _kepler_starts, "three-body": _eight_starts,
               "double-pendulum": _swing_starts}
#: systems whose H is not T(p) + V(q): a network of (q, p) trained through the Gauss solver, not leapfrog
NOT_SEPARABLE = ("double-pendulum",)

#: name -> (the true H's form with its parameters as arguments, their true values): the pendulum's g,
#: the chain's k and β, the two bodies' μ, the three bodies' G, the double pendulum's g
FORMS = {"pendulum": (_pendulum, [1.0]), "spring-chain": (_chain_form, [1.0, 1.0]),
         "two-body": (_two_body, [1.0]), "three-body": (_three_body, [1.0]),
         "double-pendulum": (_double_pendulum, [1.0])}


class KnownForm(eqx.Module):
    """The true H's form (``FORMS``) with its parameters unknown."""

    name: str = eqx.field(static=True)
    theta: jax.Array

    def __call__(self, q, p):
        return FORMS[self.name][0](q, p, *self.theta)


#: the guess every known form's training starts from (each parameter)
GUESS = 0.6


class SeparableH(eqx.Module):
    """H_θ(q, p) = T_θ(p) + V_θ(q), two MLPs."""

    kinetic: eqx.nn.MLP
    potential: eqx.nn.MLP

    def __call__(self, q, p):
        return self.kinetic(p)[0] + self.potential(q)[0]


class NetworkH(eqx.Module):
    """H_θ(q, p), one MLP of the whole state (for systems that are not separable)."""

    mlp: eqx.nn.MLP

    def __call__(self, q, p):
        return self.mlp(jnp.concatenate([q, p]))[0]


def network(dof: int, seed: int, separable: bool = True) -> SeparableH | NetworkH:
    width = 32 if dof == 1 else 64
    k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
    if separable:
        net = SeparableH(eqx.nn.MLP(dof, 1, width, 2, activation=jax.nn.softplus, key=k1),
                         eqx.nn.MLP(dof, 1, width, 2, activation=jax.nn.softplus, key=k2))
    else:
        net = NetworkH(eqx.nn.MLP(2 * dof, 1, width, 2, activation=jax.nn.softplus, key=k1))
    return jax.tree_util.tree_map(lambda x: x.astype(jnp.float64) if eqx.is_inexact_array(x) else x, net)


def observations(name: str, spacing: float, sigma: float, seed: int, count: int | None = None) -> tuple[list, float]:
    """Noisy trajectories (times, states) and the noise's absolute size (σ × the data's rms); from
    ``count`` starts (``MORE_STARTS``) where given, else the system's own."""
    H, dof, omega, starts, _ = SYSTEMS[name]
    starts = starts if count is None else MORE_STARTS[name](1, count)
    truth = atlasnn.HamiltonianSystem(H, dof, name=name)
    dt = spacing / omega
    times = dt * np.arange(OBSERVATIONS)
    clean = [atlasnn.solve(truth, z, (0.0, times[-1]))(times) for z in starts]
    rms = np.sqrt(np.mean(np.concatenate(clean) ** 2, axis=0))
    rng = np.random.default_rng(seed)
    noisy = [(times, z + sigma * rms * rng.standard_normal(z.shape)) for z in clean]
    return noisy, float(sigma * np.sqrt(np.mean(rms ** 2)))


def smoothed(trajectories: list) -> list:
    from scipy.signal import savgol_filter

    return [(t, savgol_filter(z, 7, 3, axis=0, mode="interp")) for t, z in trajectories]


def positions_only(trajectories: list, dof: int) -> list:
    return [(t, np.concatenate([z[:, :dof], np.full((t.size, dof), np.nan)], axis=1)) for t, z in trajectories]


def held_out(name: str, model, span: float, expected: float | None = None) -> dict:
    """The learned H solved from the held-out starts over ten spans against the truth; with
    ``expected`` (the result's expected_error over that horizon times the data's size, an absolute
    figure), the same on the state error's scale, per state."""
    H, dof, _, _, starts = SYSTEMS[name]
    truth = atlasnn.HamiltonianSystem(H, dof, name=name)
    learned = atlasnn.HamiltonianSystem(model, dof, name="learned", separable=name not in NOT_SEPARABLE)
    horizon = HORIZON_FACTOR * span
    t = np.linspace(0.0, horizon, 601)
    states, energies, failures, guides = [], [], [], []
    for z in np.asarray(starts, np.float64):
        ref = atlasnn.solve(truth, z, (0.0, horizon))(t)
        try:
            got = atlasnn.solve(learned, z, (0.0, horizon))(t)
        except atlasnn.AtlasError as exc:  # a learned H whose orbit leaves the data's region
            failures.append(str(exc)[:160])
            states.append(np.inf)
            energies.append(np.inf)
            continue
        e0, along = float(truth.energy64(z)), truth.energy64(got)
        states.append(float(np.abs(got - ref).max() / np.ptp(ref, axis=0).max()))
        guides.append(None if expected is None else expected / float(np.ptp(ref, axis=0).max()))
        energies.append(float(np.median(np.abs(along - e0)) / abs(e0)))
    return {"state_error": statistics.median(states), "energy_error": statistics.median(energies),
            "per_state": states, "failures": failures,
            "expected_state_error": None if expected is None or not guides else statistics.median(guides)}


def _expected(result, data: list, span: float) -> float | None:
    """The result's expected_error after ten spans as an absolute figure (times the data's rms)."""
    guide = result.expected_error(HORIZON_FACTOR * span)
    if guide is None:
        return None
    return guide * float(np.sqrt(np.nanmean(np.concatenate([z for _, z in data]) ** 2)))


def methods(steps: int, rate: float, observed: str, separable: bool = True) -> dict:
    """The methods by label; through leapfrog for a separable system, through the Gauss solver
    (``ThroughSolver``'s own, eight stages at rtol 1e-7) for another."""
    def solver(ahead: int):
        if separable:
            return SplittingComposition(scheme="leapfrog", steps=LEAPFROG_PER_INTERVAL * ahead)
        return GAUSS_POSITIONS if observed == "positions" else GAUSS

    through = "through leapfrog" if separable else "through Gauss"
    if observed == "positions":  # end-to-end segments of POSITION_AHEAD: one fitted momentum per segment
        return {through: ThroughSolver(steps=steps, rate=KNOWN_RATE, ahead=POSITION_AHEAD, stride=POSITION_AHEAD,
                                       solver=solver(POSITION_AHEAD))}
    return {"HNN": HNN(steps=steps, rate=rate), "HNN, smoothed": HNN(steps=steps, rate=rate),
            through: ThroughSolver(steps=steps, rate=rate, ahead=AHEAD, solver=solver(AHEAD)),
            f"{through}, end to end": ThroughSolver(steps=steps, rate=rate, ahead=AHEAD, stride=AHEAD,
                                                    fit_starts=True, solver=solver(AHEAD))}


def run(name: str, spacing: float, sigma: float, observed: str, steps: int, rate: float, seed: int,
        count: int | None = None) -> list[dict]:
    dof = SYSTEMS[name][1]
    data, noise = observations(name, spacing, sigma, seed, count)
    span = float(data[0][0][-1])
    rows = []
    separable = name not in NOT_SEPARABLE
    for label, method in methods(steps, rate, observed, separable).items():
        given = smoothed(data) if label == "HNN, smoothed" else data
        if observed == "positions":
            given = positions_only(given, dof)
            model = KnownForm(name, jnp.full(len(FORMS[name][1]), GUESS))
        else:
            model = network(dof, seed, separable)
        marks = []  # (step, wall time) at each progress call: the time per step once compiled
        result = learn_hamiltonian(model, given, method, noise=None if label == "HNN, smoothed" else noise,
                                   held_out_trajectories=HELD_WHOLE if observed == "all" else 0,
                                   progress=lambda k, _loss: marks.append((k, time.perf_counter())))
        # the time per step after the first (which compiles); none where training stopped within two calls
        per_step = (marks[-1][1] - marks[1][1]) / (marks[-1][0] - marks[1][0]) if len(marks) > 2 else None
        extra = {}
        if observed == "positions":
            truth = np.asarray(FORMS[name][1])
            extra = {"parameters": np.asarray(result.model.theta).tolist(),
                     "std": None if result.std is None else np.asarray(result.std).tolist(),
                     "parameter_error": float(np.max(np.abs(np.asarray(result.model.theta) / truth - 1)))}
        row = {"system": name, "spacing": spacing, "sigma": sigma, "observed": observed, "method": label,
               "trajectories": len(data), "loss": result.loss, "noise_loss": result.noise_loss,
               "train_seconds": result.seconds, "seconds_per_step": per_step,
               "stopped": result.stopped,
               "trusted": result.trusted, "notes": list(result.notes), **extra,
               "drift": None if result.drift is None else dataclasses.asdict(result.drift),
               **held_out(name, result.model, span, _expected(result, given, span))}
        print(f"{name:15s} Δt {spacing:<4g} σ {sigma:<5g} {observed:9s} {label:29s} {result.seconds:6.1f} s "
              f"({1e3 * (per_step or math.nan):.2f} ms/step)  held-out state {row['state_error']:.2e}, energy "
              f"{row['energy_error']:.2e} (expected {row['expected_state_error'] or float('nan'):.2e}), "
              f"trusted {result.trusted}"
              + (f", parameters off by {extra['parameter_error']:.1e}" if extra else "")
              + (f"; stopped: {result.stopped}" if result.stopped else ""), flush=True)
        rows.append(row)
    return rows


def _cells(label: str, rows: list[dict]) -> set:
    """The (system, spacing) pairs a run's label names: "X at Δt a and b", or "X" (every spacing of
    X in ``rows``)."""
    name, _, at = label.partition(" at Δt ")
    spacings = {float(s) for s in at.split(" and ")} if at else {r["spacing"] for r in rows if r["system"] == name}
    return {(name, s) for s in spacings}


def earlier_runs(kept: dict, rerun: list, rows: list[dict]) -> list[dict]:
    """The runs that made the rows of the new record (``rows``) other than ``rerun``'s (labels: a
    system, or a system at some spacings): each with its labels, command and machine (a record
    updated before names its own earlier runs), newest first; a label whose rows later runs have
    all replaced is dropped, and a run left with none."""
    updated = kept.get("updated") or {}
    mine = updated.get("problems") or sorted({r["system"] for r in kept["rows"]})
    runs = [{"problems": mine, "command": kept["command"], "machine": kept.get("machine")}]
    if "earlier" in updated:  # the one-run form: the earlier run made every row but the rerun's
        others = sorted({r["system"] for r in kept["rows"]} - set(mine), key=list(SYSTEMS).index)
        runs.append({"problems": others, "command": updated["earlier"], "machine": updated.get("earlier_machine")})
    runs += updated.get("earlier_runs", [])
    covered = set().union(*(_cells(label, rows) for label in rerun))
    left = []
    for run in runs:  # newest first: what a run made is covered for every older one
        cells = {label: _cells(label, rows) for label in run["problems"]}
        problems = [label for label, made in cells.items() if made - covered]
        covered |= set().union(*cells.values())
        if problems:
            left.append({**run, "problems": problems})
    return left


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--systems", nargs="+", default=list(SYSTEMS), choices=list(SYSTEMS))
    ap.add_argument("--spacings", nargs="+", type=float, default=[0.1, 0.5, 1.0])
    ap.add_argument("--sigmas", nargs="+", type=float, default=[0.0, 0.01, 0.05])
    ap.add_argument("--observed", nargs="+", default=["all", "positions"], choices=["all", "positions"])
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--rate", type=float, default=3e-3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--trajectories", type=int,
                    help="observed trajectories a system, the last held out whole (default: each system's own)")
    ap.add_argument("--out")
    ap.add_argument("--update", action="store_true", help="rerun only --systems, keeping the record's other rows")
    args = ap.parse_args(argv)
    if args.trajectories is not None and args.trajectories < 2:
        ap.error(f"--trajectories needs at least 2 (the last is held out), got {args.trajectories}")
    if args.trajectories is not None and (fixed := [name for name in args.systems if name not in MORE_STARTS]):
        ap.error(f"--trajectories: the starts of {', '.join(fixed)} are fixed; leave it out for them")
    started = time.perf_counter()
    # each training's row is also appended to OUT.partial.jsonl as it ends: a run that dies late (a
    # process of 45 Gauss trainings once ran out of memory for XLA's code at its 44th) keeps its rows
    partial = Path(f"{args.out}.partial.jsonl") if args.out else None
    rows = []
    for name in args.systems:
        for spacing in args.spacings:
            for sigma in args.sigmas:
                for observed in args.observed:
                    done = run(name, spacing, sigma, observed, args.steps, args.rate, args.seed, args.trajectories)
                    rows += done
                    if partial is not None:
                        with partial.open("a", encoding="utf-8") as f:
                            f.writelines(json.dumps(row) + "\n" for row in done)
    command = "python -m benchmarks.learned_h_regimes " + " ".join(
        f"--{k} {' '.join(map(str, v)) if isinstance(v, list) else v}" if not isinstance(v, bool) else f"--{k}"
        for k, v in vars(args).items() if v is not None and v is not False)
    print(f"{len(rows)} trainings in {time.perf_counter() - started:.0f} s")
    extra = {}
    if args.update and args.out and Path(args.out).is_file():  # the other rows as their own runs made them
        kept = json.loads(Path(args.out).read_text(encoding="utf-8"))
        rerun = {(name, spacing) for name in args.systems for spacing in args.spacings}
        whole = set(args.spacings) >= {r["spacing"] for r in kept["rows"] if r["system"] in args.systems}
        labels = args.systems if whole else [f"{name} at Δt {' and '.join(f'{s:g}' for s in args.spacings)}"
                                              for name in args.systems]
        rows = sorted([r for r in kept["rows"] if (r["system"], r["spacing"]) not in rerun] + rows,
                      key=lambda r: (list(SYSTEMS).index(r["system"]), r["spacing"]))  # stable: as each run made them
        extra["updated"] = {"problems": labels, "earlier_runs": earlier_runs(kept, labels, rows)}
    if args.out:
        write_result(args.out, {"command": command, "machine": machine_info(), **extra, "observations": OBSERVATIONS,
                                "horizon_factor": HORIZON_FACTOR, "ahead": AHEAD, "held_whole": HELD_WHOLE,
                                "leapfrog_per_interval": LEAPFROG_PER_INTERVAL, "position_ahead": POSITION_AHEAD,
                                "known_rate": KNOWN_RATE,
                                "gauss": {"stages": GAUSS.stages, "rtol": GAUSS.rtol, "max_windows": GAUSS.max_windows,
                                          "positions_max_windows": GAUSS_POSITIONS.max_windows},
                                "steps": args.steps,
                                "rate": args.rate, "network": "T_θ(p) + V_θ(q), two MLPs d → w → w → 1, softplus "
                                "(w = 32 for one degree of freedom, 64 for more); where H is not separable (the "
                                "double pendulum) one MLP 2d → 64 → 64 → 1 of (q, p)", "rows": rows})
        partial.unlink(missing_ok=True)  # its rows are in the record now


if __name__ == "__main__":
    main()

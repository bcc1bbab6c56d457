"""Trust rules of a learned Hamiltonian that look at the data and at H_θ's flow rather than at the
training loss: an H_θ whose flow misses the observations one interval ahead (an HNN's central
differences too coarse for the spacing, which its own loss cannot see), and data whose noise is
too large a part of them to pin H down. Each returns the reasons found, each a line saying what
to do.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.inverse._learn_data import Trajectory
from atlasnn.solver import GaussCollocation, solve
from atlasnn.systems import HamiltonianSystem

__all__ = ["flow_miss", "flow_reasons", "modified_reasons", "noise_reasons", "observed_size", "span_drift",
           "span_drifts", "drift_reasons", "SpanDrift", "FLOW_ACCURACY",
           "FLOW_AHEAD", "PROPAGATION", "NOISE_FACTOR", "NOISY_DATA", "NOISY_RATES"]

#: a loss this many times the noise's own (`noise_loss`: 2σ² for states predicted from an observed start) is
#: "far above the noise"
NOISE_FACTOR = 3.0
#: H_θ's flow may miss the observations it is checked against by this part of their rms size
#: (beyond the noise): about a 1 % error in a frequency over a few intervals
FLOW_ACCURACY = 1e-2
#: how many observations ahead the learned H's flow is checked against (a flow that is right over one
#: spacing may drift off over a few: an HNN's H whose frequency is a few per cent off)
FLOW_AHEAD = 5
#: how much more than σ² per component the flow may carry of a start's noise (a flow that is not an
#: isometry: a spring of ω = √2 carries up to 1.25σ² per component)
PROPAGATION = 0.5
#: noise of this part of the observed values' spread (rms about their mean) or more: the data
#: cannot pin H down
NOISY_DATA = 0.2
#: central differences whose noise is this part of the rates' rms or more: the HNN regresses on noise
NOISY_RATES = 0.3
#: the flow checks solve this many starts in one call
FLOW_BATCH = 128
#: Gauss–Newton iterations fitting a trajectory's start to the learned flow (from the observed start)
SPAN_ITERATIONS = 2
#: the solves of the flow and span checks: accurate well below any noise or FLOW_ACCURACY, so that
#: what they measure is H_θ's, not the solver's
_CHECK_SOLVER = GaussCollocation(rtol=1e-9, atol=1e-11, max_windows=512)
#: the flow check reads its orbits at as many times as the span check (the longest trajectory's
#: observations), so that both run one compiled solve, where that is at most this many
SHARED_COLUMNS = 256



def observed_size(trajectories: list[Trajectory]) -> float:
    """The observed values' rms."""
    return float(np.sqrt(np.nanmean(np.concatenate([traj.z for traj in trajectories]) ** 2)))


def observed_spread(trajectories: list[Trajectory]) -> float:
    """The observed values' rms about each component's mean."""
    z = np.concatenate([traj.z for traj in trajectories])
    seen = ~np.all(np.isnan(z), axis=0)  # a component never observed (positions only) has no mean
    z = z[:, seen]
    return float(np.sqrt(np.nanmean((z - np.nanmean(z, axis=0)) ** 2)))


def noise_reasons(trajectories: list[Trajectory], noise: float | None, hnn: bool) -> list[str]:
    """Data too noisy to trust what was learned from them: σ a large part of the values' spread
    (any method), or of the central differences' rates (an HNN: its regression then fits noise, and
    the noise in the states it regresses on biases it towards a weaker H)."""
    if not noise:
        return []
    reasons, spread = [], observed_spread(trajectories)
    if noise >= NOISY_DATA * spread:
        reasons.append(f"the noise σ = {noise:.3g} is {noise / spread:.0%} of the observed values' spread ({spread:.3g}): "
                       "data this noisy do not pin H down (its parameters can be tens of per cent off); more or "
                       "longer trajectories")
    if hnn:
        gaps = np.concatenate([traj.t[2:] - traj.t[:-2] for traj in trajectories])
        rates = np.concatenate([(traj.z[2:] - traj.z[:-2]) / (traj.t[2:] - traj.t[:-2])[:, None]
                                for traj in trajectories])
        noisy, size = float(np.sqrt(np.mean(2 * noise ** 2 / gaps ** 2))), float(np.sqrt(np.mean(rates ** 2)))
        if noisy >= NOISY_RATES * size:
            reasons.append(f"the central differences carry noise of rms {noisy:.3g} against rates of rms {size:.3g}: "
                           "the HNN regresses on noise (and on noisy states, which biases H); learn through the "
                           "solver (ThroughSolver())")
    return reasons


@eqx.filter_jit
def _orbit_batch(model: Any, dof: int, solver: GaussCollocation, starts: jax.Array, times: jax.Array) -> jax.Array:
    """Each start's orbit from its first time, read at its times (the solver a static argument)."""
    system = HamiltonianSystem(model, dof, name="learned")
    return jax.vmap(lambda z, ts: solve(system, z, (ts[0], ts[-1]), solver=solver)(ts))(starts, times)


def predict_orbits(model: Any, dof: int, starts: np.ndarray, times: np.ndarray) -> np.ndarray:
    """H_θ's orbits from ``starts`` (N, 2d) at ``times[:, 0]`` read at ``times`` (N, M), solved
    accurately, (N, M, 2d)."""
    return _in_batches(model, dof, _CHECK_SOLVER, starts, times)


def _padded(times: np.ndarray, values: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """Times (N, M) and values (N, M, 2d) widened to ``columns`` by repeating the last time, the
    values there not observed (NaN)."""
    extra = columns - times.shape[1]
    return (np.concatenate([times, np.repeat(times[:, -1:], extra, axis=1)], axis=1),
            np.concatenate([values, np.full((values.shape[0], extra, values.shape[2]), np.nan)], axis=1))


def _ahead(trajectories: list[Trajectory]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every state observed whole, with the next FLOW_AHEAD observations of its trajectory: (starts
    (N, 2d), times (N, C), targets (N, C, 2d)), a target NaN where no whole state was observed (and
    at the start, and past the trajectory's end); C the span check's columns where at most
    SHARED_COLUMNS, else FLOW_AHEAD + 1."""
    longest = max(traj.t.size for traj in trajectories)
    columns = longest if FLOW_AHEAD + 1 <= longest <= SHARED_COLUMNS else FLOW_AHEAD + 1
    steps = np.arange(FLOW_AHEAD + 1)
    starts, times, targets = [], [], []
    for traj in trajectories:
        last = traj.t.size - 1
        whole = ~np.any(np.isnan(traj.z), axis=1)
        first = np.nonzero(whole[:-1])[0]
        index = np.minimum(first[:, None] + steps, last)
        seen = whole[index] & (steps > 0) & (first[:, None] + steps <= last)
        keep = seen.any(axis=1)
        starts.append(traj.z[first[keep]]), times.append(traj.t[index[keep]])
        targets.append(np.where(seen[keep][..., None], traj.z[index[keep]], np.nan))
    starts, times, targets = (np.concatenate(x) for x in (starts, times, targets))
    return (starts,) + _padded(times, targets, columns)


def _in_batches(model: Any, dof: int, solver: GaussCollocation, starts: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The orbits on FLOW_BATCH rows at a time, the last batch padded by repeating the first row:
    one compiled program per solver for every check of a model of this shape (the model is its
    argument, not its constant)."""
    size = starts.shape[0]
    pad = (-size) % FLOW_BATCH
    starts, times = (np.concatenate([x, np.repeat(x[:1], pad, axis=0)]) for x in (starts, times))
    with jax.enable_x64(True):
        out = [np.asarray(_orbit_batch(model, dof, solver, jnp.asarray(starts[k:k + FLOW_BATCH]),
                                       jnp.asarray(times[k:k + FLOW_BATCH])))
               for k in range(0, size + pad, FLOW_BATCH)]
    return np.concatenate(out)[:size]


def flow_miss(model: Any, dof: int, trajectories: list[Trajectory], noise: float | None) -> str | None:
    """H_θ's flow, solved accurately, from every observed state to each of the next FLOW_AHEAD
    observations, against them (a wrong frequency's miss grows along the way): None where what it
    adds to the noise's own share (σ where given) is within the scatter of that share and
    FLOW_ACCURACY of the values' size; otherwise what it misses by, in words."""
    starts, times, targets = _ahead(trajectories)
    if not starts.size:
        return None
    try:  # one orbit from each start, read at the next observations
        predicted = predict_orbits(model, dof, starts, times)
    except Exception as exc:  # noqa: BLE001 (a learned H that cannot be solved is a reason itself)
        return f"could not be solved from the observed states ({type(exc).__name__})"
    seen = ~np.isnan(targets)
    squares = (predicted[seen] - targets[seen]) ** 2
    miss = float(np.sqrt(np.mean(squares)))
    # a flow from a noisy state to a noisy one misses by about √2·σ rms (the start's noise carried by
    # the flow, up to PROPAGATION·σ² more, and the end's): what is beyond that, by more than the mean's
    # own scatter (NOISE_FACTOR standard errors) and FLOW_ACCURACY of the data's size, is H_θ's
    sigma2 = (noise or 0.0) ** 2
    excess = float(np.mean(squares)) - 2.0 * sigma2
    allowed = ((2.0 * NOISE_FACTOR * np.sqrt(2.0 / squares.size) + PROPAGATION) * sigma2
               + (FLOW_ACCURACY * observed_size(trajectories)) ** 2)
    if np.isfinite(miss) and excess <= allowed:
        return None
    said = ("no noise (none was given)" if noise is None else "exact data (noise=0)" if not noise
            else f"noise of σ = {noise:g}")
    spacing = float(np.median(np.concatenate([traj.t[1:] - traj.t[:-1] for traj in trajectories])))
    return (f"misses the next {FLOW_AHEAD} observations (Δt = {spacing:.3g}) by rms {miss:.3g}, more than {said} "
            f"and {FLOW_ACCURACY:.0%} of the data's size explain ({np.sqrt(2.0 * sigma2 + allowed):.3g})")


def flow_reasons(model: Any, dof: int, trajectories: list[Trajectory], noise: float | None) -> list[str]:
    """An HNN's learned H judged by its flow (``flow_miss``): a miss says that the central
    differences were too coarse for the spacing (their error is fitted as if it were the rate)."""
    miss = flow_miss(model, dof, trajectories, noise)
    if miss is None:
        return []
    return [f"H_θ's flow {miss}: central differences are too coarse for this spacing (or the data noisier than "
            "said); learn through the solver (ThroughSolver()), or give noise=σ if the data are noisy"]


def modified_reasons(model: Any, dof: int, trajectories: list[Trajectory], noise: float | None,
                     scheme: str, steps: int) -> list[str]:
    """H_θ trained through a splitting at a fixed step reproduces the data through that scheme and
    step: it may be the scheme's modified Hamiltonian rather than the true one. Judged by its flow
    solved accurately (``flow_miss``)."""
    miss = flow_miss(model, dof, trajectories, noise)
    if miss is None:
        return []
    return [f"H_θ is the modified Hamiltonian of {scheme} at its step ({steps} steps a segment): solved accurately, "
            f"its flow {miss}; to learn the true H, train with more steps (SplittingComposition(steps=…)) until "
            "the result no longer changes — or predict with the same scheme and step"]


@dataclass(frozen=True)
class SpanDrift:
    """How far H_θ's flow drifts from the data over their whole span: from a start fitted to each
    trajectory (Gauss–Newton from the observed one), the rms miss beyond the noise, relative to
    the observed values' size (``drift``); ``floor``, the least drift the noise lets the check see
    (one standard error of the noise's mean square); trajectories of ``span`` time units."""

    drift: float
    floor: float
    span: float

    def expected_error(self, horizon: float) -> float:
        """The miss to expect ``horizon`` time units from an exact start, relative to the data's
        size: a phase error grows in proportion to time, and a miss growing linearly to m at T,
        less its mean (the fitted start), has rms m/(2√3): so 2√3·max(drift, floor)·horizon/T
        (horizon at least T), at most 2√2 (a sine's whole range over its rms: anywhere on the orbit).
        Where the drift is within the noise (below ``floor``), the floor grown: as large as the data
        allow, likely far above the error a model of few parameters makes."""
        seen = max(self.drift, self.floor)
        return float(min(2.0 * np.sqrt(2.0), 2.0 * np.sqrt(3.0) * seen * max(horizon, self.span) / self.span))

    def note(self) -> str:
        """What the check says of predictions beyond the data's span, in words."""
        later = self.expected_error(10 * self.span)
        if self.drift >= self.floor:
            return (f"checked over the observations' span ({self.span:.3g}); beyond it a prediction is an "
                    f"extrapolation: about {later:.0%} of the data's size after ten such spans (expected_error(t))")
        return (f"checked over the observations' span ({self.span:.3g}): its drift there is within the noise, which "
                f"cannot rule out a drift growing to {later:.0%} of the data's size after ten such spans "
                "(expected_error(t): a figure the data allow, not one they show)")


def span_drift(model: Any, dof: int, trajectories: list[Trajectory], noise: float | None) -> SpanDrift | None:
    """H_θ's flow against every trajectory observed whole at its start, over all its observations,
    from the starts that fit them best (Gauss–Newton from the observed ones, the Jacobian by
    differences: a start's noise carried over a long span would otherwise read as H_θ's drift);
    None where no trajectory starts whole or a solve fails."""
    return span_drifts(model, dof, [trajectories], noise)[0]


def span_drifts(model: Any, dof: int, groups: list[list[Trajectory]],
                noise: float | None) -> list[SpanDrift | None]:
    """:func:`span_drift` of each group of trajectories, all fitted in the same batched solves."""
    width = 2 * dof
    whole = [(g, traj) for g, group in enumerate(groups) for traj in group
             if not np.any(np.isnan(traj.z[0])) and traj.t.size > width + 1]
    if not whole:
        return [None] * len(groups)
    # every trajectory's times and targets padded to the longest of all (the flow check's columns too)
    # by repeating its last time, not observed
    longest = max(traj.t.size for group in groups for traj in group)
    padded = [_padded(traj.t[None], traj.z[None], longest) for _, traj in whole]
    times, target = (np.concatenate(x) for x in zip(*padded))
    target[:, 0] = np.nan  # the start is fitted, not a target
    seen = ~np.isnan(target)
    z0 = np.stack([traj.z[0] for _, traj in whole])
    best = None
    for last in [False] * SPAN_ITERATIONS + [True]:
        nudge = 1e-6 * np.maximum(1.0, np.abs(z0))  # (K, 2d)
        nudged = [] if last else [z0 + nudge * np.eye(width)[j] for j in range(width)]
        try:
            orbits = predict_orbits(model, dof, np.concatenate([z0] + nudged),
                                    np.tile(times, (len(nudged) + 1, 1))).reshape(len(nudged) + 1, *target.shape)
        except Exception:  # noqa: BLE001 (an H_θ whose flow cannot be solved from here)
            break
        if not np.all(np.isfinite(orbits)):
            break
        r = np.where(seen, orbits[0] - np.nan_to_num(target), 0.0)  # (K, M, 2d)
        best = r if best is None else np.where((np.sum(r ** 2, axis=(1, 2)) < np.sum(best ** 2, axis=(1, 2)))
                                               [:, None, None], r, best)
        if last:
            break
        jac = np.where(seen, (orbits[1:] - orbits[0]) / nudge.T[:, :, None, None], 0.0)  # (2d, K, M, 2d)
        for k in range(len(whole)):
            z0[k] = z0[k] - np.linalg.lstsq(jac[:, k].reshape(width, -1).T, r[k].ravel(), rcond=None)[0]
    owner = np.array([g for g, _ in whole])
    return [None if best is None or not np.any(owner == g) else
            _drift(best[owner == g], seen[owner == g], dof, noise, groups[g], [t for h, t in whole if h == g])
            for g in range(len(groups))]


def _drift(residual: np.ndarray, seen: np.ndarray, dof: int, noise: float | None,
           trajectories: list[Trajectory], whole: list[Trajectory]) -> SpanDrift:
    """The span check's figure from its best residuals: their mean square beyond σ², each fitted
    start taking 2d values' freedom."""
    values = max(int(seen.sum()) - 2 * dof * len(whole), 1)
    sigma2, size = (noise or 0.0) ** 2, observed_size(trajectories)
    excess = float(np.sum(residual ** 2)) / values - sigma2
    floor = float(np.sqrt(np.sqrt(2.0 / values) * sigma2)) / size
    return SpanDrift(float(np.sqrt(max(excess, 0.0))) / size, floor,
                     float(max(traj.t[-1] - traj.t[0] for traj in whole)))


def drift_reasons(drift: SpanDrift | None, noise: float | None) -> list[str]:
    """A flow that drifts off the data over their span by more than FLOW_ACCURACY of their size
    (beyond the noise): H_θ is not the data's H, whatever it does over a few observations."""
    if drift is None or drift.drift <= max(FLOW_ACCURACY, drift.floor):
        return []
    beyond = "beyond the noise" if noise is not None else "(no noise was given: the data's own noise counts here)"
    return [f"over the observations' whole span ({drift.span:.3g}), H_θ's flow from starts fitted to them misses them "
            f"by {drift.drift:.1%} of their size {beyond}: its predictions drift (about "
            f"{drift.expected_error(10 * drift.span):.0%} of the size after ten such spans); more or longer "
            "trajectories, more steps, or a model closer to the system"]

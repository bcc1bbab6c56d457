"""Trust rules of a learned Hamiltonian that look at the data and at H_θ's flow rather than at the
training loss: an H_θ whose flow misses the observations one interval ahead (an HNN's central
differences too coarse for the spacing, which its own loss cannot see), and data whose noise is
too large a part of them to pin H down. Each returns the reasons found, each a line saying what
to do.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.inverse._learn_data import Trajectory
from atlasnn.solver import GaussCollocation, solve
from atlasnn.systems import HamiltonianSystem

__all__ = ["flow_miss", "flow_reasons", "modified_reasons", "noise_reasons", "observed_size", "FLOW_ACCURACY",
           "FLOW_AHEAD", "PROPAGATION", "NOISE_FACTOR", "NOISY_DATA", "NOISY_RATES"]

#: a loss this many times the noise's own (2σ² for predicted states) is "far above the noise"
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
#: the solve of the flow check: accurate, so that what it measures is H_θ's, not the solver's
_FLOW_SOLVER = GaussCollocation(stages=8, rtol=1e-10, atol=1e-12, max_windows=512)


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


def flow_miss(model: Any, dof: int, trajectories: list[Trajectory], noise: float | None) -> str | None:
    """H_θ's flow, solved accurately, from every observed state to each of the next FLOW_AHEAD
    observations, against them (a wrong frequency's miss grows along the way): None where what it
    adds to the noise's own share (σ where given) is within the scatter of that share and
    FLOW_ACCURACY of the values' size; otherwise what it misses by, in words."""
    starts, ends, t0, t1 = [], [], [], []
    for traj in trajectories:
        whole = ~np.any(np.isnan(traj.z), axis=1)
        for k in range(1, min(FLOW_AHEAD, len(traj.t) - 1) + 1):  # to each of the next FLOW_AHEAD observations
            pair = whole[:-k] & whole[k:]
            starts.append(traj.z[:-k][pair]), ends.append(traj.z[k:][pair])
            t0.append(traj.t[:-k][pair]), t1.append(traj.t[k:][pair])
    starts, ends, t0, t1 = (np.concatenate(x) for x in (starts, ends, t0, t1))
    if not starts.size:
        return None
    system = HamiltonianSystem(model, dof, name="learned")
    with jax.enable_x64(True):
        flow = jax.jit(jax.vmap(lambda z, a, b: solve(system, z, (a, b), solver=_FLOW_SOLVER)(b)))
        try:
            predicted = np.asarray(flow(*(jnp.asarray(x) for x in (starts, t0, t1))))
        except Exception as exc:  # noqa: BLE001 (a learned H that cannot be solved is a reason itself)
            return f"could not be solved from the observed states ({type(exc).__name__})"
    squares = (predicted - ends) ** 2
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

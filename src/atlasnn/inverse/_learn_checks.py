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

__all__ = ["flow_reasons", "noise_reasons", "observed_size", "FLOW_ACCURACY", "NOISE_FACTOR", "NOISY_DATA", "NOISY_RATES"]

#: a loss this many times the noise's own (2σ² for predicted states) is "far above the noise"
NOISE_FACTOR = 3.0
#: H_θ's flow over one observation interval may miss the observations by this part of their rms
#: size (beyond the noise): about a 1 % error in a frequency over a few intervals
FLOW_ACCURACY = 1e-2
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


def flow_reasons(model: Any, dof: int, trajectories: list[Trajectory], noise: float | None) -> list[str]:
    """H_θ's flow from every observed state to the next observation against that observation: a
    miss beyond what noise of σ (none where not given) and FLOW_ACCURACY of the values' size explain
    says that the learned H's flow is not the data's — for an HNN, central differences too coarse
    for the spacing (their error is fitted as if it were the rate)."""
    starts, ends, t0, t1 = [], [], [], []
    for traj in trajectories:
        whole = ~np.any(np.isnan(traj.z), axis=1)
        pair = whole[:-1] & whole[1:]
        starts.append(traj.z[:-1][pair]), ends.append(traj.z[1:][pair])
        t0.append(traj.t[:-1][pair]), t1.append(traj.t[1:][pair])
    starts, ends, t0, t1 = (np.concatenate(x) for x in (starts, ends, t0, t1))
    if not starts.size:
        return []
    system = HamiltonianSystem(model, dof, name="learned")
    with jax.enable_x64(True):
        flow = jax.jit(jax.vmap(lambda z, a, b: solve(system, z, (a, b), solver=_FLOW_SOLVER)(b)))
        try:
            predicted = np.asarray(flow(*(jnp.asarray(x) for x in (starts, t0, t1))))
        except Exception as exc:  # noqa: BLE001 (a learned H that cannot be solved is a reason itself)
            return [f"H_θ's flow could not be solved from the observed states ({type(exc).__name__}): it is not "
                    "a usable H"]
    miss = float(np.sqrt(np.mean((predicted - ends) ** 2)))
    # a flow from a noisy state to a noisy one misses by √2·σ rms: NOISE_FACTOR times that in squares
    allowed = np.sqrt(NOISE_FACTOR * 2.0) * (noise or 0.0) + FLOW_ACCURACY * observed_size(trajectories)
    if np.isfinite(miss) and miss <= allowed:
        return []
    spacing = float(np.median(t1 - t0))
    said = f"noise of σ = {noise:g}" if noise else "no noise (none was given)"
    return [f"H_θ's flow misses the next observation by rms {miss:.3g}, more than {said} and "
            f"{FLOW_ACCURACY:.0%} of the data's size explain ({allowed:.3g}): central differences over Δt = "
            f"{spacing:.3g} are too coarse (or the data noisier than said); learn through the solver "
            "(ThroughSolver()), or give noise=σ if the data are noisy"]

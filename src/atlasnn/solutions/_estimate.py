"""An a-posteriori error estimate of a trained solution, with no reference solution.

The estimate δ(t) ≈ z(t) − ẑ(t) solves the linearised error equation (:mod:`._linearised`)
along the trained solution, forced by its residual. It needs only ẑ, dẑ/dt and H. Measured on
42 trainings of five systems (docs/ESTIMATE.md): wherever ‖δ‖ stays below 5 % of the solution's
range, max‖δ‖ / max‖e‖ was 0.87–1.05; beyond that the linearisation fails (the error is O(1):
the true error saturates at the size of the orbit while δ keeps growing with the linearised flow,
by orders of magnitude in a chaotic region), so δ is then read only as "the error is large".
:attr:`ErrorEstimate.trusted_until` is the time up to which it is quantitative.

How the solution is sampled: every window network on its own local time, both sides of every
window edge, and in float64 — the trained weights cast to float64, the same function up to
float32 rounding (≲ 1e-6), but its dẑ/dt then carries no float32 bias, which the flow can
amplify (an 8 % under-estimate on a pendulum near its separatrix when sampled in float32).
The grid: ``steps_for`` per window, raised to that window's residual bandwidth after a first
pass, then doubled until max‖δ‖ moves by less than 1 % — within a memory budget
(:func:`~._linearised.max_total_steps`, 1 GiB; 65 536 steps a window at most): a grid that would
need more stays coarser and the estimate says it did not converge.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.nn import TrialSolution
from atlasnn.solutions._evaluate import value_and_rate_chunked
from atlasnn.solutions._linearised import (
    CHUNK,
    MAX_STEPS_PER_WINDOW,
    MIN_STEPS_PER_WINDOW,
    max_total_steps,
    propagate,
    residual_and_jacobian,
    segment_bandwidths,
    steps_for,
)

__all__ = ["ErrorEstimate", "estimate_error", "TRUST_FRACTION", "state_range"]

#: δ is quantitative while ‖δ‖ ≤ this fraction of the solution's range (measured: docs/ESTIMATE.md)
TRUST_FRACTION = 0.05


def state_range(z: Any) -> float:
    """The state's range: the largest max − min over time of one component (what "relative to the
    range" means everywhere in atlasnn: an error e is reported as max_t max_i |e_i(t)| / range)."""
    z = np.asarray(z, dtype=np.float64)
    return float((z.max(0) - z.min(0)).max()) if z.size else 0.0


def _norms(delta: np.ndarray) -> np.ndarray:
    """Row norms of δ, inf without a warning where an exploding estimate overflows (a failed run)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.linalg.norm(delta, axis=1)


@dataclass(frozen=True)
class ErrorEstimate:
    """The linearised error estimate of a solution at the nodes of its grid.

    Attributes:
        t: node times, increasing (an interior window edge twice: left, then right limit).
        delta: δ at the nodes, shape (n, 2d): the estimated z − ẑ (so ẑ + δ is a corrected solution).
        z: ẑ at the nodes (float64 evaluation).
        steps: RK4 steps per window of the final grid; ``converged``: whether the last doubling
            moved max‖δ‖ by less than 1 %; ``omega_c``: the residual's bandwidth (rad/time).
    """

    t: np.ndarray
    delta: np.ndarray
    z: np.ndarray
    steps: list[int] = field(default_factory=list)
    converged: bool = True
    omega_c: float = 0.0

    @property
    def norm(self) -> np.ndarray:
        """‖δ(t)‖₂ at the nodes (inf where it overflows)."""
        return _norms(self.delta)

    @property
    def max_abs(self) -> float:
        """max over time and components of |δ_i(t)| (the estimate of the max abs error)."""
        return float(np.abs(self.delta).max()) if np.all(np.isfinite(self.delta)) else float("inf")

    @property
    def range(self) -> float:
        """The solution's range (``state_range`` of ẑ)."""
        return state_range(self.z)

    @property
    def relative_max(self) -> float:
        """max_abs / range: the estimated max error relative to the state's range."""
        scale = self.range
        return self.max_abs / scale if scale > 0 else float("inf")

    @property
    def trusted_until(self) -> float:
        """The last node time before ‖δ‖ first exceeds TRUST_FRACTION × range (the end when never)."""
        over = np.nonzero(~(self.norm <= TRUST_FRACTION * self.range))[0]
        return float(self.t[-1]) if over.size == 0 else float(self.t[max(int(over[0]) - 1, 0)])

    @property
    def trusted(self) -> bool:
        """Whether the estimate stays quantitative over the whole interval."""
        return self.trusted_until >= float(self.t[-1])

    def at(self, t: Any) -> np.ndarray:
        """δ at any times in the interval (linear between nodes; at a window edge, the right limit):
        shape t.shape + (2d,)."""
        tt = np.asarray(t, dtype=np.float64)
        flat = tt.reshape(-1)
        keep = np.concatenate([np.diff(self.t) > 0, [True]])  # of an edge's two copies, the right one
        nodes, delta = self.t[keep], self.delta[keep]
        out = np.stack([np.interp(flat, nodes, delta[:, j]) for j in range(delta.shape[1])], axis=-1)
        return out.reshape(tt.shape + (delta.shape[1],))

    def summary(self) -> dict[str, Any]:
        """What results.json records: max |δ|, relative to the range, trust, grid."""
        return {"max_abs": self.max_abs, "relative_max": self.relative_max, "range": self.range,
                "trusted_until": self.trusted_until, "trusted": self.trusted, "converged": self.converged,
                "steps": [int(s) for s in self.steps], "omega_c": self.omega_c}


def _sample(windows: list[tuple[TrialSolution, float, float, float]], steps: list[int]):
    """(t, ẑ, dẑ/dt) in float64 on the grid: per window 2·steps + 1 samples of local time."""
    out_t, out_z, out_dz = [], [], []
    for (model, start, length, offset), n in zip(windows, steps):
        s = np.linspace(0.0, length, 2 * n + 1)
        with jax.enable_x64(True):
            # cast on the host: an eager cast compiles a program per leaf shape
            m64 = jax.tree_util.tree_map(lambda x: jax.device_put(np.asarray(x, np.float64)) if eqx.is_inexact_array(x)
                                         else x, model)
            # in chunks of a fixed size: one program for windows of any length and every doubling
            z, dz = value_and_rate_chunked(m64, s + offset, jnp.float64, CHUNK)
        tk = start + s
        tk[-1] = start + length  # the edge exactly
        out_t.append(tk)
        out_z.append(z)
        out_dz.append(dz)
    return np.concatenate(out_t), np.concatenate(out_z), np.concatenate(out_dz)


def estimate_error(system: Any, windows: list[tuple[TrialSolution, float, float, float]], *,
                   z0: Any = None, steps: int | None = None, rtol: float = 1e-2,
                   max_doublings: int = 3) -> ErrorEstimate:
    """The linearised error estimate of a solution given as windows.

    Args:
        system: the Hamiltonian system.
        windows: (model, start time, length, the model's time at the window's start) per window,
            in order (a Solution is one window whose model sees absolute time; a time-marching
            window's model sees local time from 0).
        z0: the exact initial state, if known (δ(t0) = z0 − ẑ(t0): a float32 model holds z0
            rounded); default δ(t0) = 0.
        steps: RK4 steps per window (default: the grid rule, then doubling, see the module docstring).
    """
    n = [steps or steps_for(length) for _, _, length, _ in windows]
    budget = max_total_steps(int(system.state_dim))
    history, est, omega_c, converged = [], None, None, False
    for _ in range(max_doublings + 2):
        t, z, dz = _sample(windows, n)
        r, A = residual_and_jacobian(system, z, dz)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(A))):
            delta = np.full_like(z, np.inf)
            return ErrorEstimate(t[::2], delta[::2], z[::2], n, False, float("nan"))
        if omega_c is None and steps is None:
            bands = segment_bandwidths(t, r)  # per window: a fast window must not refine a slow one
            omega_c = max(bands, default=0.0)
            needed = _within(budget, [max(k, steps_for(length, w)) for k, (_, _, length, _), w in zip(n, windows, bands)])
            if needed != n:  # the first guess was too coarse for this residual
                n = needed
                continue
        cut = np.nonzero(np.diff(t) == 0)[0]
        y0 = None if z0 is None else np.asarray(z0, dtype=np.float64).reshape(-1) - z[0]
        tn, delta, idx = propagate(t, A, r, jumps=z[cut + 1] - z[cut], y0=y0)
        new = ErrorEstimate(tn, delta, z[idx], list(n), False, float(omega_c or 0.0))
        peak = float(_norms(delta).max())
        if history and abs(peak - history[-1]) <= rtol * max(peak, 1e-300):
            return ErrorEstimate(tn, delta, z[idx], list(n), True, float(omega_c or 0.0))
        history.append(peak)
        est = new
        if steps is not None or len(history) > max_doublings or 2 * sum(n) > budget:
            break  # (past the memory budget the grid stays as it is: not converged)
        n = [min(2 * k, MAX_STEPS_PER_WINDOW) for k in n]
    return ErrorEstimate(est.t, est.delta, est.z, est.steps, converged, est.omega_c)


def _within(budget: int, steps: list[int]) -> list[int]:
    """``steps`` scaled down to at most ``budget`` in all (never below the grid rule's minimum)."""
    total = sum(steps)
    if total <= budget:
        return steps
    return [max(MIN_STEPS_PER_WINDOW, int(k * budget / total)) for k in steps]

"""The words for a Gauss march that stopped: whether the field is what stopped it, whether its
windows collapsed (a kink in H, a time scale falling to 0), and times written with as many digits
as tell them apart (used by :mod:`._gauss`)."""

from __future__ import annotations

import jax
import numpy as np

from atlasnn.systems import HamiltonianSystem

__all__ = ["COLLAPSE", "COLLAPSE_WINDOWS", "collapsed", "diverging", "readable_times", "states_ahead"]


def diverging(system: HamiltonianSystem, z0: np.ndarray, z: np.ndarray) -> str | None:
    """Whether the field is what stopped a march at the state z it reached: not finite there or a
    little way along the flow from it (where the next window's stages went), or grown a million-fold
    over its size at z0 (a singularity, or a solution that blows up in finite time); else None."""
    with jax.enable_x64(True):
        f = lambda x: np.asarray(system.vector_field(np.atleast_2d(x)))  # noqa: E731
        f_end = f(z)
        if not np.all(np.isfinite(f_end)):
            return "the vector field J∇H is not finite at the state reached"
        ahead = f(states_ahead(z, f_end[0]))
        if not np.all(np.isfinite(ahead)):
            return "the vector field J∇H is not finite just ahead along the flow (a NaN or an infinity in H there)"
        grown = np.max(np.abs(f_end)) / (np.max(np.abs(f(z0))) + 1e-300)
        if grown > 1e6:
            return (f"the field grew {grown:.1e}-fold from z0 to the state reached (a singularity of H, or a solution "
                    "that blows up in finite time)")
    return None


def states_ahead(z: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """States a little way along the flow from z (its rate ``rate``): 8 steps from 1e-8 to 1e-1 of
    |z| / |rate|, where a stopped march's next window put its stages (8, n)."""
    steps = np.geomspace(1e-8, 1e-1, 8) * (np.max(np.abs(z)) + 1e-300) / (np.max(np.abs(rate)) + 1e-300)
    return z[None, :] + steps[:, None] * rate[None, :]


def readable_times(*values: float) -> list[str]:
    """The times with 6 significant digits, or as many more as tell the different ones apart (an
    interval [1e12, 1e12 + 10] is not "[1e+12, 1e+12]")."""
    for digits in range(6, 18):
        out = [f"{float(v):.{digits}g}" for v in values]
        if len(set(out)) == len(set(float(v) for v in values)):
            return out
    return [repr(float(v)) for v in values]


#: a march of constant lengths stops, naming a non-smooth H, where its length shrank this many-fold
#: below the longest it took and reaching T at it would take more than COLLAPSE_WINDOWS windows
#: (Kepler e = 0.99 from pericentre at constant lengths in t shrank them 86-fold; H = p²/2 + |q| at its kink 10¹⁰-fold)
COLLAPSE = 1e4
COLLAPSE_WINDOWS = 1e6


def collapsed(longest: np.ndarray, h: np.ndarray, t: np.ndarray, T: float, failed: np.ndarray, until: int | None,
              constant: bool) -> str | None:
    """Why a march in t of constant lengths it found (``constant``) should stop now, or None: a
    member whose length shrank ``COLLAPSE``-fold below the longest it took and that would need more
    than ``COLLAPSE_WINDOWS`` windows at it to reach T (lengths are only ever shortened: that many
    at least). A smooth H does not do this outside close encounters; a kink (abs, jnp.where) does,
    and the length it needed there would otherwise be kept to T. In τ (``until``: t's index),
    ``longest`` and ``h`` are how far t moved per window, best and last call: a time scale g
    that falls towards 0 stalls t."""
    if until is None and not constant:
        return None
    h = np.maximum(h, 1e-300)  # in τ, t may not have moved at all
    going = (t < T) & (failed == 0) & (longest > 0)
    fold = np.where(going, longest / h, 0.0)
    need = np.where(going, (T - t) / h, 0.0)
    bad = np.flatnonzero((fold >= COLLAPSE) & (need > COLLAPSE_WINDOWS))
    if bad.size == 0:
        return None
    m = int(bad[0])
    if until is not None:
        return (f"t advanced {fold[m]:.3g}-fold less per window than it had (g = dt/dτ fell), which would take "
                f"{need[m]:.3g} more windows")
    return (f"its constant window length shrank {fold[m]:.3g}-fold (to {h[m]:.3g}), which would take "
            f"{need[m]:.3g} more windows: H is probably not smooth there (abs, a kink, jnp.where), or the motion "
            f"is singular")

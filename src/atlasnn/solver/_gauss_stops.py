"""The words for a Gauss march that stopped: whether the field is what stopped it, and times
written with as many digits as tell them apart (used by :mod:`._gauss`)."""

from __future__ import annotations

import jax
import numpy as np

from atlasnn.systems import HamiltonianSystem

__all__ = ["diverging", "readable_times"]


def diverging(system: HamiltonianSystem, z0: np.ndarray, z: np.ndarray) -> str | None:
    """Whether the field is what stopped a march at the state z it reached: not finite there or a
    little way along the flow from it (where the next window's stages went), or grown a million-fold
    over its size at z0 (a singularity, or a solution that blows up in finite time); else None."""
    with jax.enable_x64(True):
        f = lambda x: np.asarray(system.vector_field(np.atleast_2d(x)))  # noqa: E731
        f_end = f(z)
        if not np.all(np.isfinite(f_end)):
            return "the vector field J∇H is not finite at the state reached"
        scale = np.max(np.abs(z)) + 1e-300
        steps = np.geomspace(1e-8, 1e-1, 8) * scale / (np.max(np.abs(f_end)) + 1e-300)
        ahead = f(z[None, :] + steps[:, None] * f_end[0][None, :])
        if not np.all(np.isfinite(ahead)):
            return "the vector field J∇H is not finite just ahead along the flow (a NaN or an infinity in H there)"
        grown = np.max(np.abs(f_end)) / (np.max(np.abs(f(z0))) + 1e-300)
        if grown > 1e6:
            return (f"the field grew {grown:.1e}-fold from z0 to the state reached (a singularity of H, or a solution "
                    "that blows up in finite time)")
    return None


def readable_times(*values: float) -> list[str]:
    """The times with 6 significant digits, or as many more as tell the different ones apart (an
    interval [1e12, 1e12 + 10] is not "[1e+12, 1e+12]")."""
    for digits in range(6, 18):
        out = [f"{float(v):.{digits}g}" for v in values]
        if len(set(out)) == len(set(float(v) for v in values)):
            return out
    return [repr(float(v)) for v in values]

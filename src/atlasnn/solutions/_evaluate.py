"""Evaluating a trained network at many times with few compiled programs: the times are padded to
a bucket size, so a new number of times rarely compiles again (Solution, PiecewiseSolution,
bundles and the error estimate all evaluate through here)."""

from __future__ import annotations

import jax
import numpy as np

from atlasnn.nn import TrialSolution


@jax.jit
def _evaluate(model: TrialSolution, t: jax.Array):
    return model.value_and_rate(t)


def bucket_size(n: int) -> int:
    """The padded length of ``n`` evaluation times: 8, 16, 32, ... up to 4096, then multiples of
    4096 (a few compiled shapes instead of one per length, at most about 2× the work)."""
    if n <= 4096:
        size = 8
        while size < n:
            size *= 2
        return size
    return -(-n // 4096) * 4096


def value_and_rate_padded(model: TrialSolution, times: np.ndarray, dtype) -> tuple[np.ndarray, np.ndarray]:
    """(ẑ, dẑ/dt) at the 1-D ``times`` as NumPy arrays, computed in ``dtype`` with the times padded
    to :func:`bucket_size` (by repeating the last one), so that a new number of times rarely
    compiles a new program."""
    n = times.size
    padded = np.zeros(bucket_size(n), dtype=np.float64)
    padded[:n] = times
    if n:
        padded[n:] = times[-1]
    # device_put, not jnp.asarray: the latter compiles a small program per shape
    z, dz = _evaluate(model, jax.device_put(padded.astype(np.dtype(dtype))))
    return np.asarray(z)[:n], np.asarray(dz)[:n]


def value_and_rate_chunked(model: TrialSolution, times: np.ndarray, dtype, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """(ẑ, dẑ/dt) at the 1-D ``times`` as NumPy arrays, evaluated ``chunk`` times per call (the last
    chunk padded by repeating the last time): one compiled program for any number of times, where
    a caller that asks for ever larger grids (the error estimate doubles its grid) would compile
    a bucket of its own at every size. Each time's row does not depend on the others in its call,
    so the values equal one call on all the times."""
    n = times.size
    padded = np.full(max(-(-n // chunk), 1) * chunk, times[-1] if n else 0.0, dtype=np.float64)
    padded[:n] = times
    host = padded.astype(np.dtype(dtype))
    parts = [_evaluate(model, jax.device_put(host[i:i + chunk])) for i in range(0, padded.size, chunk)]
    z = np.concatenate([np.asarray(p[0]) for p in parts])
    dz = np.concatenate([np.asarray(p[1]) for p in parts])
    return z[:n], dz[:n]

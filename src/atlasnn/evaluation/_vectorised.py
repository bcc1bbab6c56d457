"""Symplectic integrators run on many members of a bundle at once: the classical side of a bundle's
cost.

A member is an initial state z0_i and a parameter vector θ_i (the box's varying parameters λ_i set
into the system's own values). All N members advance together, as arrays of shape (N, d), in one
jitted ``lax.scan`` over the output times, in float64 whatever the global precision. Between two
consecutive output times t_{k-1} < t_k the interval is cut into n_k = ⌈(t_k − t_{k-1})·steps_per_unit⌉
equal steps, so every output time is a step time (no interpolation) and no step is longer than
1/steps_per_unit.

Both methods are compositions of kicks (p ← p − c·h ∂H/∂q) and drifts (q ← q + b·h ∂H/∂p), exact
flows of V and T for a separable H = T(p) + V(q):

- Störmer–Verlet (kick–drift–kick): kicks (½, ½), drift (1); second order;
- Yoshida-4: Verlet substeps of w1·h, w0·h, w1·h. A symmetric composition of a symmetric
  second-order method is consistent when 2 w1 + w0 = 1 and its h³ error term cancels when
  2 w1³ + w0³ = 0, i.e. w0 = −2^{1/3} w1, so w1 = 1/(2 − 2^{1/3}) and w0 = 1 − 2 w1 (< 0: the
  middle substep runs backwards). Adjacent half kicks of two substeps merge, leaving kicks
  (w1/2, (w1+w0)/2, (w0+w1)/2, w1/2) around drifts (w1, w0, w1); fourth order.

The force ∂H/∂q at the end of a step is the one the next step starts with (carried in the scan),
so a step costs one force evaluation per drift: 1 for Verlet, 3 for Yoshida-4, plus one at the start.
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import program_cache
from atlasnn.errors import ConfigError
from atlasnn.systems import BundleBox, HamiltonianSystem

__all__ = ["CHUNK_BYTES", "MEMBER_BLOCK", "MemberRun", "verlet_members", "yoshida4_members"]

#: the largest output (members × times × 2d float64) one compiled call produces; more members go in chunks
CHUNK_BYTES = 2 * 1024**3
#: members stepped together inside a compiled call (their outputs stay in cache while being laid out)
MEMBER_BLOCK = 2048

_W1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
_W0 = 1.0 - 2.0 * _W1

# (kick coefficients, drift coefficients): one more kick than drifts, in units of the step h
_SCHEMES = {
    "verlet": ((0.5, 0.5), (1.0,)),
    "yoshida4": ((_W1 / 2, (_W1 + _W0) / 2, (_W0 + _W1) / 2, _W1 / 2), (_W1, _W0, _W1)),
}
_LABELS = {"verlet": "verlet_members (Störmer–Verlet)", "yoshida4": "yoshida4_members (Yoshida-4)"}


class MemberRun(NamedTuple):
    """What the vectorised integrators return: the trajectories ``z`` (N, T, 2d) float64 at the
    requested times, and per member the number of ``steps`` and of ``force_evaluations`` (∂H/∂q)."""

    z: np.ndarray
    steps: int
    force_evaluations: int


# ------------------------------------------------------------------------------- the kernel
def _member_h(system: HamiltonianSystem):
    """H(q, p, θ) for one member, a scalar (θ ignored for a system without parameters)."""
    if system.parametric is not None:
        fn = system.parametric
        return lambda q, p, th: jnp.asarray(fn(q, p, th)).reshape(())
    fn = system.hamiltonian
    return lambda q, p, th: jnp.asarray(fn(q, p)).reshape(())


@program_cache
@functools.lru_cache(maxsize=32)
def _kernel(system: HamiltonianSystem, scheme: str):
    """A jitted ``(q0, p0 (n_blocks, B, d), θ (n_blocks, B, P), h (T,), n (T,)) -> z (n_blocks·B, T, 2d)``:
    n[k] steps of size h[k] from output time k − 1 to output time k, a block of B members at once,
    one block after another (so each block's output is laid out member-major while it is in cache)."""
    kicks, drifts = _SCHEMES[scheme]
    h_fn = _member_h(system)
    dh_dq = jax.vmap(jax.grad(h_fn, argnums=0))
    dh_dp = jax.vmap(jax.grad(h_fn, argnums=1))

    def block(q0, p0, theta, h, n):
        def interval(carry, hn):
            hk, nk = hn

            def step(_, c):
                q, p, g = c  # g = ∂H/∂q at q, carried from the previous step
                for a, b in zip(kicks[:-1], drifts):
                    p = p - (a * hk) * g
                    q = q + (b * hk) * dh_dp(q, p, theta)
                    g = dh_dq(q, p, theta)
                return q, p - (kicks[-1] * hk) * g, g

            carry = jax.lax.fori_loop(0, nk, step, carry)
            return carry, jnp.concatenate([carry[0], carry[1]], axis=-1)

        _, zs = jax.lax.scan(interval, (q0, p0, dh_dq(q0, p0, theta)), (h, n))
        return jnp.swapaxes(zs, 0, 1)

    def run(q0, p0, theta, h, n):
        out = jax.lax.map(lambda args: block(*args, h, n), (q0, p0, theta))
        return out.reshape(-1, *out.shape[2:])

    return jax.jit(run)


# ------------------------------------------------------------------------------ arguments
def _grid(t: Any, t0: float, steps_per_unit: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, h, n): the output times checked, and per interval the step size and step count."""
    if isinstance(steps_per_unit, bool) or not isinstance(steps_per_unit, (int, float, np.integer, np.floating)) \
            or not math.isfinite(steps_per_unit) or steps_per_unit <= 0:
        raise ConfigError(f"steps_per_unit must be a positive finite number, got {steps_per_unit!r}")
    try:
        t = np.asarray(t, np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"output times t must be numbers, got {t!r}") from None
    if t.size == 0 or not np.all(np.isfinite(t)):
        raise ConfigError(f"output times t must be a non-empty list of finite numbers, got {t.tolist()}")
    if t[0] < t0 or np.any(np.diff(t) < 0):
        raise ConfigError(f"output times t must be sorted and not before the box's t0 = {t0}, "
                          f"got {t.size} times from {t.min()} to {t.max()}")
    gaps = np.diff(np.concatenate([[t0], t]))
    # the small slack keeps a gap that is a whole number of steps from gaining one by rounding
    n = np.where(gaps > 0, np.ceil(gaps * float(steps_per_unit) * (1 - 1e-12)), 0).astype(np.int64)
    n = np.where(gaps > 0, np.maximum(n, 1), 0)
    h = np.where(n > 0, gaps / np.maximum(n, 1), 0.0)
    return t, h, n


def _members(system: HamiltonianSystem, box: BundleBox, z0: Any, lam: Any) -> tuple[np.ndarray, np.ndarray]:
    """(z0 (N, 2d), θ (N, P_all)) as float64."""
    try:
        z0 = np.asarray(z0, np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"member initial states z0 must be numbers, got {z0!r}") from None
    z0 = z0.reshape(1, -1) if z0.ndim == 1 else z0
    if z0.ndim != 2 or z0.shape[1] != system.state_dim or z0.shape[0] == 0:
        raise ConfigError(f"member initial states z0 must have shape (N, {system.state_dim}), got {z0.shape}")
    if box.params:
        lam_arr = np.asarray(lam, np.float64)
        if lam_arr.size != z0.shape[0] * len(box.params):
            raise ConfigError(f"member parameters lam must have shape ({z0.shape[0]}, {len(box.params)}) for "
                              f"{list(box.param_names)}, got {lam_arr.shape}")
        theta = box.full_theta(system, lam_arr)
    else:
        theta = np.tile(system.param_vector(), (z0.shape[0], 1))
    if not (np.all(np.isfinite(z0)) and np.all(np.isfinite(theta))):
        raise ConfigError("member initial states z0 and parameters lam must be finite")
    return z0, theta


# ------------------------------------------------------------------------------ the methods
def _integrate(scheme: str, system: HamiltonianSystem, box: BundleBox, z0: Any, lam: Any, t: Any,
               steps_per_unit: Any) -> MemberRun:
    if not isinstance(system, HamiltonianSystem):
        raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    if not isinstance(box, BundleBox):
        raise ConfigError(f"box must be a BundleBox, got {type(box).__name__}")
    system.require_separable(_LABELS[scheme])
    box.check_system(system)
    z0, theta = _members(system, box, z0, lam)
    t, h, n = _grid(t, box.t0, steps_per_unit)
    n_mem, d = z0.shape[0], system.dim
    blk = min(MEMBER_BLOCK, n_mem)
    per_chunk = max(1, CHUNK_BYTES // (t.size * system.state_dim * 8 * blk))  # blocks per compiled call
    chunk = blk * min(per_chunk, -(-n_mem // blk))
    n_pad = -(-n_mem // blk) * blk  # the last chunk may be smaller (whole blocks)
    z0 = np.concatenate([z0, np.repeat(z0[-1:], n_pad - n_mem, axis=0)])
    theta = np.concatenate([theta, np.repeat(theta[-1:], n_pad - n_mem, axis=0)])
    fn = _kernel(system, scheme)
    parts = []
    with jax.enable_x64(True):
        hj, nj = jnp.asarray(h, jnp.float64), jnp.asarray(n, jnp.int64)
        for i in range(0, n_pad, chunk):
            nb = min(chunk, n_pad - i) // blk
            zc = jnp.asarray(z0[i : i + nb * blk].reshape(nb, blk, 2 * d), jnp.float64)
            th = jnp.asarray(theta[i : i + nb * blk].reshape(nb, blk, theta.shape[1]), jnp.float64)
            parts.append(np.asarray(fn(zc[..., :d], zc[..., d:], th, hj, nj), np.float64))
    out = parts[0] if len(parts) == 1 else np.concatenate(parts)
    steps = int(n.sum())
    return MemberRun(out[:n_mem], steps, 1 + steps * len(_SCHEMES[scheme][1]))


def verlet_members(system: HamiltonianSystem, box: BundleBox, z0: Any, lam: Any, t: Any,
                   steps_per_unit: float) -> MemberRun:
    """Störmer–Verlet (kick–drift–kick, order 2) for every member (z0 (N, 2d), λ (N, P) of the box's
    varying parameters) at once, at the sorted times t (T,) ≥ ``box.t0``, with steps of at most
    1/steps_per_unit that land on every output time. Needs a separable H; float64 throughout.

    Returns a :class:`MemberRun`: ``z`` (N, T, 2d), and per member ``steps`` and
    ``force_evaluations`` (one ∂H/∂q per step, plus one at the start)."""
    return _integrate("verlet", system, box, z0, lam, t, steps_per_unit)


def yoshida4_members(system: HamiltonianSystem, box: BundleBox, z0: Any, lam: Any, t: Any,
                     steps_per_unit: float) -> MemberRun:
    """Yoshida's fourth-order composition of Störmer–Verlet (substeps w1·h, w0·h, w1·h) for every
    member at once; arguments and result as for :func:`verlet_members` (three ∂H/∂q per step)."""
    return _integrate("yoshida4", system, box, z0, lam, t, steps_per_unit)

"""A bundle solution: ẑ(t; z0, λ) for every member (z0, λ) of a box, one window or a time-marched chain.

Window k (t_k ≤ t ≤ t_{k+1}) holds a :class:`~atlasnn.nn.BundleTrial` indexed by the member's
own z0 and λ, started from the previous window's end:

    ẑ_k(t; z0, λ) = s_k(z0, λ) + f(t − t_k; γ_k) N_k(t, z0, λ; θ_k),   s_0 = z0,
    s_{k+1}(z0, λ) = ẑ_k(t_{k+1}; z0, λ),

so each window hands the whole map z0 ↦ ẑ_k(t_{k+1}; z0) over, and ẑ(t0; z0, λ) = z0 exactly
for every member. Evaluation is vectorised over members and times (compiled once per padded
size, members in chunks so memory stays bounded); sensitivities ∂ẑ/∂z0 and ∂ẑ/∂λ come from
forward-mode autodiff of the same function.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import BundleTrial
from atlasnn.solutions._evaluate import bucket_size
from atlasnn.systems import BundleBox, HamiltonianSystem

__all__ = ["BundleSolution", "MEMBER_CHUNK", "bundle_start"]

#: members evaluated together in one step of the compiled evaluation (bounds its memory)
MEMBER_CHUNK = 2048


def bundle_start(windows: Sequence[BundleTrial], edges, z0: jax.Array, lam: jax.Array) -> jax.Array:
    """s_n(z0, λ): the state where the windows given end (z0 itself when there are none),
    for members z0 (N, 2d), λ (N, P); traceable (time-marching trains the next window on it)."""
    return _starts(windows, edges, z0, lam)[-1]


def _starts(windows: Sequence[BundleTrial], edges, z0, lam):
    """s_0..s_n for members (z0 (N, 2d), λ (N, P)): (n + 1, N, 2d)."""
    out = [z0]
    for k, w in enumerate(windows):
        t = jnp.full((z0.shape[0],), edges[k + 1], z0.dtype)
        out.append(w(t, z0, lam, start=out[-1]))
    return jnp.stack(out)


@partial(jax.jit, static_argnames=("chunk",))
def _evaluate(windows, edges, t_parts, z0, lam, chunk):
    """ẑ for members (N, 2d) at each window's own times: ``t_parts[k]`` (T_k,) or None where window
    k serves no time; returns one (N, T_k, 2d) per window that serves times."""
    n_mem, dim = z0.shape

    def block(args):
        zb, lb = args
        starts = _starts(windows, edges, zb, lb)  # (n+1, C, 2d)
        outs = []
        for k, (w, t) in enumerate(zip(windows, t_parts)):
            if t is None:
                continue
            n_t = t.shape[0]
            tt = jnp.broadcast_to(t, (zb.shape[0], n_t)).reshape(-1)
            rep = lambda a: jnp.repeat(a, n_t, axis=0)  # noqa: E731
            outs.append(w(tt, rep(zb), rep(lb), start=rep(starts[k])).reshape(zb.shape[0], n_t, dim))
        return tuple(outs)

    zc = z0.reshape(n_mem // chunk, chunk, dim)
    lc = lam.reshape(n_mem // chunk, chunk, lam.shape[1])
    return tuple(o.reshape(n_mem, o.shape[2], dim) for o in jax.lax.map(block, (zc, lc)))


@dataclass(frozen=True, eq=False)
class BundleSolution:
    """The trained bundle: ``windows`` (one ``BundleTrial`` per window), ``edges``
    t_0 < … < t_n, the ``box`` it was trained over, and the ``system`` (for residuals and
    references). Call it with times (T,), initial states (N, 2d) and parameters (N, P) of the
    box's varying parameters (``box.param_names``); (N, T, 2d) comes back."""

    windows: tuple[BundleTrial, ...]
    edges: np.ndarray
    box: BundleBox
    system: HamiltonianSystem | None = None
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        edges = np.asarray(self.edges, np.float64).reshape(-1)
        if len(self.windows) < 1 or edges.size != len(self.windows) + 1 or np.any(np.diff(edges) <= 0):
            raise ConfigError(f"a bundle solution needs n windows and n + 1 increasing edges, got "
                              f"{len(self.windows)} and {edges.tolist()}")
        dims = {w.state_dim for w in self.windows} | {self.box.state_dim}
        if len(dims) != 1:
            raise ConfigError(f"bundle windows and box disagree on the state size: {sorted(dims)}")
        object.__setattr__(self, "windows", tuple(self.windows))
        object.__setattr__(self, "edges", edges)

    @property
    def state_dim(self) -> int:
        return self.box.state_dim

    @property
    def t0(self) -> float:
        return float(self.edges[0])

    @property
    def T(self) -> float:
        return float(self.edges[-1])

    def members(self, z0: Any, lam: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """(z0 (N, 2d), λ (N, P)) as float arrays, checked against the box's shape."""
        z0 = np.asarray(z0, np.float64)
        z0 = z0.reshape(1, -1) if z0.ndim == 1 else z0
        if z0.ndim != 2 or z0.shape[1] != self.state_dim:
            raise ConfigError(f"bundle z0 must have shape (N, {self.state_dim}), got {z0.shape}")
        n_p = len(self.box.params)
        lam = np.zeros((z0.shape[0], 0)) if lam is None and n_p == 0 else np.asarray(lam, np.float64)
        lam = lam.reshape(z0.shape[0], n_p) if lam.size == z0.shape[0] * n_p else lam
        if lam.shape != (z0.shape[0], n_p):
            raise ConfigError(f"bundle parameters must have shape ({z0.shape[0]}, {n_p}) for "
                              f"{list(self.box.param_names)}, got {lam.shape}")
        if not (np.all(np.isfinite(z0)) and np.all(np.isfinite(lam))):
            raise ConfigError("bundle z0 and parameters must be finite")
        return z0, lam

    def window_of(self, t: np.ndarray) -> np.ndarray:
        """The window serving each time (times outside [t0, T] go to the first or last)."""
        return np.clip(np.searchsorted(self.edges, t, side="right") - 1, 0, len(self.windows) - 1)

    def __call__(self, t: Any, z0: Any, lam: Any = None) -> np.ndarray:
        """ẑ(t; z0, λ) for every member and time: (N, T, 2d) in the model's float type."""
        t = np.atleast_1d(np.asarray(t, np.float64))
        z0, lam = self.members(z0, lam)
        n = z0.shape[0]
        chunk = min(MEMBER_CHUNK, bucket_size(n))
        n_pad = -(-n // chunk) * chunk
        dtype = self.windows[0].weights[0].dtype
        zp = np.concatenate([z0, np.repeat(z0[-1:], n_pad - n, 0)])
        lp = np.concatenate([lam, np.repeat(lam[-1:], n_pad - n, 0)]) if lam.shape[1] else np.zeros((n_pad, 0))
        which = self.window_of(t)
        parts, where = [], []
        for k in range(len(self.windows)):
            idx = np.flatnonzero(which == k)
            if idx.size == 0:
                parts.append(None)
                continue
            tk = t[idx]
            parts.append(jnp.asarray(np.concatenate([tk, np.full(bucket_size(idx.size) - idx.size, tk[-1])]), dtype))
            where.append(idx)
        outs = _evaluate(self.windows, jnp.asarray(self.edges, dtype), tuple(parts), jnp.asarray(zp, dtype),
                         jnp.asarray(lp, dtype), chunk)
        result = np.empty((n, t.size, self.state_dim), np.asarray(outs[0]).dtype)
        for idx, o in zip(where, outs):
            result[:, idx] = np.asarray(o)[:n, : idx.size]
        return result

    def sensitivities(self, t: Any, z0: Any, lam: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """(∂ẑ/∂z0 of shape (N, T, 2d, 2d), ∂ẑ/∂λ of shape (N, T, 2d, P)) by forward-mode autodiff."""
        t = np.atleast_1d(np.asarray(t, np.float64))
        z0, lam = self.members(z0, lam)
        dtype = self.windows[0].weights[0].dtype
        edges, which = jnp.asarray(self.edges, dtype), self.window_of(t)
        parts = tuple(jnp.asarray(t[which == k], dtype) if np.any(which == k) else None
                      for k in range(len(self.windows)))
        order = np.argsort(np.concatenate([np.flatnonzero(which == k) for k in range(len(self.windows))]),
                           kind="stable")

        def one(z, l):
            outs = _evaluate(self.windows, edges, parts, z[None], l[None], 1)
            return jnp.concatenate([o[0] for o in outs])[order]

        dz, dl = jax.vmap(jax.jacfwd(one, argnums=(0, 1)))(jnp.asarray(z0, dtype), jnp.asarray(lam, dtype))
        return np.asarray(dz), np.asarray(dl)

    def describe(self) -> dict[str, Any]:
        return {"windows": len(self.windows), "edges": self.edges.tolist(), "box": self.box.describe(),
                "architecture": self.windows[0].architecture(),
                "system": None if self.system is None else self.system.describe()}

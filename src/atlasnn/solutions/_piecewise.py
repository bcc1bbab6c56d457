"""A time-marching solution: one callable solution made of consecutive window trial solutions.

The interval [t0, T] is cut at the window edges t0 = t_0 < t_1 < … < t_n = T (equal lengths w).
Window k holds a trial solution on its local time s = t − t_k ∈ [0, w],

    ẑ_k(s) = z_k + f(s; γ_k) N_k(s; θ_k),    z_k = ẑ_{k−1}(w)  (z_0 the problem's z0),

so the pieces join exactly: ẑ_k(0) = z_k is the previous window's end state, bit for bit
(f(0) = 0), and the solution is continuous at every edge (up to the float rounding of the
previous window's evaluation at s = w). Every window model has t0 = 0 as its own start, so they
all have the same structure: they are stacked into one pytree and evaluated by one ``vmap``.

A time t is served by the window k with t_k ≤ t < t_{k+1} (t = T by the last window). Times
outside [t0, T] are served by the first or last window, evaluated beyond its own interval: an
extrapolation, as with :class:`~atlasnn.solutions._solution.Solution`.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.solutions._base import AbstractSolution, finite_times
from atlasnn.solutions._evaluate import bucket_size
from atlasnn.solutions._solution import check_inside, check_outside_mode, check_state_size
from atlasnn.systems import HamiltonianSystem

__all__ = ["WindowRecord", "PiecewiseSolution", "stack_models", "unstack_models", "window_edges"]


def window_edges(t0: float, T: float, n_windows: int) -> np.ndarray:
    """t_k = t0 + k (T − t0)/n for k = 0..n, in float64, with t_n = T exactly."""
    if isinstance(n_windows, bool) or not isinstance(n_windows, (int, np.integer)) or n_windows < 1:
        raise ConfigError(f"number of windows must be an integer >= 1, got {n_windows!r}")
    if not (np.isfinite(t0) and np.isfinite(T)) or T <= t0:
        raise ConfigError(f"interval must satisfy t0 < T (finite), got t0={t0!r}, T={T!r}")
    edges = float(t0) + (float(T) - float(t0)) * np.arange(n_windows + 1, dtype=np.float64) / n_windows
    edges[-1] = float(T)
    return edges


def stack_models(trees: Sequence[Any]) -> Any:
    """The trees (the window models of a march, the runs of a seed batch and their optimiser
    states) as one pytree whose array leaves have a leading axis, the inverse of
    :func:`unstack_models`; concrete leaves are stacked on the host (float64 leaves stay float64
    whatever JAX's global switch says)."""
    leaves = jax.tree_util.tree_leaves(trees[0])
    with _float64_if(any(getattr(x, "dtype", None) == np.float64 for x in leaves)):
        return jax.tree_util.tree_map(_stack, *trees)


def _stack(*xs):
    """jnp.stack(xs), on the host when every x is a concrete array (eagerly, jnp.stack compiles a
    few programs per leaf shape; copying the same values is exact; weakly typed leaves keep jnp.stack's
    typing)."""
    if all(_concrete(x) for x in xs):
        return jax.device_put(np.stack([np.asarray(x) for x in xs]))
    return jnp.stack(xs)


def unstack_models(stacked: Any, n: int) -> list[Any]:
    """The ``n`` trees of a pytree stacked on a leading axis (the window models of
    :func:`stack_models`, the runs of a seed batch): each concrete stacked leaf copied to the host
    once and row i copied back (indexed eagerly, each leaf shape compiled a program or two); other
    leaves (weakly typed, traced, NumPy) split by iterating their leading axis, one dispatch a piece."""
    leaves, treedef = jax.tree_util.tree_flatten(stacked)
    host = [np.asarray(x) if _concrete(x) else None for x in leaves]
    pieces = [list(x) if h is None else None for x, h in zip(leaves, host)]
    with _float64_if(any(h is not None and h.dtype == np.float64 for h in host)):
        return [treedef.unflatten([p[i] if h is None else jax.device_put(h[i]) for p, h in zip(pieces, host)])
                for i in range(n)]


def _concrete(x) -> bool:
    return isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer) and not x.weak_type


def _float64_if(on: bool):
    """JAX's float64 mode for the block when ``on`` (float64 models), else the mode as it is."""
    return jax.enable_x64(True) if on else contextlib.nullcontext()


@jax.jit
def _evaluate_stacked(stacked: TrialSolution, s: jax.Array):
    """(ẑ_k(s_k), dẑ_k/ds(s_k)) for every window k at its row of local times s (shape (n, m))."""
    return jax.vmap(lambda model, times: model.value_and_rate(times))(stacked, s)


@dataclass
class WindowRecord:
    """What happened in one window: its interval, Adam's run, the polishing phase and the times.

    ``epochs``/``stop_reason``/``final_loss``/``best_loss`` are Adam's; ``polish_*`` the L-BFGS
    phase's (zeros and "" when there was none); ``loss`` is the physics loss of the window's
    returned model: on the polishing grid when it was polished, else Adam's ``best_loss``;
    ``wall_time`` (compilation excluded) and ``compile_time`` cover training and polishing.
    """

    index: int
    start: float
    end: float
    z_start: list[float]
    gamma: dict[str, float]
    epochs: int
    stop_reason: str
    final_loss: float
    best_loss: float
    polish_steps: int = 0
    polish_stop_reason: str = ""
    polish_initial_loss: float = float("nan")
    loss: float = float("nan")
    wall_time: float = 0.0
    compile_time: float = 0.0
    history: np.ndarray | None = field(default=None, repr=False)  # Adam's per-epoch loss
    polish_history: np.ndarray | None = field(default=None, repr=False)

    def summary(self) -> dict[str, Any]:
        """The record without its loss curves (JSON-able)."""
        out = {k: v for k, v in self.__dict__.items() if k not in ("history", "polish_history")}
        out["z_start"] = [float(x) for x in self.z_start]
        out["gamma"] = {k: float(v) for k, v in self.gamma.items()}
        return out


@dataclass(eq=False)
class PiecewiseSolution(AbstractSolution):
    """A time-marching solution over [t0, T], callable at any times like a Solution.

    Attributes:
        models: the window trial solutions (local time, t0 = 0 each), in order.
        system: the Hamiltonian system.
        edges: the window edges t_0..t_n (float64).
        windows: one ``WindowRecord`` per window (may be empty for a bare solution).
        info: free-form record (scheme settings, training summary).
        stacked: the window models as one pytree with a leading window axis (built from ``models``
            when not given; a solver that has it already passes it).
        outside: what evaluating outside [t0, T] does, as for [`Solution`][atlasnn.solutions.Solution]:
            ``"warn"`` (once), ``"raise"`` or ``"allow"`` (the first or last window extrapolates).
    """

    models: list[TrialSolution]
    system: HamiltonianSystem
    edges: np.ndarray
    windows: list[WindowRecord] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)
    outside: str = "warn"
    stacked: Any = field(default=None, repr=False)
    _warned: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        check_outside_mode(self.outside)
        self.edges = np.asarray(self.edges, dtype=np.float64)
        n = len(self.models)
        if n < 1 or self.edges.shape != (n + 1,) or not np.all(np.diff(self.edges) > 0):
            raise ConfigError(f"a piecewise solution needs n >= 1 models and n + 1 increasing edges, "
                              f"got {n} models and edges of shape {self.edges.shape}")
        if any(float(m.t0) != 0.0 for m in self.models):
            raise ConfigError("every window model of a piecewise solution must use local time (t0 = 0)")
        for k, m in enumerate(self.models):
            check_state_size(m, self.system, f"window {k}'s model")
        # float64 window models (the collocation solver's) are stacked and evaluated in float64
        # whatever JAX's global switch says
        self._x64 = np.dtype(self.models[0].z0.dtype) == np.float64
        if self.stacked is None:
            self.stacked = stack_models(list(self.models))

    # ------------------------------------------------------------------ evaluation
    def window_index(self, t) -> np.ndarray:
        """The window serving each time: k with t_k ≤ t < t_{k+1}, clipped to [0, n − 1]."""
        arr = np.asarray(t, dtype=np.float64)
        return np.searchsorted(self.edges[1:-1], arr, side="right").astype(np.int64)

    def _evaluate(self, t) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        arr = finite_times(t)
        shape = arr.shape
        flat = arr.reshape(-1)
        check_inside(self, self.interval, flat)
        k = self.window_index(flat)
        s = flat - self.edges[k]  # local time, in float64 before the cast
        n = len(self.models)
        counts = np.bincount(k, minlength=n)
        width = bucket_size(int(counts.max(initial=0)))  # few compiled shapes
        order = np.argsort(k, kind="stable")
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        col = np.empty(flat.size, dtype=np.int64)
        col[order] = np.arange(flat.size) - np.repeat(starts, counts)
        grid = np.zeros((n, width), dtype=np.float64)
        grid[k, col] = s
        dtype = self.models[0].z0.dtype
        with _float64_if(self._x64):
            z, dz = _evaluate_stacked(self.stacked, jax.device_put(np.asarray(grid, dtype=dtype)))
        z, dz = np.asarray(z)[k, col], np.asarray(dz)[k, col]
        d = self.system.state_dim
        return z.reshape(shape + (d,)), dz.reshape(shape + (d,)), shape

    def pieces(self) -> list[tuple[TrialSolution, float, float, float]]:
        return [(m, float(a), float(b - a), 0.0) for m, a, b in zip(self.models, self.edges[:-1], self.edges[1:])]

    # ------------------------------------------------------------------ attributes
    @property
    def n_windows(self) -> int:
        return len(self.models)

    @property
    def window_length(self) -> float:
        return float(self.edges[1] - self.edges[0])

    @property
    def interval(self) -> tuple[float, float]:
        return float(self.edges[0]), float(self.edges[-1])

    @property
    def t0(self) -> float:
        return float(self.edges[0])

    @property
    def z0(self) -> np.ndarray:
        return np.asarray(self.models[0].z0, dtype=np.float64)

    @property
    def scaling_name(self) -> str:
        return self.models[0].scaling.name

    @property
    def gamma(self) -> dict[str, float]:
        """γ of the first window (where it is learned; the later windows keep it unless thawed)."""
        return {k: float(v) for k, v in self.models[0].scaling.gamma().items()}

    @property
    def gammas(self) -> list[dict[str, float]]:
        """γ of every window."""
        return [{k: float(v) for k, v in m.scaling.gamma().items()} for m in self.models]

    @property
    def wall_time(self) -> float:
        """Training wall time summed over the windows (compilation excluded)."""
        return float(sum(w.wall_time for w in self.windows))

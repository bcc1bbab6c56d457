"""The float64 collocation solver: ATLAS-NN's trial solution per window, its output layer solved
(not trained) by Gauss–Newton over random features, windows chosen by their estimated error.

The method is in :mod:`._program` (one compiled program) and :mod:`._features` (the basis);
this module holds the settings, checks them, runs the program chunk by chunk and turns its
windows into the :class:`~atlasnn.solutions.PiecewiseSolution` every other part of atlasnn reads.
"""

from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import to_host
from atlasnn.errors import ConfigError
from atlasnn.nn import inverse_softplus, make_model
from atlasnn.solutions import PiecewiseSolution, WindowRecord
from atlasnn.solver._base import AbstractSolver, register_solver, solve_one
from atlasnn.solver._features import RandomFeatures, check_grid, collocation_nodes, window_scaling
from atlasnn.solver._program import MarchState, compiled_march
from atlasnn.systems import HamiltonianSystem, require_float64_field

__all__ = ["Collocation", "require_float64"]


def require_float64(system: HamiltonianSystem | None = None) -> None:
    """Refuse, in one line, a device on which JAX cannot compute in float64, and a ``system`` whose H
    traced in float64 holds a float32 constant or computes in float32
    (:func:`atlasnn.systems.require_float64_field`)."""
    if not _offers_float64(jax.default_backend()):
        raise ConfigError(f"the collocation solver needs float64, which the {jax.default_backend()} device "
                          "does not offer; run on the CPU (JAX_PLATFORMS=cpu) or use solver=AdamMarch()")
    if system is not None:
        require_float64_field(system)


@functools.lru_cache(maxsize=8)
def _offers_float64(backend: str) -> bool:
    """Whether the default device of ``backend`` keeps a float64 array (asked once per backend)."""
    with jax.enable_x64(True):
        return jax.device_put(np.zeros(1, np.float64)).dtype == jnp.float64  # a transfer, not a program


def _positive_int(name: str, value: Any, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ConfigError(f"collocation {name} must be an integer >= {low}, got {value!r}")
    return int(value)


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not np.isfinite(value) or value <= 0:
        raise ConfigError(f"collocation {name} must be a finite number > 0, got {value!r}")
    return float(value)


#: why Collocation is on its way out: on no problem of the work–precision suite is it as accurate
#: as the default, and at its tightest it takes 4.9–46× the default's time (docs/CHOOSING.md,
#: from docs/benchmarks/solver_workprecision.json)
DEPRECATION = ("Collocation (random features) is deprecated and will be removed: GaussCollocation(), the "
               "default, is more accurate and faster on every problem measured (docs/CHOOSING.md)")


@register_solver
@dataclass(frozen=True)
class Collocation(AbstractSolver):
    """Windows of ẑ_k(s) = z_k + f(s) W_k φ(s/h), W_k found by float64 Gauss–Newton on collocation
    points, each accepted when its estimated local error meets atol + rtol·|z| (docs/SOLVER.md).

    Deprecated (a ``FutureWarning`` when built): ``GaussCollocation`` is more accurate and
    faster on every problem of the work–precision suite.

    Attributes:
        rtol: relative tolerance: each window's estimated local error must be within atol + rtol·|z|
            per component.
        atol: absolute tolerance (see rtol).
        features: M, the random tanh features per window (unknowns: 2d·M per window).
        points: P collocation nodes per window (P ≥ M: the residual's 2d·P equations must be able
            to determine the 2d·M unknowns); default M + 4.
        scale: the features' slopes are uniform in ±scale on the normalised window time.
        scaling: the time scaling f: ``"linear"`` (f = s, default), ``"tanh"`` or ``"rational_exp"``.
        shape: γ̂ of a tanh/rational-exp scaling (m·h or α·h).
        nodes: ``"chebyshev"`` (Chebyshev–Lobatto) or ``"gauss"`` (Gauss–Legendre).
        check: RK4 steps per window of the error estimate (default 2P); ``check_grid``: their
            spacing, ``"uniform"`` or ``"chebyshev"`` (finer near the window's ends).
        seed: the draw of the random features.
        order: the exponent q of the length controller (h ← h·0.8·ε^(−1/q)).
        safety: the local error estimate is multiplied by this before it is compared with the
            tolerance (it reads a median 2–3× low: docs/SOLVER.md).
        growth: the most a window may grow over the last one.
        first_window: the first window's length (default 1/‖A(z0)‖, A the vector field's Jacobian).
        max_newton: Gauss–Newton iterations per window at most; ``newton_tol``: its step tolerance.
        fresh_jacobians: iterations that compute a new Jacobian; later ones keep the last one and
            its factorisation (a simplified Newton).
        unroll: RK4 steps of the error estimate per loop iteration of the compiled program.
        max_rejects: rejected tries in a row before the march gives up.
        chunk: windows per call of the compiled program (progress is reported between calls).
    """

    name: ClassVar[str] = "collocation"
    #: round-off ~1e-16 per operation, amplified by the collocation's conditioning
    tightest: ClassVar[float] = 1e-15

    rtol: float = 1e-12
    atol: float = 1e-14
    features: int = 20
    points: int | None = None
    scale: float = 2.0
    scaling: str = "linear"
    shape: float = 1.0
    nodes: str = "chebyshev"
    check: int | None = None
    check_grid: str = "uniform"
    seed: int = 0
    order: float = 8.0
    safety: float = 3.0
    growth: float = 2.0
    first_window: float | None = None
    max_newton: int = 12
    newton_tol: float = 1e-13
    fresh_jacobians: int = 12
    unroll: int = 1
    max_rejects: int = 30
    chunk: int = 64

    def __post_init__(self) -> None:
        warnings.warn(DEPRECATION, FutureWarning, stacklevel=4)  # the caller of Collocation(...)
        self.check_tolerances()
        m = _positive_int("features", self.features)
        p = m + 4 if self.points is None else _positive_int("points", self.points)
        if p < m:
            raise ConfigError(f"collocation points ({p}) must be at least the features ({m}): fewer points cannot "
                              f"determine {m} output weights per component; raise points or lower features")
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "check", 2 * p if self.check is None else _positive_int("check", self.check, 2))
        for name in ("scale", "shape", "order", "newton_tol", "safety"):
            _positive(name, getattr(self, name))
        if _positive("growth", self.growth) <= 1.0:
            raise ConfigError(f"collocation growth must be > 1, got {self.growth!r}")
        if self.first_window is not None:
            _positive("first_window", self.first_window)
        window_scaling(self.scaling)
        collocation_nodes(2, self.nodes)
        check_grid(3, self.check_grid)
        for name in ("max_newton", "max_rejects", "chunk", "fresh_jacobians", "unroll"):
            _positive_int(name, getattr(self, name))
        _positive_int("seed", self.seed, 0)

    # ------------------------------------------------------------------ solving
    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *,
              progress: Callable[[float], None] | None = None) -> PiecewiseSolution:
        return solve_one(self.solve_batch, system, z0, t0, T, progress)

    def solve_batch(self, system: HamiltonianSystem, z0s: np.ndarray, t0: float, T: float, *, seeds: Any = None,
                    progress: Callable[[float], None] | None = None) -> list[PiecewiseSolution]:
        """One solution per row of ``z0s`` (shape (B, 2d)), all marched by one compiled program;
        member b uses the features of ``seeds[b]`` (default: this solver's seed for every member)."""
        require_float64(system)
        rtol, atol = self.rtol, self.atol
        z0s = np.atleast_2d(np.asarray(z0s, np.float64))
        seeds = [self.seed] * len(z0s) if seeds is None else [int(s) for s in seeds]
        if len(seeds) != len(z0s):
            raise ConfigError(f"solve_batch needs one seed per initial state, got {len(seeds)} and {len(z0s)}")
        program = compiled_march(system, self.scaling, chunk=self.chunk, max_newton=self.max_newton,
                                 newton_tol=self.newton_tol, fresh=self.fresh_jacobians, unroll=self.unroll,
                                 order=self.order, growth=self.growth, max_rejects=self.max_rejects,
                                 safety=self.safety, members=len(z0s))
        feats = [RandomFeatures.draw(self.features, self.scale, s) for s in seeds]
        started = time.perf_counter()
        rows, state, first_call = self._march(program, feats, z0s, t0, T, rtol, atol, progress)
        wall = time.perf_counter() - started
        out, problem = [], None
        for b, z0 in enumerate(z0s):
            start, length, z_start, weights, est_max, ratio = (np.concatenate([r[i][b] for r in rows]) for i in range(6))
            end, failed = float(state.t[b]), int(state.failed[b])
            stopped = failed or start.size == 0 or end < T
            if stopped and problem is None:
                problem = (f"the collocation march{'' if len(z0s) == 1 else f' of member {b}'} stopped at t = {end:.6g} "
                           f"of [{t0:.6g}, {T:.6g}]: windows shrank below round-off or failed {self.max_rejects} times "
                           f"in a row (rtol={rtol:g}, atol={atol:g}); loosen the tolerance or raise features")
            if stopped and start.size == 0:
                out.append(None)  # a member that stopped before its first window: nothing to keep
                continue
            info = {"solver": self.name, "settings": {**self.settings(), "seed": seeds[b]}, "rtol": float(rtol),
                    "atol": float(atol), "windows": int(start.size), "rejected": int(state.rejected[b]),
                    "newton_iterations": int(state.newton[b]), "running_estimate_max": float(est_max.max()),
                    "running_estimate_end": np.asarray(state.delta[b]).tolist(), "solve_time": wall,
                    "first_call_time": first_call, "batch": len(z0s)}
            # a member that stopped keeps the windows it accepted (the error's .partial)
            out.append(self._solution(system, z0, feats[b], start, length, z_start, weights, est_max, ratio, info))
        if problem is not None:
            kept = any(part is not None for part in out)
            error = ConfigError(problem + ("; the solution" + ("s" if len(z0s) > 1 else "") + " computed so far: the "
                                           "error's .partial" if kept else ""))
            error.partial = out
            raise error
        return out

    def _march(self, program, feats, z0s, t0, T, rtol, atol, progress):
        """Call the compiled program until every member reaches T or fails: the rows of accepted
        windows per call (each (B, ...) cut to the member's count), the final state, the first
        call's time (compilation or cache load included)."""
        b = len(z0s)
        nodes = collocation_nodes(self.points, self.nodes)
        check = check_grid(2 * self.check + 1, self.check_grid)
        rows, first_call = [], 0.0
        # the program's inputs as NumPy arrays: building them with jax.numpy would compile a small
        # program per operation in a new process (tens of milliseconds of a warm start)
        f64 = lambda x: np.asarray(x, np.float64)  # noqa: E731
        args = ((f64([f.a for f in feats]), f64([f.b for f in feats])), f64(nodes), tuple(map(f64, check)),
                f64(self.shape))
        zeros = np.zeros(b, np.int64)
        state = MarchState(np.full(b, float(t0)), f64(z0s), np.full(b, float(self.first_window or 0.0)),
                           np.zeros_like(f64(z0s)), zeros, zeros, zeros)
        T_, rtol_, atol_ = f64(T), f64(rtol), f64(atol)
        with jax.enable_x64(True):
            while True:
                tic = time.perf_counter()
                out = to_host(program(*args, state, T_, rtol_, atol_))
                if not rows:  # the first call compiles (or loads from the cache) and runs
                    first_call = time.perf_counter() - tic
                state = out.state
                counts = np.asarray(out.count)
                rows.append([[np.asarray(x)[m, :counts[m]] for m in range(b)] for x in out[1:-1]])
                t_now, failed = np.asarray(out.state.t), np.asarray(out.state.failed)
                if progress is not None:
                    progress(min(1.0, float(t_now.min() - t0) / (T - t0)))
                if np.all((t_now >= T) | (failed != 0)):
                    break
        return rows, jax.device_get(state), first_call

    def _solution(self, system, z0, feats, start, length, z_start, weights, est_max, ratio, info) -> PiecewiseSolution:
        """The windows as a PiecewiseSolution of float64 trial solutions (one-hidden-layer tanh
        networks whose first layer is the features scaled to each window)."""
        n = start.size
        scaling = window_scaling(self.scaling)
        with jax.enable_x64(True):
            # its shapes only (every leaf is set below): a model drawn at random would compile the draw
            skeleton = jax.eval_shape(lambda: make_model(np.zeros(system.state_dim), scaling=self.scaling,
                                                         width=self.features, depth=1, activation="tanh"))
            host = self._stacked(skeleton, feats, length, z_start, weights, scaling)  # NumPy leaves
            stacked = jax.tree_util.tree_map(jnp.asarray, host)
        models = [jax.tree_util.tree_map(lambda x, k=k: x[k], host) for k in range(n)]
        edges = np.append(start, start[-1] + length[-1])
        # a window's record: no Adam run (0 epochs, stop reason "gauss-newton"); its ``loss`` is the
        # local error estimate over the tolerance (safety factor included), ≤ 1 for every window kept
        records = [WindowRecord(k, float(start[k]), float(edges[k + 1]), z_start[k].tolist(),
                                {g: float(v) for g, v in scaling.gamma(length[k], self.shape).items()},
                                0, "gauss-newton", float("nan"), float("nan"), loss=float(ratio[k]))
                   for k in range(n)]
        info["window_estimate_max"] = est_max.tolist()
        return PiecewiseSolution(models, system, edges, records, info, outside="warn", stacked=stacked)

    def _stacked(self, skeleton, feats, length, z_start, weights, scaling):
        n = length.size
        f64 = lambda x: np.asarray(x, np.float64)  # noqa: E731
        first = f64(feats.a[None, :, None] / length[:, None, None])
        leaves = {
            "w0": first, "b0": f64(np.broadcast_to(feats.b, (n, feats.count))), "w1": f64(weights),
            "b1": np.zeros((n, z_start.shape[1]), np.float64), "z0": f64(z_start),
        }
        stacked = eqx.tree_at(lambda m: (m.net.weights[0], m.net.biases[0], m.net.weights[1], m.net.biases[1], m.z0),
                              skeleton, (leaves["w0"], leaves["b0"], leaves["w1"], leaves["b1"], leaves["z0"]))
        gamma = [scaling.gamma(h, self.shape) for h in length]
        if gamma and gamma[0]:
            raw = {g: f64([inverse_softplus(x[g]) for x in gamma]) for g in gamma[0]}
            stacked = eqx.tree_at(lambda m: tuple(getattr(m.scaling, f"raw_{g}") for g in raw), stacked,
                                  tuple(raw.values()))
        if any(isinstance(x, jax.ShapeDtypeStruct) for x in jax.tree_util.tree_leaves(stacked)):
            raise AssertionError("a leaf of the window model was left unset")  # a model grew a parameter
        return stacked

    def settings(self) -> dict[str, Any]:
        """The settings as a JSON-able dict (what a record keeps)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

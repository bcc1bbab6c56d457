"""The solution of an explicit splitting method: states at step points, and between them the same
method's partial step.

The march takes n steps of one length h from t0 (a constant step: the method stays symplectic).
It keeps the state every ``every`` steps, rounded to float64 (the compensated sum of the march
carries on inside it; the end state keeps its compensation). At a time t in step j (t0 + jh ≤
t < t0 + (j + 1)h) the solution is the state kept last before step j, carried by full steps to
step j and then by one step of length t − t0 − jh of the same method: the state at t with the
method's own accuracy, for any t, continuous at the step points (to round-off). Its derivative is
the rate of that last partial step.

Its error estimate compares it with a companion solution over the same interval by the same method
with steps half as long (supplied by the solver): the companion's error is 2^p times smaller
(p the order), so the difference is this solution's error to within 2^−p of itself
(docs/SOLVER.md measures it against exact solutions).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import program_cache
from atlasnn.errors import ConfigError
from atlasnn.solutions._base import AbstractSolution, check_inside, finite_times
from atlasnn.solutions._estimate import ErrorEstimate
from atlasnn.solutions._polynomial import CompanionEstimated, _at_least_roundoff
from atlasnn.solutions._solution import check_outside_mode
from atlasnn.solutions._splitting_step import partial_rate, partial_step
from atlasnn.solutions._splitting_tables import splitting_scheme
from atlasnn.systems import HamiltonianSystem

__all__ = ["SplittingSolution"]

#: rows per call of the compiled dense output: a few times go in a call of the small size, more in
#: calls of the large one (two programs per system and scheme; each row is a step of the method,
#: so padding is work: 200 times take two calls of 128 rows, not one of 1 024)
_EVAL_SMALL, _EVAL_CHUNK = 16, 128
#: a state of at least this many numbers is stepped one row at a time (a loop over the rows a call
#: holds, the padding rows not stepped), not all rows at once: FPUT-β, N = 1 024, 198 rows all at
#: once took 11.6 ms, one at a time 7.5 ms; 200 times in two calls of 128 rows 11.0 ms stepping the
#: padding too, 8.3 ms without. Smaller states are stepped all at once, which compiles in less than
#: half the time (N = 256: 0.28 s against 0.75 s) and is as fast
_EVAL_BATCH_NUMBERS = 2048
#: interior points per kept interval where the error estimate compares the two solutions
_ESTIMATE_POINTS = 3


@program_cache
@functools.lru_cache(maxsize=64)
def _dense(system: HamiltonianSystem, scheme: str, kind: str):
    """The compiled dense output, per system, scheme and kind: rows of (start state, full steps,
    h, τ) -> ẑ (``"at"``: from the kept state itself, no full steps; ``"after"``: after the full
    steps) or (ẑ, dẑ/dt) (``"rate"``). The start state is a kept state rounded to float64 (the
    march keeps them so). For a state of ``_EVAL_BATCH_NUMBERS`` numbers or more, the count of rows
    to step comes first (the rest are padding)."""
    sch = splitting_scheme(scheme)
    if kind == "at":
        one = lambda z, steps, h, tau: partial_step(system, sch, z, jnp.zeros_like(z), 0, h, tau)  # noqa: E731
    else:
        step = partial_rate if kind == "rate" else partial_step
        one = lambda z, steps, h, tau: step(system, sch, z, jnp.zeros_like(z), steps, h, tau)  # noqa: E731
    if system.state_dim < _EVAL_BATCH_NUMBERS:
        return jax.jit(jax.vmap(one))

    def counted(count, *rows):  # the first ``count`` rows, one at a time; the padding is left as zeros
        tree = jax.tree_util.tree_map
        shapes = jax.eval_shape(one, *tree(lambda x: x[0], rows))

        def row(i, out):
            return tree(lambda o, v: o.at[i].set(v), out, one(*tree(lambda x: x[i], rows)))
        return jax.lax.fori_loop(0, count, row, tree(lambda s: jnp.zeros((rows[0].shape[0],) + s.shape, s.dtype), shapes))
    return jax.jit(counted)


@dataclass(eq=False)
class SplittingSolution(CompanionEstimated, AbstractSolution):
    """An explicit splitting method's solution over [t0, t0 + n·h], callable at any times.

    Attributes:
        system: the Hamiltonian system (separable).
        scheme: the splitting scheme's name (``atlasnn.solutions.SPLITTING_SCHEMES``).
        t0: the start.
        h: the step.
        n_steps: n, the number of steps.
        kept: the step indices whose states are kept (increasing, from 0; the last is n).
        z: the kept states (len(kept), 2d); ``e``: their compensations (z + e is the state; the
            march keeps them only at the end, the states between rounded).
        info: the solver's record (settings, tolerance, counts, times).
        estimator: a function returning the companion solution of the error estimate.
        outside: what evaluating outside [t0, T] does (as for [`Solution`][atlasnn.solutions.Solution]).
    """

    interval_name: ClassVar[str] = "interval"

    system: HamiltonianSystem
    scheme: str
    t0: float
    h: float
    n_steps: int
    kept: np.ndarray
    z: np.ndarray
    e: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)
    estimator: Callable[[], "SplittingSolution"] | None = field(default=None, repr=False)
    outside: str = "warn"
    _warned: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        check_outside_mode(self.outside)
        splitting_scheme(self.scheme)  # refuses an unknown name
        self.kept = np.asarray(self.kept, np.int64)
        self.z, self.e = np.asarray(self.z, np.float64), np.asarray(self.e, np.float64)
        self.t0, self.h, self.n_steps = float(self.t0), float(self.h), int(self.n_steps)
        k, d = self.kept.size, self.system.state_dim
        if not (self.h > 0 and np.isfinite(self.h) and self.n_steps >= 1):
            raise ConfigError(f"a splitting solution needs a step h > 0 and n_steps >= 1, got h = {self.h!r}, "
                              f"n_steps = {self.n_steps!r}")
        if k < 2 or self.kept[0] != 0 or self.kept[-1] != self.n_steps or np.any(np.diff(self.kept) <= 0):
            raise ConfigError(f"a splitting solution's kept steps must rise from 0 to n_steps = {self.n_steps}, got "
                              f"{self.kept[:3].tolist()}…{self.kept[-2:].tolist()}")
        if self.z.shape != (k, d) or self.e.shape != (k, d):
            raise ConfigError(f"a splitting solution keeping {k} states needs z and e of shape ({k}, {d}), got "
                              f"{self.z.shape} and {self.e.shape}")

    # ------------------------------------------------------------------ evaluation
    def _rows(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For each time: the kept state it starts from, the full steps after it, and τ."""
        j = np.clip(np.floor((t - self.t0) / self.h), 0, self.n_steps - 1).astype(np.int64)
        c = np.searchsorted(self.kept, j, side="right") - 1
        return c, j - self.kept[c], (t - self.t0) - j * self.h

    def _evaluate(self, t) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        arr = finite_times(t)
        z, dz = self._values(arr, rates=True)
        return z, dz, arr.shape

    def __call__(self, t) -> np.ndarray:
        """ẑ(t): shape t.shape + (2d,)."""
        return self._values(finite_times(t), rates=False)[0]

    def _values(self, arr: np.ndarray, rates: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """ẑ at the times ``arr`` (and dẑ/dt with ``rates``), by the compiled dense output."""
        flat = arr.reshape(-1)
        check_inside(self, self.interval, flat)
        d = self.system.state_dim
        z, dz = np.empty((flat.size, d)), np.empty((flat.size, d)) if rates else None
        kind = "rate" if rates else "at" if np.all(np.diff(self.kept) == 1) else "after"
        if not rates:  # times at kept states: those states themselves, with no step
            c = self._kept_row(flat)
            at = c >= 0
            z[at] = self.z[c[at]] + self.e[c[at]]
            if np.all(at):
                return z.reshape(arr.shape + (d,)), None
            flat, rows = flat[~at], np.nonzero(~at)[0]
        else:
            rows = np.arange(flat.size)
        program = _dense(self.system, self.scheme, kind)
        c, steps, tau = self._rows(flat)
        starts = self._starts()
        with jax.enable_x64(True):
            for a in range(0, flat.size, _EVAL_CHUNK):
                m = min(_EVAL_CHUNK, flat.size - a)
                size = _EVAL_SMALL if m <= _EVAL_SMALL else _EVAL_CHUNK
                take = np.minimum(np.arange(a, a + size), flat.size - 1)  # padded with the last row
                rows_in = (starts[c[take]], steps[take], np.full(size, self.h), tau[take])
                out = program(*rows_in) if d < _EVAL_BATCH_NUMBERS else program(np.int64(m), *rows_in)
                where = rows[a:a + m]
                if rates:
                    z[where], dz[where] = np.asarray(out[0])[:m], np.asarray(out[1])[:m]
                else:
                    z[where] = np.asarray(out)[:m]
        shape = arr.shape + (d,)
        return z.reshape(shape), None if dz is None else dz.reshape(shape)

    def _starts(self) -> np.ndarray:
        """The kept states the dense output starts from, rounded (z + e): ``z`` itself where the
        compensations are kept only at the end (as the march keeps them; it never starts there)."""
        plain = self.__dict__.get("_plain")
        if plain is None:
            plain = self.__dict__["_plain"] = not np.any(self.e[:-1])
        return self.z if plain else self.z + self.e

    def _kept_row(self, t: np.ndarray) -> np.ndarray:
        """For each time, the row of the kept state at exactly that step point (to round-off of the
        times), or −1."""
        s = (t - self.t0) / self.h
        j = np.rint(s)
        near = np.abs(s - j) <= 1e-12 * np.maximum(1.0, np.abs(s))
        c = np.searchsorted(self.kept, j.astype(np.int64))
        c = np.minimum(c, self.kept.size - 1)
        return np.where(near & (self.kept[c] == j), c, -1)

    def pieces(self) -> list[tuple[Any, float, float, float]]:
        raise NotImplementedError("a splitting solution has no network pieces; its estimate() compares it with a "
                                  "companion solution")

    # ------------------------------------------------------------------ the error estimate
    def estimate(self, z0: Any = None) -> ErrorEstimate:
        """The a-posteriori error estimate against the companion: the difference of the two at
        every kept state, at points between them, and at T. ``z0`` is accepted for the common
        interface; the state at t0 is exact here."""
        cached = self.__dict__.get("_estimate")
        if cached is not None:
            return cached
        companion = self.companion()
        starts = self.t0 + self.kept * self.h
        inner = (starts[:-1, None] + np.diff(starts)[:, None] * (np.arange(1, _ESTIMATE_POINTS + 1)
                                                                 / (_ESTIMATE_POINTS + 1))).reshape(-1)
        t = np.sort(np.concatenate([starts, inner]))
        mine = self(t)
        est = ErrorEstimate(t, _at_least_roundoff(companion(t) - mine, mine), mine, steps=[int(self.n_steps)],
                            converged=True)
        self.__dict__["_estimate"] = est
        return est

    # ------------------------------------------------------------------ attributes
    @property
    def interval(self) -> tuple[float, float]:
        return self.t0, self.t0 + self.n_steps * self.h

    @property
    def z0(self) -> np.ndarray:
        return self.z[0] + self.e[0]

    @property
    def n_windows(self) -> int:
        """The number of steps (the windows of this solution)."""
        return self.n_steps

    @property
    def end_state(self) -> np.ndarray:
        """ẑ(T), the last step's end."""
        return self.z[-1] + self.e[-1]


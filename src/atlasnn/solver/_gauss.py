"""The Gauss collocation solver: ATLAS-NN's trial solution with a polynomial network collocated at
the s Gauss–Legendre nodes of every window — the s-stage Gauss–Legendre Runge–Kutta method.

The method is in :mod:`._gauss_step` (one window) and :mod:`._gauss_march` (the compiled march);
this module holds the settings, checks them, runs the program chunk by chunk and returns the
:class:`~atlasnn.solutions.PolynomialSolution`, with its error estimate (a companion solution on
windows half as long) and, for long marches, the means to solve a window again. With a
``time_scale`` it marches the time-transformed system (:mod:`._gauss_time`) and returns a
:class:`~atlasnn.solutions.TimeTransformedSolution`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields
from typing import Any, Callable, ClassVar

import jax
import numpy as np

from atlasnn.compile_cache import to_host
from atlasnn.errors import ConfigError
from atlasnn.limits import available_memory
from atlasnn.solutions import (PolynomialSolution, TimeTransformedSolution, TracedSolution, bucket_size, edge_offsets,
                               gauss_tableau)
from atlasnn.solver._base import AbstractSolver, monotone_progress, register_solver, solve_one
from atlasnn.solver._collocation import require_float64
from atlasnn.solver._gauss_core import LOOPS, compiled_gauss_core, gauss_core, traced_inputs
from atlasnn.solver._gauss_march import (FAILURES, NEWTON_LATER, STEP_MODES, GaussState, ReplayState, clock,
                                         compiled_gauss_march, compiled_gauss_replay, compiled_gauss_windows,
                                         initial_state)
from atlasnn.solver._gauss_stops import collapsed, diverging, readable_times
from atlasnn.solver._gauss_time import (AUTO, WATCH_FIRST, ScaleVaries, ScaleWatch, TimeTransform, check_time_scale,
                                        describe_time_scale, march_advice, potential_applies)
from atlasnn.systems import HamiltonianSystem, require_float64_field

__all__ = ["GaussCollocation", "KEEP_BYTES", "NEWTON_AUTO_SIZE", "STAGES_BY_TOLERANCE", "stages_for"]

#: a march keeps every window's polynomial while they take at most this much memory (else only the
#: window starts, and a window is solved again when it is evaluated)
KEEP_BYTES = 1 << 30
#: the stage count for a tolerance when none is given: the first s whose rtol bound the tolerance
#: reaches. Measured (benchmarks/gauss_orders.py: Hénon–Heiles, Kepler e = 0.6, the double
#: pendulum, an FPUT-β chain; s = 2 … 16, the fastest at each rtol): s = 8 on three of the four at
#: rtol 1e-5, 12 on two at 1e-7 (8 and 16 one each), 16 on three at 1e-9 and on all four below.
STAGES_BY_TOLERANCE = ((1e-6, 8), (1e-8, 12), (0.0, 16))
#: the largest state (2d components) that gets the Newton fallback by default: past it the Jacobian
#: (n field derivatives) and s/2 complex LU factorisations of n × n cost more than the shorter
#: fixed-point windows that replace a failed one (benchmarks/gauss_scaling.py)
NEWTON_AUTO_SIZE = 64
#: the most memory one call's buffers take across the members of a batch: the program fills, returns
#: and copies them whole, so a large buffer is a fixed cost (256 copies of Hénon–Heiles, d = 1 024:
#: 67 ms a solve with 64 MiB, 28 ms with 4 MiB); more calls cost little
_CHUNK_BYTES = 4 << 20
#: window lengths replayed per call of the companion's program
_REPLAY_CHUNK = 4096


def stages_for(rtol: float) -> int:
    """The stage count :class:`GaussCollocation` takes for ``rtol`` when none is given."""
    return next(s for bound, s in STAGES_BY_TOLERANCE if rtol >= bound)


def _number(name: str, value: Any, *, low: float = 0.0, above: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(value)) or (float(value) <= low if above else float(value) < low):
        raise ConfigError(f"GaussCollocation {name} must be a finite number {'>' if above else '>='} {low:g}, "
                          f"got {value!r}")
    return float(value)


def _integer(name: str, value: Any, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ConfigError(f"GaussCollocation {name} must be an integer >= {low}, got {value!r}")
    return int(value)


@register_solver
@dataclass(frozen=True)
class GaussCollocation(AbstractSolver):
    """ATLAS-NN's trial solution ẑ(t_k + θh) = z_k + θh·N(θ) with N a polynomial of degree s − 1,
    collocated at the s Gauss–Legendre nodes of each window: the s-stage Gauss–Legendre
    Runge–Kutta method. Symplectic, symmetric, of order 2s at the window ends and s + 1 between
    them; conserves every quadratic invariant (angular momentum) to round-off. The stage equations
    are solved by fixed-point iteration to round-off (simplified Newton where it does not converge;
    at a tolerance far above round-off, to 0.01·rtol spread over the interval's windows),
    the state summed with compensation, the coefficients symplectic in float64 (docs/SOLVER.md).

    Attributes:
        stages: s (1–16; order 2s); None: chosen from rtol (``STAGES_BY_TOLERANCE``).
        rtol: relative tolerance: every window's error along it, as its Picard check bounds it, must
            be within atol + rtol·|z| per component (a tolerance below float64's round-off counts as
            round-off).
        atol: absolute tolerance (see rtol).
        steps: ``"constant"`` (one length, found over the first windows and only ever shortened:
            symplectic) or ``"adaptive"`` (every window its own length: fewer windows on an eccentric
            orbit, no exact symplecticity).
        h: a window length to use throughout (tolerances then only checked and recorded).
        safety: the check's bound is multiplied by this before it is compared with the tolerance.
        growth: the most a window may grow over the last (while lengths may grow).
        warmup: windows over which a constant length is found.
        newton: solve a window by simplified Newton iterations where the fixed-point iteration fails
            (decoupled: s/2 complex systems of the state's size); None: for states of at most
            ``NEWTON_AUTO_SIZE`` components, else the window is shortened instead (its Jacobian and
            their factorisations cost more than many fixed-point windows there), and compiled into
            the march only once a window needs it (``NEWTON_LATER``). A system that
            declares a ``linear_part`` is solved by Newton iterations with it whatever this says.
        max_iterations: iterations per window at most (each kind).
        max_rejects: rejected tries in a row before the march gives up.
        keep: keep every window's polynomial (True), only the window starts (False: a window is
            solved again when evaluated), or decide by the memory it takes (None: up to 1 GiB).
        chunk: windows per call of the compiled program (progress is reported between calls).
        time_scale: march in a fictitious time τ with dt/dτ = g(q, p), windows of one τ-length
            (Poincaré's transformation: symplectic in the extended phase space; for close
            encounters and eccentric orbits): a function g(q, p) > 0, small where the motion is
            fast, or ``"potential"``: g = (−V(q))^(−3/2) for a separable H whose potential is
            negative (gravitational N-body problems); ``h`` and the lengths recorded are then in τ
            (``_gauss_time``; docs/howto/CLOSE_ENCOUNTERS.md). None: march in t. ``"auto"``
            (the default): march in t, and for a system ``"potential"`` suits (separable, V < 0
            and homogeneous of degree −1, as gravity's) march in τ with it instead once a march of
            constant lengths in t finds g varying 20-fold over its windows after a chunk, or is
            stopped by lengths a close encounter shrank (``info["time_scale_chosen"]`` says why).
        max_windows: the most window tries (accepted or rejected) of a solve run inside ``jax.jit``,
            ``jax.grad``, ``jax.vmap`` or ``jax.jvp`` (its traceable core has static shapes, as
            Diffrax's ``max_steps``); a march that needs more raises when it runs.
        differentiation: how that core may be differentiated: ``"reverse"`` (``jax.grad``,
            ``jax.vjp``: the march's adjoint) or ``"forward"`` (``jax.jvp``, ``jax.jacfwd``: through its loop).
    """

    name: ClassVar[str] = "gauss"
    #: a tolerance below round-off counts as round-off; this is only a floor against nonsense
    tightest: ClassVar[float] = 1e-16

    stages: int | None = None
    rtol: float = 1e-11
    atol: float = 1e-13
    steps: str = "constant"
    h: float | None = None
    safety: float = 2.0
    growth: float = 4.0
    warmup: int = 8
    newton: bool | None = None
    max_iterations: int = 100
    max_rejects: int = 30
    keep: bool | None = None
    chunk: int = 1024
    time_scale: str | Callable | None = AUTO
    max_windows: int = 4096
    differentiation: str = "reverse"

    def __post_init__(self) -> None:
        if self.stages is not None:
            gauss_tableau(self.stages)  # refuses a stage count out of range
        self.check_tolerances()
        _number("safety", self.safety)
        if _number("growth", self.growth) <= 1.0:
            raise ConfigError(f"GaussCollocation growth must be > 1, got {self.growth!r}")
        if self.steps not in STEP_MODES:
            raise ConfigError(f"GaussCollocation steps must be one of {list(STEP_MODES)}, got {self.steps!r}")
        if self.h is not None:
            _number("h", self.h)
        if self.differentiation not in LOOPS:
            raise ConfigError(f"GaussCollocation differentiation must be one of {list(LOOPS)}, "
                              f"got {self.differentiation!r}")
        for name in ("max_iterations", "max_rejects", "chunk", "max_windows"):
            _integer(name, getattr(self, name))
        _integer("warmup", self.warmup, 0)
        for name in (("newton",) if self.newton is not None else ()) + (("keep",) if self.keep is not None else ()):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"GaussCollocation {name} must be true or false, got {getattr(self, name)!r}")
        check_time_scale(self.time_scale)

    def newton_for(self, size: int) -> bool:
        """Whether a state of ``size`` components gets the Newton fallback (``newton``)."""
        return self.newton if self.newton is not None else size <= NEWTON_AUTO_SIZE

    @property
    def stage_count(self) -> int:
        """s: ``stages``, or the count chosen from rtol."""
        return self.stages if self.stages is not None else stages_for(self.rtol)

    @property
    def order(self) -> int:
        """2s, the order at the window ends."""
        return 2 * self.stage_count

    def settings(self) -> dict[str, Any]:
        """The settings as a JSON-able dict (what a record keeps; a time scale by its name)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        return {**out, "time_scale": describe_time_scale(self.time_scale)}

    # ------------------------------------------------------------------ solving
    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *,
              progress: Callable[[float], None] | None = None) -> PolynomialSolution | TimeTransformedSolution:
        return solve_one(self.solve_batch, system, z0, t0, T, progress)

    def solve_traced(self, system: HamiltonianSystem, z0: Any, t0: Any, T: Any) -> TracedSolution:
        """The solution as JAX values, by the traceable core (``solver/_gauss_core.py``): what
        ``solve`` returns inside ``jax.jit``, ``jax.grad``, ``jax.vmap`` or ``jax.jvp``. The same
        windows and numbers as ``solve`` on numbers (to round-off); no progress, no error estimate,
        no time scale (docs/JAX.md)."""
        if self.time_scale not in (None, AUTO):
            raise ConfigError("GaussCollocation time_scale is not available inside jit/grad/vmap (there the march is "
                              "in t): solve without it there, or call solve on numbers")
        n = system.state_dim
        require_float64_field(system, constants=False)
        need = self.max_windows * (self.stage_count + 3) * n * 8
        room = available_memory()
        if room is not None and need > room:
            raise ConfigError(f"GaussCollocation max_windows = {self.max_windows} keeps about {need / 2**30:.3g} GiB "
                              f"for one traced solve ((s + 3)·2d·8 bytes a window, 2d = {n}), more than the "
                              f"{room / 2**30:.3g} GiB available; lower max_windows")
        settings = dict(stages=self.stage_count, steps=self.steps, rtol=self.rtol, atol=self.atol, h=self.h,
                        max_windows=self.max_windows, differentiation=self.differentiation,
                        max_iterations=self.max_iterations, newton=self.newton_for(n), growth=self.growth,
                        safety=self.safety, warmup=self.warmup, max_rejects=self.max_rejects)
        z0, t0, T = traced_inputs(system, z0, t0, T)  # refused here, in one line, before any trace
        if system.traced:  # H closes over traced values: they cannot be a compiled program's constants
            return gauss_core(system, z0, t0, T, **settings)
        return compiled_gauss_core(system, z0, t0, T, **settings)

    def solve_batch(self, system: HamiltonianSystem, z0s: np.ndarray, t0: float, T: float, *,
                    progress: Callable[[float], None] | None = None
                    ) -> list[PolynomialSolution] | list[TimeTransformedSolution]:
        """One solution per row of ``z0s`` (shape (B, 2d)), all marched by one compiled program."""
        require_float64(system)
        z0s = np.atleast_2d(np.asarray(z0s, np.float64))
        if self.time_scale not in (None, AUTO):
            return self._solve_scaled(system, z0s, t0, T, progress, self.time_scale)
        auto = (self.time_scale == AUTO and self.steps == "constant" and self.h is None
                and all(potential_applies(system, z) for z in z0s))
        tic = time.perf_counter()
        if auto and progress is not None:
            progress = monotone_progress(progress)  # the march in τ that may follow starts again from t0
        try:
            return self._solve_rows(system, z0s, t0, T, progress, watch=ScaleWatch(system, len(z0s)) if auto else None)
        except ScaleVaries as why:
            spent = time.perf_counter() - tic
            return self._solve_scaled(system, z0s, t0, T, progress, "potential",
                                      chosen=f"{why} (that march took {spent:.3g} s before this one)", spent=spent)

    def _solve_scaled(self, system: HamiltonianSystem, z0s: np.ndarray, t0: float, T: float,
                      progress: Callable[[float], None] | None, time_scale: Any, chosen: str | None = None,
                      spent: float = 0.0) -> list[TimeTransformedSolution]:
        """``solve_batch`` in τ with ``time_scale`` (``chosen``: why the default took it, after a
        march in t of ``spent`` seconds, which the solutions' ``solve_time`` includes)."""
        transform = TimeTransform(system, time_scale)
        try:
            parts, stop = self._solve_rows(transform.extended, transform.lift(z0s, t0), t0, T, progress,
                                           until=transform.clock), None
        except ConfigError as exc:
            if not isinstance(getattr(exc, "partial", None), list):
                raise
            parts, stop = exc.partial, exc
        out, problem = transform.solutions(parts, T)
        if stop is not None and problem is None:
            problem = transform.stop_line(parts)  # a scale that turned NaN ahead, not H
        for sol in out if chosen else ():
            if sol is not None:
                sol.info["time_scale_chosen"] = f"'potential': {chosen}"
                sol.info["solve_time"] = sol.info.get("solve_time", 0.0) + spent
        if problem is None and stop is None:
            return out
        # a scale that stopped the time says so, rather than the march's projection it led to
        error = ConfigError(problem + "; the solution computed so far: the error's .partial" if problem else str(stop))
        error.partial = out
        raise error from None

    def _solve_rows(self, system: HamiltonianSystem, z0s: np.ndarray, t0: float, T: float,
                    progress: Callable[[float], None] | None, until: int | None = None,
                    watch: ScaleWatch | None = None) -> list[PolynomialSolution]:
        """``solve_batch`` in the march's own time, or (``until``: the index of t in the
        extended state) in τ until t reaches T; ``watch``: the default's, which raises
        :class:`ScaleVaries` where the march in t should be one in τ."""
        b, n = z0s.shape
        # a batch padded to 8, 16, 32 … members (copies of the first, already at T, dropped): a few
        # compiled programs rather than one per batch size
        padded = b if b == 1 else bucket_size(b)
        per_window = 8 * (self.stage_count + 3) * n + 24
        chunk = int(min(self.chunk, max(16, _CHUNK_BYTES // (padded * per_window))))
        settings = dict(stages=self.stage_count, steps=self.steps, chunk=chunk, max_iterations=self.max_iterations,
                        growth=self.growth, safety=self.safety, warmup=self.warmup, max_rejects=self.max_rejects,
                        members=padded, until=until)
        # Newton's iteration by default: compiled only once a window needs it (NEWTON_LATER)
        later = self.newton is None and self.newton_for(n)
        program = compiled_gauss_march(system, newton=NEWTON_LATER if later else self.newton_for(n), **settings)
        with_newton = (lambda: compiled_gauss_march(system, newton=True, **settings)) if later else None
        started = time.perf_counter()
        # the padding members start at T: nothing to march
        starts = np.concatenate([np.full(b, float(t0)), np.full(padded - b, float(T))])
        padding = np.repeat(z0s[:1], padded - b, axis=0)
        if until is not None:
            padding[:, until] = float(T)
        rows, state, first_call, stopped = self._march(program, np.concatenate([z0s, padding]), starts, T, progress,
                                                       2 * per_window, until, watch, with_newton)
        wall = time.perf_counter() - started
        out, problem = [], None
        for m in range(b):
            start, length, z, e, L, ratio = (np.concatenate([r[i][m] for r in rows]) for i in range(6))
            end, failed = float(clock(state, until)[m]), int(state.failed[m])
            info = {"solver": self.name, "settings": self.settings(), "stages": self.stage_count, "order": self.order,
                    "windows": int(start.size),
                    "rejected": int(state.rejected[m]), "iterations": int(state.iterations[m]),
                    "newton_windows": int(state.newton[m]), "check_worst": float(state.worst[m]),
                    "h_min": float(length.min(initial=math.inf)), "h_max": float(length.max(initial=0.0)),
                    "solve_time": wall, "first_call_time": first_call, "batch": b}
            if failed or start.size == 0 or end < T:
                if watch is not None and (stopped is not None or failed in (1, 2)):
                    raise ScaleVaries(f"the march in t stopped at t = {readable_times(end)[0]} (windows a close "
                                      "encounter shortened)")
                problem = problem or self._stopped_line(m, b, end, t0, T, stopped, failed, z0s[m],
                                                        system.linear_part is not None,
                                                        diverging(system, z0s[m], np.asarray(state.z[m])),
                                                        until is None and potential_applies(system, z0s[m]))
                # what was computed up to the stop is kept: the error's .partial
                out.append(self._solution(system, np.append(start, state.t[m]), length, z, e, L, ratio, info)
                           if start.size else None)
                continue
            advice = None if until is not None or self.steps != "constant" or self.h is not None else \
                march_advice(system, length, z, self.warmup)
            out.append(self._solution(system, np.append(start, state.t[m]), length, z, e, L, ratio,
                                      {**info, **({"advice": advice} if advice else {})}))
        if problem is not None:
            kept = any(part is not None for part in out)
            error = ConfigError(problem + ("; the solution" + ("s" if b > 1 else "") + " computed so far: the error's "
                                           ".partial" if kept else ""))
            error.partial = out
            raise error
        return out

    def _stopped_line(self, m: int, b: int, end: float, t0: float, T: float, stopped: str | None, failed: int,
                      z0: np.ndarray, linear: bool = False, diverging: str | None = None,
                      gravitational: bool = False) -> str:
        """Why member m stopped (``stopped``: the host's reason, else the program's code ``failed``),
        and the remedy for that reason (``linear``: the system declares a linear part;
        ``diverging``: what :func:`diverging` found of the field just past the stop; ``gravitational``:
        ``time_scale="potential"`` suits the system, the remedy for windows a close encounter shrank)."""
        who = "the Gauss march" + ("" if b == 1 else f" of member {m}")
        if failed == 4:
            return (f"{who} cannot start: the vector field J∇H is not finite at z0 = {np.asarray(z0).tolist()} "
                    "(a NaN or an infinity in H or its gradient there); check H and z0")
        if diverging is not None and stopped is None and failed in (1, 3):
            at, start, stop = readable_times(end, t0, T)
            return f"{who} stopped at t = {at} of [{start}, {stop}]: {diverging}; check H there"
        why = stopped or FAILURES.get(failed, "the march stopped")
        default_iterations = type(self).__dataclass_fields__["max_iterations"].default
        if gravitational and self.time_scale in (None, AUTO) and (stopped is not None or failed in (1, 2)):
            remedy = ("a close encounter shortened the windows: time_scale='potential' marches it on windows short "
                      "only there, symplectic (docs/howto/CLOSE_ENCOUNTERS.md)")
        elif stopped is not None and stopped.startswith("t advanced"):
            remedy = "give a time scale g(q, p) that stays positive, not near 0, wherever the orbit goes"
        elif stopped is not None and stopped.startswith("its constant window"):
            remedy = ("smooth H there (|q| → √(q² + ε²)) or solve piecewise between the crossings; steps='adaptive' "
                      "passes a kink, but not to the tolerance (docs/SOLVER.md, 'Non-smooth Hamiltonians')")
        elif stopped is not None:
            remedy = "shorten the interval, loosen the tolerance or give a longer h"
        elif failed == 1:
            remedy = (f"times near t = {readable_times(end)[0]} are float64 numbers {np.spacing(abs(end)):.3g} apart, "
                      "which the lengths the tolerance asks for come down to: give h (a window length well above "
                      "that), or start the interval nearer 0 (H does not depend on t)")
        elif failed == 3 and self.max_iterations < default_iterations:
            remedy = f"raise max_iterations ({self.max_iterations}; the default is {default_iterations})"
        elif failed == 3 and linear:
            why = "the stage equations did not converge (Newton's iteration with the declared linear_part failed)"
            remedy = ("try a shorter h" if self.h else "loosen the tolerance") + \
                ", or declare in linear_part more of H's stiff quadratic part"
        elif failed == 3 and not self.newton_for(np.asarray(z0).size):
            off = "newton=False" if self.newton is False else \
                f"Newton is off by default above {NEWTON_AUTO_SIZE} components"
            why = f"the stage equations did not converge (the fixed-point iteration failed; {off})"
            remedy = "set newton=True (Newton's iteration solves such windows)" + (" or try a shorter h" if self.h
                                                                                   else "")
        elif self.h is not None:
            remedy = "try a shorter h"
        else:
            remedy = "loosen the tolerance, or the system may be singular there"
        at, start, stop = readable_times(end, t0, T)
        return f"{who} stopped at t = {at} of [{start}, {stop}]: {why} (rtol={self.rtol:g}, atol={self.atol:g}, " \
               f"h={self.h}); {remedy}"

    def _march(self, program, z0s, starts, T, progress, window_bytes, until=None, watch=None, with_newton=None):
        """Call the compiled program until every member reaches T (its time, or component ``until``
        of its state) or fails: the accepted windows per call (each (B, ...) cut to the member's
        count), the final state, the first call's time, and why the march was stopped early (None:
        it was not) — windows that collapsed (:func:`collapsed`) or would not fit in memory.
        ``watch`` sees each call's window starts and, where a march not yet done should be one in
        τ, raises :class:`ScaleVaries`. ``with_newton``: the program with Newton's iteration, for
        the rest of the march once a window needs it."""
        b, t0 = len(z0s), float(np.min(starts))
        counts, room, longest, before = np.zeros(b), False, np.zeros(b), np.asarray(starts, np.float64)  # the memory available: read once a second call is needed
        stacked = [initial_state(z, t, self.stage_count) for z, t in zip(z0s, starts)]
        state = GaussState(*(np.array(x) for x in zip(*stacked)))  # not np.stack: its checks, 14 times a call
        args = tuple(np.float64(x) for x in (T, self.rtol, self.atol, self.h or 0.0))
        rows, first_call = [], 0.0
        # the windows a call may take: all the chunk holds, or for a watched march WATCH_FIRST, then twice as
        # many each call (it is seen soon, and at most about twice what showed g varying is thrown away)
        limit = WATCH_FIRST if watch is not None else math.inf
        with jax.enable_x64(True):
            while True:
                tic = time.perf_counter()
                out = to_host(program(state, *args, np.float64(min(limit, 2**30))))
                limit *= 2
                if not rows:  # the first call compiles (or loads from the cache) and runs
                    first_call = time.perf_counter() - tic
                state = out.state
                kept = np.asarray(out.kept, bool)
                rows.append([[np.asarray(x)[m][kept[m]] for m in range(b)] for x in out[1:-1]])
                t_now, failed = np.asarray(clock(state, until)), np.asarray(state.failed)
                if watch is not None and np.any(failed[:len(watch.off)] == 5):
                    # a close approach in t: the march in τ takes it without Newton (and its program in t)
                    raise ScaleVaries(f"a window in t near t = {readable_times(float(t_now.min()))[0]} needed Newton's "
                                      "iteration (a close approach)")
                if with_newton is not None and np.any(failed == 5):  # a window needs Newton: the program with it
                    program, with_newton, failed = with_newton(), None, np.where(failed == 5, 0, failed)
                    state = state._replace(failed=failed.astype(state.failed.dtype))
                if watch is not None and not np.all(t_now[:len(watch.off)] >= T):
                    for m in range(len(watch.off)):
                        watch.see(m, rows[-1][2][m])
                    if (reason := watch.reason()) is not None:
                        raise ScaleVaries(reason)
                if progress is not None:
                    progress(min(1.0, float(t_now.min() - t0) / (T - t0)))
                if np.all((t_now >= T) | (failed != 0)):
                    break
                counts += kept.sum(axis=1)
                if until is None:  # the lengths in t
                    current = np.asarray(state.h)
                    longest = np.maximum(longest, [np.max(x, initial=0.0) for x in rows[-1][1]])
                else:  # in τ: how far t moved per window over this call
                    current = (t_now - before) / np.maximum(kept.sum(axis=1), 1)
                    longest, before = np.maximum(longest, current), t_now
                if (collapse := collapsed(longest, current, t_now, T, failed, until,
                                          constant=self.steps == "constant" and self.h is None)) is not None:
                    return rows, state, first_call, collapse
                done = np.clip((t_now - starts) / np.maximum(T - starts, 1e-300), 1e-300, 1.0)
                projected = float(np.sum(np.where(starts < T, counts / done, 0.0)))
                room = available_memory() if room is False else room
                if room is not None and projected * window_bytes > room:
                    return rows, state, first_call, (
                        f"it would need about {projected:.3g} windows ({projected * window_bytes / 2**30:.3g} GiB) "
                        f"to reach T, more than the {room / 2**30:.3g} GiB of memory available")
        return rows, state, first_call, None

    # ------------------------------------------------------------------ the solution
    def _solution(self, system, edges, lengths, z, e, L, ratio, info) -> PolynomialSolution:
        keep = self.keep if self.keep is not None else L.nbytes <= KEEP_BYTES
        sol = PolynomialSolution(system, edges, z, e, L if keep else None, self.stage_count, ratio, info,
                                 resolve=None if keep else self.resolver(system), offsets=edge_offsets(edges, lengths))
        sol.estimator = lambda start=None: self.companion(sol, start)
        return sol

    def resolver(self, system):
        """``resolve(z, e, h) -> L``: windows solved again from their starts (from a guess of
        constant rate: the same equations, the same polynomial to round-off), in blocks padded to
        8, 16, … 4 096 windows (padded to 4 096 always, five windows of a wide NLS took 50 s)."""
        windows = compiled_gauss_windows(system, stages=self.stage_count, max_iterations=self.max_iterations,
                                         newton=self.newton_for(system.state_dim))

        def resolve(z, e, h):
            out = []
            with jax.enable_x64(True):
                for a in range(0, len(h), _REPLAY_CHUNK):
                    piece = slice(a, a + _REPLAY_CHUNK)
                    m = len(h[piece])
                    pad = lambda x: np.concatenate([x, np.repeat(x[:1], bucket_size(m) - m, axis=0)])  # noqa: E731
                    out.append(np.asarray(windows(pad(z[piece]), pad(e[piece]), pad(h[piece])))[:m])
            return np.concatenate(out)

        return resolve

    def companion(self, sol: PolynomialSolution, start: np.ndarray | None = None) -> PolynomialSolution:
        """The same method over the same interval on windows half as long, from ``start`` (default
        sol.z0): the reference of the error estimate (``atlasnn.solutions._polynomial``)."""
        starts, lengths = sol.edges[:-1] + sol.offsets[:-1], sol.lengths
        halves = np.repeat(0.5 * lengths, 2)
        edges = np.append(np.stack([starts, starts + 0.5 * lengths], axis=1).reshape(-1), sol.edges[-1])
        replay = compiled_gauss_replay(sol.system, stages=self.stage_count, max_iterations=self.max_iterations,
                                       newton=self.newton_for(sol.system.state_dim))
        z0 = sol.z0 if start is None else np.asarray(start, np.float64)
        state = ReplayState(z0, np.zeros_like(z0), np.float64(0.0), np.zeros((self.stage_count, z0.size)), np.int64(0))
        zs, es, Ls = [], [], []
        with jax.enable_x64(True):
            for a in range(0, halves.size, _REPLAY_CHUNK):
                part = np.zeros(_REPLAY_CHUNK)
                piece = halves[a:a + _REPLAY_CHUNK]
                part[:piece.size] = piece
                state, (z, e, L) = to_host(replay(state, part))
                zs.append(np.asarray(z)[:piece.size])
                es.append(np.asarray(e)[:piece.size])
                Ls.append(np.asarray(L)[:piece.size])
        if int(state.failed):
            raise ConfigError("the error estimate's companion solution did not converge on windows half as long")
        L = np.concatenate(Ls)
        keep = sol.L is not None
        return PolynomialSolution(sol.system, edges, np.concatenate(zs), np.concatenate(es), L if keep else None,
                                  self.stage_count, None, {"companion_of": sol.info.get("solver")}, outside="allow",
                                  resolve=None if keep else self.resolver(sol.system),
                                  offsets=sol.offsets[0] + edge_offsets(edges, halves))


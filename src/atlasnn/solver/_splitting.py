"""Explicit splitting and composition methods for separable Hamiltonians H = T(p) + V(q):
:class:`SplittingComposition`, beside the Gauss solver.

Each step is a composition of the exact flows of T and V (drifts and kicks) with the coefficients
of a published scheme (:mod:`atlasnn.solutions._splitting_tables`): explicit, symplectic and
(for the symmetric schemes) time-reversible, of order 2 to 10. The step is constant over the
interval (so the method stays symplectic), set from the tolerance by a pilot
(:mod:`._splitting_march`), or given. The solution is a
:class:`~atlasnn.solutions.SplittingSolution`: dense output by a partial step of the same method,
and an error estimate against a companion with steps half as long.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, fields
from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.limits import available_memory
from atlasnn.solutions import SplittingSolution, TracedSplittingSolution, linear_splitting, splitting_scheme
from atlasnn.solver._base import AbstractSolver, register_solver, solve_one
from atlasnn.solver._collocation import require_float64
from atlasnn.solver._gauss_core import traced_inputs
from atlasnn.solver._splitting_march import compiled_split_march, pilot_step, step_bounds
from atlasnn.systems import HamiltonianSystem

__all__ = ["SplittingComposition", "SCHEME_BY_TOLERANCE", "scheme_for"]

#: the scheme for a tolerance when none is given: the first whose rtol bound the tolerance reaches
#: (benchmarks/splitting_workprecision.py, the schemes for a general T(p) at equal accuracy: Blanes
#: and Moan's order 6 the fastest or within 1.3× of it at 1e-5 and 1e-7 on every problem held by
#: accuracy; Sofroniou and Spaletta's order 10 the fastest at 1e-9 and 1e-11 on Kepler's problem and
#: the chain with energy in every mode, within 1.2× on Hénon–Heiles. Where stability holds the step,
#: REACH_SCHEME is weighed against these.)
SCHEME_BY_TOLERANCE = (("1e-8", "blanes_moan6"), ("0", "sofspa10"))
#: the most memory the kept states of one solution take (past it, fewer are kept and evaluating
#: between them takes more steps)
KEEP_BYTES = 256 << 20
#: the most memory one call's buffer of kept states takes across the members of a batch: the program
#: fills and returns it whole, so a large one is a fixed cost a call (FPUT-β, N = 256: a 4 MiB buffer
#: made each of the pilot's 32-step calls take 1.9 ms, its steps 0.4 ms)
_CHUNK_BYTES = 256 << 10
#: marches at most with a step from the tolerance: each checked against a march with steps twice
#: as long, and shortened where the check finds the error above the tolerance (an orbit reaching
#: faster frequencies, or larger errors, than the pilot's first steps saw)
_TRIES = 4


#: the scheme tried beside the tolerance's where that one is held to its stability limit: the
#: furthest stability limit per force evaluation of the schemes of order 4 and more (0.60·2/ω
#: against Kahan–Li 8's 0.18; ``stability_limit``)
REACH_SCHEME = "mclachlan4"


@dataclass
class _Plan:
    """A march planned: the scheme, its order, its compiled program and buffer, the step count,
    and the pilot's record."""

    scheme: str
    order: int
    program: Any
    chunk: int
    steps: int
    record: dict[str, Any]


def scheme_for(rtol: float) -> str:
    """The scheme :class:`SplittingComposition` takes for ``rtol`` when none is given."""
    return next(name for bound, name in SCHEME_BY_TOLERANCE if rtol >= float(bound))


def _positive(name: str, value: Any, kind: type = float) -> Any:
    ok = not isinstance(value, bool) and isinstance(value, (int, np.integer) if kind is int else
                                                    (int, float, np.integer, np.floating))
    if not ok or not math.isfinite(float(value)) or value <= 0:
        what = "an integer >= 1" if kind is int else "a finite number > 0"
        raise ConfigError(f"SplittingComposition {name} must be {what}, got {value!r}")
    return kind(value)


@register_solver
@dataclass(frozen=True)
class SplittingComposition(AbstractSolver):
    """An explicit symplectic splitting method for a separable H = T(p) + V(q): each step a
    composition of exact drifts q ← q + c·h·T'(p) and kicks p ← p − c·h·V'(q) with a published
    scheme's coefficients. Symplectic for any step; one constant step over the interval. For a
    system with a ``linear_part`` and its ``nonlinear_flow`` the drift is the linear part's exact
    flow and the kick the rest's: a split-step method (docs/SPLITTING.md).

    Attributes:
        scheme: the scheme's name (``atlasnn.solutions.SPLITTING_SCHEMES``: leapfrog, yoshida4,
            mclachlan4, blanes_moan6, kahan_li8, sofspa10, …); None: chosen from rtol
            (``SCHEME_BY_TOLERANCE``), and where stability rather than accuracy holds the step,
            weighed against ``REACH_SCHEME`` (``info["scheme_choice"]``).
        rtol: relative tolerance: the error over the whole interval within atol + rtol·max|z|,
            per component: a pilot sets the step, a march with longer steps checks the march
            afterwards (``info["check"]``, in tolerances), and a march whose check fails is done
            again with shorter steps.
        atol: absolute tolerance (see rtol).
        h: a step to use throughout (rounded so that whole steps reach T); tolerances then unused.
        steps: the number of steps over the interval (instead of h). Inside ``jax.jit``,
            ``jax.grad`` or ``jax.vmap`` the step count must be known before the trace: give it here.
        chunk: kept states per call of the compiled program (progress is reported between calls).
    """

    name: ClassVar[str] = "splitting"
    tightest: ClassVar[float] = 1e-16

    scheme: str | None = None
    rtol: float = 1e-11
    atol: float = 1e-13
    h: float | None = None
    steps: int | None = None
    chunk: int = 1024

    def __post_init__(self) -> None:
        if self.scheme is not None:
            splitting_scheme(self.scheme)  # an unknown name: one line naming the choices
        self.check_tolerances()
        if self.h is not None:
            object.__setattr__(self, "h", _positive("h", self.h))
        if self.steps is not None:
            object.__setattr__(self, "steps", _positive("steps", self.steps, int))
        if self.h is not None and self.steps is not None:
            raise ConfigError("SplittingComposition takes h or steps, not both")
        _positive("chunk", self.chunk, int)

    @property
    def scheme_name(self) -> str:
        """The scheme used: ``scheme``, or the one chosen from rtol."""
        return self.scheme if self.scheme is not None else scheme_for(self.rtol)

    @property
    def order(self) -> int:
        return splitting_scheme(self.scheme_name).order

    def settings(self) -> dict[str, Any]:
        """The settings as a JSON-able dict (what a record keeps)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    # ------------------------------------------------------------------ solving
    def solve(self, system: HamiltonianSystem, z0: np.ndarray, t0: float, T: float, *,
              progress: Callable[[float], None] | None = None) -> SplittingSolution:
        return solve_one(self.solve_batch, system, z0, t0, T, progress)

    def solve_batch(self, system: HamiltonianSystem, z0s: np.ndarray, t0: float, T: float, *,
                    progress: Callable[[float], None] | None = None) -> list[SplittingSolution]:
        """One solution per row of ``z0s`` (shape (B, 2d)), all with the step the tolerance asks of
        the hardest member, marched by one compiled program."""
        _check_system(system)
        z0s = np.atleast_2d(np.asarray(z0s, np.float64))
        if self.scheme is not None and splitting_scheme(self.scheme).nystrom:
            _check_quadratic_kinetic(system, z0s[0], self.scheme)
        tic = time.perf_counter()
        plan = self._plan(system, z0s, T - t0)
        pilot_time = time.perf_counter() - tic
        zs, es, kept, steps = self._marched(system, z0s, t0, T, plan, progress)
        h = (T - t0) / steps
        info = {"solver": self.name, "settings": self.settings(), "scheme": plan.scheme,
                "order": splitting_scheme(plan.scheme).order, "stages": _kicks(plan.scheme), "windows": steps,
                "steps": steps, "h": h, "solve_time": time.perf_counter() - tic, "pilot_time": pilot_time,
                "batch": len(z0s), **plan.record}
        out = []
        for m in range(len(z0s)):
            sol = SplittingSolution(system, plan.scheme, t0, h, steps, kept, zs[:, m], es[:, m], dict(info))
            sol.estimator = functools.partial(self.companion, sol)
            if not np.all(np.isfinite(sol.end_state)):
                error = ConfigError(f"the splitting march{'' if len(z0s) == 1 else f' of member {m}'} blew up (a "
                                    f"state that is not finite) with h = {h:.3g}: give a smaller h or a tighter "
                                    "tolerance, or use GaussCollocation")
                error.partial = sol
                raise error
            out.append(sol)
        return out

    def _marched(self, system, z0s: np.ndarray, t0: float, T: float, plan: "_Plan",
                 progress: Callable[[float], None] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """The march of the plan's steps — with a step from the tolerance, checked
        (:meth:`_check`) and marched again with shorter steps where the check finds the error
        above the tolerance: the kept states, compensations, their indices and the step count."""
        given, steps, order = self.h is not None or self.steps is not None, plan.steps, plan.order
        for attempt in range(1, _TRIES + 1):
            steps += 0 if given else -steps % 4  # a multiple of 4: the check's march takes 1/2 or 3/4 as many
            every = max(1, math.ceil(steps * 16 * z0s.shape[1] / KEEP_BYTES))
            zs, es, kept = march(plan.program, z0s, (T - t0) / steps, steps, every, plan.chunk, progress)
            if given:
                break
            ratio = self._check(system, plan, z0s, t0, T, steps, (zs, es, kept))
            plan.record.update(check=ratio, tries=attempt)
            if ratio <= 1.0:
                break
            if attempt == _TRIES:  # what was marched is kept (the error's .partial); it is not passed off as met
                raise _unmet(system, plan.scheme, ratio, attempt, SplittingSolution(
                    system, plan.scheme, t0, (T - t0) / steps, steps, kept, zs[:, 0], es[:, 0], dict(plan.record)))
            # the error over the tolerance: the step it asks for, with room (at most 16 times shorter a try)
            shrink = (0.5 / ratio) ** (1.0 / order) if math.isfinite(ratio) else 0.5
            steps = math.ceil(steps / min(max(shrink, 1 / 16), 0.8))
        return zs, es, kept, steps

    def _check(self, system, plan: "_Plan", z0s: np.ndarray, t0: float, T: float, steps: int, fine: tuple) -> float:
        """The error of a march of ``steps`` steps (``fine``: its kept states, compensations and
        indices) over the tolerance, at the most of 16 times and the members: against the same
        scheme with steps r = 2 times as long (4/3 where the step is near the stability limit)
        (Richardson: the difference over r^p − 1), or where that march is not stable, half as long
        (the difference times 2^p/(2^p − 1))."""
        zs, es, kept = fine
        limited = plan.record.get("limited_by") == "stability"
        r, p = (4 / 3 if limited else 2.0), 2.0 ** plan.order
        for factor, weight in ((r, 1.0 / (r ** plan.order - 1.0)), (0.5, p / (p - 1.0))):
            n = int(round(steps / factor))
            h = (T - t0) / n
            every = -(-n // 15)  # at most 15 times between t0 and T: one small call of the dense output
            other, other_e, marks = march(plan.program, z0s, h, n, every, plan.chunk, None)
            if np.all(np.isfinite(other)) or factor == 0.5:
                break
        t = t0 + marks * h
        worst = 0.0
        for m in range(z0s.shape[0]):
            sol = SplittingSolution(system, plan.scheme, t0, (T - t0) / steps, steps, kept, zs[:, m], es[:, m])
            mine = sol(t)
            gap = np.abs((other[:, m] + other_e[:, m]) - mine) * weight
            scale = self.atol + self.rtol * np.abs(mine).max()
            worst = max(worst, float(gap.max() / scale) if np.all(np.isfinite(gap)) else math.inf)
        return worst

    def _plan(self, system: HamiltonianSystem, z0s: np.ndarray, span: float) -> "_Plan":
        """The scheme, its program and the number of steps over ``span``: ``steps``, from ``h``,
        or from the tolerance by the pilot. With no scheme given, where the tolerance's scheme is
        held to its stability limit (a step far below the one its accuracy allows), the scheme
        that reaches furthest per force evaluation (``REACH_SCHEME``) is tried too and the one that
        costs fewer evaluations over the interval taken (``info["scheme_choice"]``)."""
        chunk = int(min(self.chunk, max(16, _CHUNK_BYTES // (16 * z0s.size))))
        first = self._pilot(system, z0s, span, self.scheme_name, chunk)
        if self.scheme is not None or self.h is not None or self.steps is not None \
                or first.record.get("limited_by") != "stability" or self.scheme_name == REACH_SCHEME:
            return first
        other = self._pilot(system, z0s, span, REACH_SCHEME, chunk)
        costs = {plan.scheme: plan.steps * _kicks(plan.scheme) for plan in (first, other)}
        best = min((first, other), key=lambda plan: costs[plan.scheme])
        best.record["scheme_choice"] = {name: int(c) for name, c in costs.items()}
        return best

    def _pilot(self, system, z0s: np.ndarray, span: float, scheme: str, chunk: int) -> "_Plan":
        program = compiled_split_march(system, scheme, chunk, len(z0s))
        sch = splitting_scheme(scheme)
        if self.steps is not None:
            return _Plan(scheme, sch.order, program, chunk, self.steps, {})
        if self.h is not None:
            return _Plan(scheme, sch.order, program, chunk, max(1, round(span / self.h)), {})
        guess, largest = step_bounds(system, z0s, span, sch)
        h, record = pilot_step(program, z0s, span, sch.order, self.rtol, self.atol, guess, largest)
        return _Plan(scheme, sch.order, program, chunk, max(1, math.ceil(span / h)), record)

    def companion(self, sol: SplittingSolution) -> SplittingSolution:
        """The same scheme over the same interval with steps half as long, keeping its states at
        the same times: the reference of the error estimate."""
        n = sol.system.state_dim
        chunk = int(min(self.chunk, max(16, _CHUNK_BYTES // (16 * n))))
        program = compiled_split_march(sol.system, sol.scheme, chunk, 1)
        every = int(sol.kept[1] - sol.kept[0]) if sol.kept.size > 2 else sol.n_steps
        z, e, kept = march(program, sol.z0[None], 0.5 * sol.h, 2 * sol.n_steps, 2 * every, chunk, None)
        return SplittingSolution(sol.system, sol.scheme, sol.t0, 0.5 * sol.h, 2 * sol.n_steps, kept, z[:, 0],
                                 e[:, 0], {"companion_of": self.name}, outside="allow")

    def solve_traced(self, system: HamiltonianSystem, z0: Any, t0: Any, T: Any) -> TracedSplittingSolution:
        """The solution as JAX values (inside ``jax.jit``, ``jax.grad`` or ``jax.vmap``): ``steps``
        steps by a scan, every state kept; differentiable through the scan exactly."""
        if self.steps is None:
            raise ConfigError("inside jit/grad/vmap a SplittingComposition needs steps=N (the step count must be "
                              "known before the trace); or call solve on numbers")
        _check_system(system)
        z0, t0, T = traced_inputs(system, z0, t0, T)
        if system.traced:  # H closes over traced values: they cannot be a compiled program's constants
            return TracedSplittingSolution.march(system, self.scheme_name, z0, t0, T, self.steps)
        return _compiled_march(system, self.scheme_name, z0, t0, T, self.steps)


@eqx.filter_jit
def _compiled_march(system: HamiltonianSystem, scheme: str, z0, t0, T, steps: int) -> TracedSplittingSolution:
    """The traced march compiled once per system, scheme and step count (static): ``jax.grad`` or
    ``jax.vmap`` without an outer ``jax.jit`` reuse it; inside one it is inlined."""
    return TracedSplittingSolution.march(system, scheme, z0, t0, T, steps)


#: a march keeping more than this many bytes first checks the memory left
_READ_MEMORY_ABOVE = 64 << 20


def march(program, z0s: np.ndarray, h: float, steps: int, every: int, chunk: int,
          progress: Callable[[float], None] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``steps`` steps of h from the states ``z0s`` (B, 2d) by the compiled ``program``, keeping the
    state every ``every`` steps and at the end: the kept states (K, B, 2d), their compensations,
    and their step indices (K,)."""
    z, e = z0s, np.zeros_like(z0s)
    zs, es, kept, done = [z0s[None]], [e[None]], [0], 0
    need = (steps // every + 2) * z0s.nbytes * 2
    # the memory left is read only for a large march (reading it costs ~0.2 ms, a tenth of a small solve)
    if need > _READ_MEMORY_ABOVE and (room := available_memory()) is not None and need > room:
        raise ConfigError(f"the splitting march would keep {steps // every} states of {z0s.nbytes} bytes, more "
                          "than the memory available; loosen the tolerance or shorten the interval")
    with jax.enable_x64(True):
        while done < steps:
            slots = min(chunk, (steps - done) // every)
            size = every if slots else steps - done
            slots = max(slots, 1)
            out = program(z, e, np.float64(h), np.int64(size), np.int64(slots))
            z, e = np.asarray(out.z), np.asarray(out.e)
            zs.append(np.asarray(out.zs)[:slots])
            es.append(np.asarray(out.es)[:slots])
            kept.extend(done + size * np.arange(1, slots + 1))
            done += size * slots
            if progress is not None:
                progress(done / steps)
    return np.concatenate(zs), np.concatenate(es), np.asarray(kept, np.int64)


def _check_quadratic_kinetic(system: HamiltonianSystem, z0: np.ndarray, scheme: str) -> None:
    """Refuse a Nyström scheme (its order holds only for T quadratic in p) where T is not: the
    Hessian of H in p, applied to a random vector, differs between z0's p and a point beside it."""
    d = system.dim
    if linear_splitting(system):
        raise ConfigError(f"the scheme {scheme!r} keeps its order only for H = T(p) + V(q) with T quadratic in p, "
                          "not for a linear part's flow composed with the rest's; choose a scheme for any T, "
                          "e.g. blanes_moan6 or sofspa10")
    rng = np.random.default_rng(0)
    v, shift = rng.standard_normal(d), rng.standard_normal(d)
    q0, p0 = z0[:d], z0[d:]
    with jax.enable_x64(True):
        rate = lambda p: jax.jvp(lambda pp: system.dH_dp(q0, pp), (p,), (v,))[1]  # noqa: E731
        a, b = np.asarray(rate(p0)), np.asarray(rate(p0 + shift * (1.0 + np.abs(p0))))
    if not np.allclose(a, b, rtol=1e-10, atol=1e-12 * (1.0 + np.abs(a).max())):
        raise ConfigError(f"the scheme {scheme!r} keeps its order only for T quadratic in p, and T(p) of system "
                          f"{system.name!r} is not (its Hessian varies with p): choose a scheme for any T, e.g. "
                          "blanes_moan6 or sofspa10 (or none: the tolerance picks one)")


def _unmet(system: HamiltonianSystem, scheme: str, ratio: float, tries: int, partial: SplittingSolution) -> ConfigError:
    """The one-line error of a march whose check still finds the error above the tolerance after
    its last try, with what was marched as ``.partial``."""
    error = ConfigError(f"the splitting march ({scheme}) did not meet the tolerance in {tries} tries (its check "
                        f"says {ratio:.3g}× it): the error does not fall with the step as the scheme's order says — "
                        f"is H = T(p) + V(q) as declared (system {system.name!r})? Use GaussCollocation for any H; "
                        "the march computed so far: the error's .partial")
    error.partial = partial
    return error


def _kicks(scheme: str) -> int:
    """Force evaluations a step of the scheme."""
    return splitting_scheme(scheme).forces


def _check_system(system: HamiltonianSystem) -> None:
    require_float64(system)
    if linear_splitting(system):
        return
    if system.linear_part is not None:
        raise ConfigError(f"SplittingComposition splits a system with a linear_part into the linear part's flow and "
                          f"the rest's, which system {system.name!r} does not declare (nonlinear_flow); declare it, "
                          "or use GaussCollocation, which solves the linear part exactly in its stage equations")
    system.require_separable("SplittingComposition")

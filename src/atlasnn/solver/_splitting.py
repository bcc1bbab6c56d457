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
from atlasnn.solutions import (SplittingSolution, TracedSplittingSolution, linear_splitting, splitting_scheme,
                               stability_limit)
from atlasnn.solver._base import AbstractSolver, register_solver, solve_one
from atlasnn.solver._collocation import require_float64
from atlasnn.solver._gauss_core import traced_inputs
from atlasnn.solver._splitting_march import (PILOT_CHUNK, PILOT_STEPS, PILOT_TRIES, PilotMarches, batch_frequency,
                                             compiled_split_march, march, pilot_step, step_bounds)
from atlasnn.systems import HamiltonianSystem

__all__ = ["SplittingComposition", "SCHEME_BY_TOLERANCE", "scheme_for"]

#: the scheme for a tolerance when none is given: the first whose rtol bound the tolerance reaches
#: (benchmarks/splitting_workprecision.py, the schemes for a general T(p) at equal accuracy: Blanes
#: and Moan's order 6 the fastest or within 1.3× of it at 1e-5 and 1e-7 on every problem held by
#: accuracy; Sofroniou and Spaletta's order 10 the fastest at 1e-9 and 1e-11 on Kepler's problem and
#: the chain with energy in every mode, within 1.2× on Hénon–Heiles. Where stability holds the step,
#: the schemes of REACH_LADDER are weighed against these.)
SCHEME_BY_TOLERANCE = (("1e-8", "blanes_moan6"), ("0", "sofspa10"))
#: the most memory the kept states of one solution take (past it, fewer are kept and evaluating
#: between them takes more steps)
KEEP_BYTES = 256 << 20
#: the most memory one call's buffer of kept states takes across the members of a batch, in the
#: march that keeps them: the program fills and returns it whole, a fixed cost a call (FPUT-β,
#: N = 1 024: a 16 MiB buffer cost 2.2 ms a call), and each call is a fixed cost too (there, 228
#: steps kept in calls of 16 states took 10.4 ms, in calls of 256 states 7.5 ms, in one block 5.1)
_CHUNK_BYTES = 4 << 20
#: marches at most with a step from the tolerance: each checked against a march with longer
#: steps, and shortened where the check finds the error above the tolerance (an orbit reaching
#: faster frequencies, or larger errors, than the pilot's first steps saw)
_TRIES = 4
#: the check's step over the march's, a/b: twice as long, or where the step is held by stability
#: 7/8 (a march with steps longer than one held at the stability limit is not safe: on FPUT-β
#: N = 256, 4/3 and 8/7 times the step both blew up, and the check fell back to half steps, twice
#: the march's cost); the march's step count a multiple of a, so that every b-th step of the
#: check lands on a step of the march
_CHECK_RATIO = (2, 1)
_CHECK_RATIO_LIMITED = (7, 8)
#: the check's times at most (step points of both marches, so no partial step: more cost only a
#: row of the buffer each; a chain of random masses and springs whose error reached 1.4 of the
#: tolerance read 0.72 of it at 15 times, 0.80 at 60: the rest is Richardson's order not yet
#: holding at that step, which ``estimate()``, against half steps, reads within 13 %)
_CHECK_TIMES = 60


#: the schemes probed at their stability limits when none is given, in order of their cost per
#: unit of h·ω at that limit (force evaluations over the limit x*: McLachlan 4 1.66, Blanes–Moan 6
#: 3.19, Sofroniou–Spaletta 10 11.1; ``stability_limit``), those cheaper there than the
#: tolerance's scheme: where stability holds the step, the first that meets the tolerance at its
#: limit is the cheapest (on FPUT-β, N = 256, at rtol 1e-11, Blanes–Moan 6 at its limit took 2 170
#: force evaluations, where McLachlan's scheme, held there by accuracy, took 3 900 and the
#: tolerance's Sofroniou–Spaletta 10 takes 35 a step at about the same stable step)
REACH_LADDER = ("mclachlan4", "blanes_moan6", "sofspa10")


@dataclass
class _Plan:
    """A march planned: the scheme, its order, the compiled program of the pilot and the check
    (a small buffer), the step count, and the pilot's record."""

    scheme: str
    order: int
    program: Any
    steps: int
    record: dict[str, Any]
    settled: bool = True  # whether the pilot found a step (not only its last try)
    omega: float | None = None  # the fastest linearised frequency the pilot's step bounds took
    largest: float = math.inf  # the largest stable step (``step_bounds``)
    marches: PilotMarches | None = None  # the pilot's two marches, where they covered the interval

    def check_ratio(self, step: float) -> tuple[int, int]:
        """The check's step over the march's ``step``, as (a, b) (``_CHECK_RATIO``): 7/8 where
        stability held the step, or where twice the step would pass the largest stable one."""
        limited = self.record.get("limited_by") == "stability" or 2.0 * step > self.largest
        return _CHECK_RATIO_LIMITED if limited else _CHECK_RATIO


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
            weighed against those of ``REACH_LADDER`` (``info["scheme_choice"]``).
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
        zs, es, kept, steps, plan = self._marched(system, z0s, t0, T, plan, progress)
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
                 progress: Callable[[float], None] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, "_Plan"]:
        """The march of the plan's steps — with a step from the tolerance, checked
        (:meth:`_check`) and marched again with shorter steps where the check finds the error
        above the tolerance (:meth:`_retry`): the kept states, compensations, their indices, the
        step count and the plan marched."""
        given, steps = self.h is not None or self.steps is not None, plan.steps
        for attempt in range(1, _TRIES + 1):
            ab = plan.check_ratio((T - t0) / steps)
            steps += 0 if given else -steps % ab[0]  # the check's steps land on the march's
            coarse = None
            if attempt == 1 and not given and _from_pilot(plan, steps, ab):
                # the pilot's march of half steps is this march, or a finer one: taken, and checked
                # against the pilot's other march, as a march with twice its steps would be
                steps, (zs, es, kept), coarse = 2 * PILOT_STEPS, plan.marches.fine, plan.marches.coarse
                plan.record["march_from_pilot"] = True
                if progress is not None:
                    progress(1.0)
            else:
                every = max(1, math.ceil(steps * 8 * z0s.shape[1] / KEEP_BYTES))
                chunk = _chunk(self.chunk, _CHUNK_BYTES, z0s.size, steps // every)
                program = compiled_split_march(system, plan.scheme, chunk, len(z0s))
                zs, es, kept = march(program, z0s, (T - t0) / steps, steps, every, chunk, progress)
                plan.record.pop("march_from_pilot", None)
            if given:
                break
            ratio, check_steps = self._check(system, plan, z0s, t0, T, steps, (zs, es, kept), ab, coarse)
            plan.record.update(check=ratio, check_steps=check_steps, tries=attempt)
            if ratio <= 1.0:
                break
            if attempt == _TRIES:  # what was marched is kept (the error's .partial); it is not passed off as met
                raise _unmet(system, plan.scheme, ratio, attempt, SplittingSolution(
                    system, plan.scheme, t0, (T - t0) / steps, steps, kept, zs[:, 0], es[:, 0], dict(plan.record)))
            plan, steps = self._retry(system, z0s, T - t0, plan, steps, ratio, last=attempt == _TRIES - 1)
        return zs, es, kept, steps, plan

    def _retry(self, system, z0s: np.ndarray, span: float, plan: "_Plan", steps: int,
               ratio: float, last: bool = False) -> tuple["_Plan", int]:
        """The plan and step count of the next try after a check found the error ``ratio`` times
        the tolerance: the step that error asks of the same scheme (with room; at most 16 times
        shorter a try). Where that scheme was taken for its reach at the stability limit, with no
        scheme given, accuracy holds the step after all: the tolerance's scheme (of higher order)
        is piloted too, its pilot's error grown as the check found the reach scheme's grown over
        its pilot's, to the power of the orders' ratio (the orbit reached faster frequencies than
        the pilots' first steps showed: an error of order p grows as the p-th power of the
        frequency), and the scheme of fewer force evaluations taken (``info["retry_choice"]``) —
        never with a longer step than the one that failed (a march that blew up before may have led to it), and
        not for the ``last`` try (a Toda lattice's shock: switched with a longer step on the last
        try, the march failed where the same scheme's shorter step met the tolerance)."""
        shrink = (0.5 / ratio) ** (1.0 / plan.order) if math.isfinite(ratio) else 0.5
        same = math.ceil(steps / min(max(shrink, 1 / 16), 0.8))
        if self.scheme is not None or plan.scheme == self.scheme_name or not math.isfinite(ratio) \
                or last or plan.omega is None or "pilot_span" not in plan.record:
            return plan, same
        rec = plan.record
        # the check's error over what the reach scheme's pilot foresaw at this step
        foreseen = rec["pilot_error"] * span / rec["pilot_span"] * (span / steps / rec["pilot_h"]) ** plan.order
        growth = ratio / max(foreseen, 1e-300)
        other = self._pilot(system, z0s, span, self.scheme_name, plan.omega)
        if not other.settled or "pilot_span" not in other.record or growth <= 1.0:
            return plan, same
        o = other.record
        # the growth as a frequency the pilots did not see: (h·ω)^p error terms grow by g^p for a
        # frequency g times higher, so the other scheme's error by growth^(its order / this one's)
        grown = o["pilot_error"] * span / o["pilot_span"] * growth ** (other.order / plan.order)
        needed = max(other.steps, steps, math.ceil(span / (o["pilot_h"] * (0.5 / grown) ** (1.0 / other.order))))
        costs = {plan.scheme: same * _kicks(plan.scheme), other.scheme: needed * _kicks(other.scheme)}
        plan.record["retry_choice"] = other.record["retry_choice"] = {k: int(v) for k, v in costs.items()}
        if costs[other.scheme] < costs[plan.scheme]:
            other.record.update(tries=rec["tries"], first_check=ratio, first_scheme=plan.scheme)
            return other, needed
        return plan, same

    def _check(self, system, plan: "_Plan", z0s: np.ndarray, t0: float, T: float, steps: int,
               fine: tuple, ab: tuple[int, int], coarse: tuple | None = None) -> tuple[float, int]:
        """The error of a march of ``steps`` steps (``fine``: its kept states, compensations and
        indices) over the tolerance, at the most of ``_CHECK_TIMES`` times and the members, and the steps of the
        march it was checked against: the same scheme with steps r = a/b times as long
        (``ab``, from ``_Plan.check_ratio``; Richardson: the difference over |r^p − 1|), or where that march is
        not stable, half as long (the difference times 2^p/(2^p − 1)). The times are steps of both
        marches: the march's own states are compared, with no partial step. ``coarse``: the march
        of twice the step made already (the pilot's, every state kept), compared at its steps."""
        zs, es, kept = fine
        a, b = ab
        p = 2.0 ** plan.order
        if coarse is not None:
            (other, other_e, marks), n, weight = coarse, steps // 2, 1.0 / (p - 1.0)
        tries = () if coarse is not None else \
            ((steps * b // a, 1.0 / abs((a / b) ** plan.order - 1.0), b), (2 * steps, p / (p - 1.0), 2))
        for n, weight, stride in tries:
            every = stride * -(-n // (_CHECK_TIMES * stride))  # each a step of the march too
            # the pilot's program (calls of PILOT_CHUNK states): no program of its own to compile
            other, other_e, marks = march(plan.program, z0s, (T - t0) / n, n, every, PILOT_CHUNK, None)
            if np.all(np.isfinite(other)) or n == 2 * steps:
                break
        t = t0 + marks * ((T - t0) / n)
        worst = 0.0
        for m in range(z0s.shape[0]):
            sol = SplittingSolution(system, plan.scheme, t0, (T - t0) / steps, steps, kept, zs[:, m], es[:, m])
            mine = sol(t)
            gap = np.abs((other[:, m] + other_e[:, m]) - mine) * weight
            scale = self.atol + self.rtol * np.abs(mine).max()
            worst = max(worst, float(gap.max() / scale) if np.all(np.isfinite(gap)) else math.inf)
        return worst, n

    def _plan(self, system: HamiltonianSystem, z0s: np.ndarray, span: float) -> "_Plan":
        """The scheme, its pilot's program and the number of steps over ``span``: ``steps``, from
        ``h``, or from the tolerance by the pilot. With no scheme given (and T and V split, not a
        linear part's flow), the schemes of ``REACH_LADDER`` cheaper at their stability limits
        than the tolerance's are probed there first (two pilot tries each, cheapest first): the
        first that meets the tolerance at its limit — stability, not accuracy, holds the step — is
        taken, or a scheme probed before it that costs fewer evaluations at the step its accuracy
        asks. Where none does, the tolerance's scheme is piloted, and of it and the probes the one
        that costs fewer evaluations over the interval taken (``info["scheme_choice"]``)."""
        omega = None if self.steps is not None or self.h is not None else batch_frequency(system, z0s)
        if self.scheme is not None or omega is None or linear_splitting(system):
            # (a linear part's flow is exact: its frequencies set no stability limit to reach past)
            return self._pilot(system, z0s, span, self.scheme_name, omega)
        probes: list[_Plan] = []
        for name in (s for s in REACH_LADDER if _reach_cost(s) < _reach_cost(self.scheme_name)):
            probes.append(self._pilot(system, z0s, span, name, omega, from_limit=True))
            if probes[-1].record.get("limited_by") == "stability":
                return _cheapest([p for p in probes if p.settled])
        return _cheapest([self._pilot(system, z0s, span, self.scheme_name, omega)] + [p for p in probes if p.settled])

    def _pilot(self, system, z0s: np.ndarray, span: float, scheme: str, omega: float | None,
               from_limit: bool = False) -> "_Plan":
        program = compiled_split_march(system, scheme, PILOT_CHUNK, len(z0s))
        sch = splitting_scheme(scheme)
        if self.steps is not None:
            return _Plan(scheme, sch.order, program, self.steps, {})
        if self.h is not None:
            return _Plan(scheme, sch.order, program, max(1, round(span / self.h)), {})
        guess, largest = step_bounds(system, omega, span, sch)
        h, record, marches = pilot_step(program, z0s, span, sch.order, self.rtol, self.atol,
                                        min(largest, span / 16) if from_limit else guess, largest,
                                        tries=2 if from_limit else PILOT_TRIES, keep=not from_limit)
        settled = record.pop("settled", True)
        return _Plan(scheme, sch.order, program, max(1, math.ceil(span / h)), record, settled, omega, largest, marches)

    def companion(self, sol: SplittingSolution) -> SplittingSolution:
        """The same scheme over the same interval with steps half as long, keeping its states at
        the same times: the reference of the error estimate."""
        every = int(sol.kept[1] - sol.kept[0]) if sol.kept.size > 2 else sol.n_steps
        chunk = _chunk(self.chunk, _CHUNK_BYTES, sol.system.state_dim, sol.n_steps // every)
        program = compiled_split_march(sol.system, sol.scheme, chunk, 1)
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


def _chunk(most: int, budget: int, size: int, kept: int) -> int:
    """Kept states a call of the march keeping ``kept`` states of ``size`` numbers: the power of 4
    from 16 that holds them all, within ``budget`` bytes and ``most`` (a buffer much longer than
    the march is a fixed cost for nothing: FPUT-β, N = 256, 231 steps kept in a buffer of 1 024
    took 5.4 ms, of 256 2.1 ms; four sizes at most, each a program)."""
    rows = 16
    while rows < kept and rows * 4 * 8 * size <= budget and rows * 4 <= most:
        rows *= 4
    return min(rows, most)


def _from_pilot(plan: "_Plan", steps: int, ab: tuple[int, int]) -> bool:
    """Whether the first march can be the pilot's march of half steps: the pilot covered the
    interval, its half steps are at most the planned step, and the check compares with twice the
    step (not a step held at the stability limit, checked with 7/8 of it)."""
    return plan.marches is not None and steps <= 2 * PILOT_STEPS and ab == _CHECK_RATIO


def _cheapest(plans: list["_Plan"]) -> "_Plan":
    """Of the plans, the one of fewest force evaluations over the interval, with every plan's
    count in its record (``scheme_choice``)."""
    costs = {plan.scheme: plan.steps * _kicks(plan.scheme) for plan in plans}
    best = min(plans, key=lambda plan: costs[plan.scheme])
    best.record["scheme_choice"] = {name: int(c) for name, c in costs.items()}
    return best


def _reach_cost(scheme: str) -> float:
    """Force evaluations per unit of h·ω at the scheme's stability limit: its cost where stability
    holds the step."""
    sch = splitting_scheme(scheme)
    return sch.forces / stability_limit(sch)


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

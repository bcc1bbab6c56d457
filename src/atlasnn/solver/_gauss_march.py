"""The Gauss collocation march as one compiled program: windows in a ``lax.while_loop``, each
solved by :func:`._gauss_step.gauss_step`, its length set by the window's Picard check.

The lengths (``steps``):

* ``"constant"``: one length for the whole march, found over the first ``warmup`` windows (each
  grows or shrinks by the check's error, as an adaptive solver's step does, and the warm-up goes
  on while a window still grows by the most it may) and then kept: a later
  window is only ever shortened, when its check exceeds the tolerance (it is tried again shorter,
  and the shorter length is kept from then on). A method of fixed step is symplectic; a handful of
  shortenings keeps the energy error bounded (each changes the modified Hamiltonian once);
* ``"adaptive"``: every window's length from the previous window's check (grow at most ``growth``,
  shrink at least to half after a rejection): fewer windows where the dynamics has several time
  scales (an eccentric orbit), at the price of exact symplecticity (the energy error can drift);
* a length given by the user (``h``): every window that length, the check only recorded.

A window is accepted when its iteration reached round-off (at a tolerance far above it, its share
of rtol: :func:`._gauss_step.stage_share`) and (unless the length is given) its
check's error bound, times ``safety``, is within atol + rtol·|z| for every component (a tolerance
below round-off counts as round-off). The error is of order s + 1 in h along the window, so the
next length is h · clip(0.9 ε^(−1/(s+1)), 0.2, growth) with ε the bound over the tolerance.

The program marches at most ``chunk`` accepted windows per call (a batch: ``chunk`` tries per member)
and returns them; the caller calls it again from where it stopped (one program serves every
interval, and progress shows between calls).

A march may run until one component of the state, rather than the time it marches in, reaches T
(``until``: that component's index): the time transformation (:mod:`._gauss_time`) marches a
fictitious time τ until the physical time, a component of its extended state, reaches T. No window
is then cut short to land on T (the last one ends past it: every window keeps the one length, and
the map stays symplectic); the first length is the field's, at most the span the component's
rate at the start would take to reach T. Members (initial states) on a leading axis: one
program marches them all, each with windows of its own — on a CPU one after the other, elsewhere
in lock step (every member one try per trip).
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from atlasnn.compile_cache import cpu_loop_options, program_cache
from atlasnn.precision import trace_settings
from atlasnn.solutions import gauss_tableau
from atlasnn.solver._exported import exported_program
from atlasnn.solver._gauss_step import (FIXED_POINT_UNROLL, compensated_add, continued_stages, fixed_point_unroll,
                                        gauss_step, local_error, stage_share, tableau_arrays)

__all__ = ["GaussState", "GaussChunk", "ReplayState", "clock", "marching", "started", "try_window",
           "compiled_gauss_march", "compiled_gauss_replay", "compiled_gauss_windows", "initial_state", "FAILURES",
           "NEWTON_LATER", "STEP_MODES"]

#: the ways window lengths are chosen (module docstring)
STEP_MODES = ("constant", "adaptive")

#: why a march stopped early, by the code in GaussState.failed
FAILURES = {
    1: "the window length fell below round-off of the time",
    2: "windows were rejected too many times in a row",
    3: "the stage equations did not converge (fixed-point and Newton iterations both failed)",
    4: "the vector field J∇H is not finite at the initial state",
    5: "a window's stage equations need Newton's iteration, which this program leaves out",
}
#: ``newton`` of a program that leaves Newton's iteration out until a window needs it: such a
#: window stops the march unchanged (FAILURES[5]) and the host goes on with the program that has
#: it. Most marches never need it, and its branch (the Jacobian, the complex factorisations) is
#: about 40 % of the program's compile time (the outer solar system: 19.1 against 11.7 s cold)
NEWTON_LATER = "later"


class GaussState(NamedTuple):
    """Where a march stands between calls (float64 arrays but for the counters)."""

    t: jax.Array
    te: jax.Array  # the compensation of t's summation
    z: jax.Array
    e: jax.Array  # the compensation of z's summation
    h: jax.Array  # the length the next window tries
    h_prev: jax.Array  # the last accepted window's length (its L_prev continues into the next)
    L_prev: jax.Array  # (s, n)
    accepted: jax.Array
    rejected: jax.Array
    iterations: jax.Array
    newton: jax.Array  # windows solved by the Newton iteration
    failed: jax.Array  # 0 running or done, else a key of FAILURES
    worst: jax.Array  # the largest check ratio among the accepted windows
    settled: jax.Array  # 1 once a constant length is found (then only ever shortened)


class GaussChunk(NamedTuple):
    """``chunk`` rows of windows — whether each was accepted (the others are rejected tries or
    unused rows), starts, lengths, start states and their compensation, stage increments L (s, n),
    check ratios — and the state after them."""

    kept: jax.Array
    start: jax.Array
    length: jax.Array
    z: jax.Array
    e: jax.Array
    L: jax.Array
    ratio: jax.Array
    state: GaussState


def initial_state(z0: np.ndarray, t0: float, stages: int) -> GaussState:
    """The state before the first window (host NumPy arrays); the program sets the first length and
    the first window's guess on its first call (:func:`started`)."""
    z0 = np.asarray(z0, np.float64)
    zero, izero = np.float64(0.0), np.int64(0)
    return GaussState(np.float64(t0), zero, z0, np.zeros_like(z0), zero, zero, np.zeros((stages,) + z0.shape),
                      izero, izero, izero, izero, izero, zero, izero)


def clock(st: GaussState, until: int | None):
    """What a march runs until reaches T: the time it marches in, or component ``until`` of the state."""
    return st.t if until is None else st.z[..., until] + st.e[..., until]


def started(system, tab, st: GaussState, T, h_given, until: int | None = None) -> GaussState:
    """``st`` with its first length and guess where the march has not started (h_prev = 0): the
    given length, else 1/ω with ω the field's fastest frequency at z0 (:func:`_frequency`; at most
    the interval — with ``until``, the span that component's rate at z0 takes to cover what is left
    of it), and a guess of constant rate f(z0), written as a previous window of that length whose
    polynomial is that line. A field that is not finite there fails the march before its first
    window (FAILURES[4])."""

    def start(st):
        omega, f0 = _frequency(system, st.z)
        span = T - st.t if until is None else (T - clock(st, until)) / jnp.maximum(jnp.abs(f0[until]), 1e-300)
        h0 = jnp.where(omega > 0, 1.0 / jnp.where(omega > 0, omega, 1.0), span)
        h0 = jnp.minimum(span, h0)
        h0 = lax.stop_gradient(jnp.where(h_given > 0, h_given, h0))
        failed = jnp.where(jnp.all(jnp.isfinite(f0)), st.failed, 4).astype(st.failed.dtype)
        return st._replace(h=h0, h_prev=h0, L_prev=h0 * tab["b"][:, None] * f0[None, :], failed=failed)

    return lax.cond(st.h_prev > 0, lambda st: st, start, st)


#: the signs of the moves of :func:`field_roundoff` beyond "all one way" and "alternating": fixed
#: draws (any two components move apart in at least one of them with probability 15/16)
_ROUNDOFF_DRAWS = 3


def field_roundoff(field, z):
    """How much the field moves when the state moves by its round-off: the largest change of each
    component of f over moves of z by a few ulps (4 eps|z|: all one way, in alternating directions
    and with signs of a few fixed random draws, so that a difference of two large components is
    moved too — two bodies close together, x_2 − x_3, which the first two moves shift alike). The
    window's check integrates f and so carries h times this: H = p²/2 + (q − c)²/2 at c = 1e6 has
    ṗ of size 1 carrying 1e-10 (an ulp of q), which a tolerance of 1e-13 on p would chase with
    windows ever shorter (13 375 for [0, 10], millions at c = 1e8)."""
    step = 4 * jnp.finfo(z.dtype).eps * jnp.abs(z)
    n = z.shape[-1]
    draws = np.random.default_rng(0).choice([-1.0, 1.0], size=(_ROUNDOFF_DRAWS, n))
    signs = np.concatenate([np.ones((1, n)), np.where(np.arange(n) % 2 == 0, 1.0, -1.0)[None], draws])
    f = field(jnp.concatenate([z[None], z + signs * step]))
    return jnp.max(jnp.abs(f[1:] - f[:1]), axis=0)


#: products with A in :func:`_frequency` (two per power iteration of A²)
_POWER_PRODUCTS = 12


def _frequency(system, z):
    """(ω, f(z)): ω² ≈ the spectral radius of A², A the field's Jacobian at z (for H = T(p) + V(q),
    A²'s eigenvalues are −ω² of the linearised motion whatever the masses and units), by power
    iterations of A² as pairs of products A·v, each a central difference of the field at z ± δv,
    from a start that has a part along every component (one evaluation at two states: one place in
    the program that evaluates the field, where Jacobian–vector products traced it twice more and
    took a quarter of the solar system's compile); and f(z) as the mean of the first pair, which
    needs no copy of the field of its own (nor, as a third state in every pair, twelve more
    evaluations: 10 % of an NLS solve on 512 points). ω only sets the first window's length, which
    the warm-up then adapts: a few digits suffice; f(z) the first guess. With a declared linear
    part, A is the Jacobian of the rest of the field."""
    field = system.vector_field
    linear = getattr(system, "linear_part", None)
    if linear is not None:
        # the stiff linear part is solved exactly in the stage equations and sets no length: the
        # nonlinear part's frequency does (from 1/k_max², the warm-up's windows grew 1.3x each with
        # the check at its round-off floor, and the constant length settled 100x short: NLS, 1 024 points)
        field = lambda x: system.vector_field(x) - jax.vmap(linear.field)(x)  # noqa: E731
    n = z.shape[0]
    v = 1.0 + jnp.arange(n, dtype=z.dtype) / n
    delta = jnp.finfo(z.dtype).eps ** (1 / 3) * (1.0 + jnp.sqrt(jnp.sum(z ** 2)))

    def body(i, carry):
        v, last, growth, f0 = carry
        norm = jnp.sqrt(jnp.sum(v ** 2))
        v = v / jnp.where(norm > 0, norm, 1.0)
        f = field(jnp.stack([z + delta * v, z - delta * v]))
        w = (f[0] - f[1]) / (2 * delta)
        size = jnp.sqrt(jnp.sum(w ** 2))
        # f(z) from the first pair, to O(δ²) (δ² ≈ 4e-11 relative): a guess and a finiteness check
        f0 = jnp.where(i == 0, 0.5 * (f[0] + f[1]), f0)
        return w, size, last * size, f0  # |A²u| = |Av|·|A(Av/|Av|)|: the last two products' sizes

    zero = jnp.zeros((), z.dtype)
    _, _, growth, f0 = lax.fori_loop(0, _POWER_PRODUCTS, body, (v, zero, zero, jnp.zeros_like(z)))
    if linear is not None:
        f0 = f0 + linear.field(z)
    return jnp.where(jnp.isfinite(growth), jnp.sqrt(growth), 0.0), f0


def _window(system, tab, settings, st: GaussState, T, rtol, atol, h_given):
    """Try one window from ``st``: (accepted?, the step's result, its length, its check ratio, the
    next length, whether it is the last window, whether a constant length is settled)."""
    s = tab["b"].shape[0]
    field = system.vector_field
    jac = (lambda x: system.jacobian(x[None])[0]) if settings["newton"] is True else None
    # a window that would end within the round-off of T ends at T (the slack at most a hundredth of
    # the window: 1e-12·|T| alone is 1 at T = 1e12, and a window shortened after a rejection was
    # stretched back to the whole remaining span, rejected again, until the march gave up)
    floor = jnp.minimum(1e-12 * jnp.maximum(jnp.abs(T), 1.0), 0.01 * st.h)
    span = (T - st.t) - st.te
    # with ``until``, T is that component's end: no window is cut to land on it
    last = (st.h >= span - floor) if settings["until"] is None else jnp.asarray(False)
    h = jnp.where(last, span, st.h)
    Y0 = continued_stages(tab, st.z, st.e, st.L_prev, h / st.h_prev)
    # the stage equations to round-off, or (a tolerance far above it, the lengths the check's) to their
    # share of rtol over the windows the interval will take: those done and those left at this length
    windows = st.accepted + jnp.maximum(span, 0.0) / h
    enough = 0.0 if settings["until"] is not None else jnp.where(h_given > 0, 0.0, stage_share(rtol, windows))
    r = gauss_step(field, jac, tab, st.z, st.e, h, Y0, max_iterations=settings["max_iterations"],
                   implicit_gradients=settings.get("implicit", False), linear=getattr(system, "linear_part", None),
                   enough=lax.stop_gradient(enough), unroll=settings.get("unroll", FIXED_POINT_UNROLL))
    # the check only steers the lengths, which carry no derivative (below): kept out of gradients
    zc, ec, hc, Lc, z1 = lax.stop_gradient((st.z, st.e, h, r.L, r.z))
    end, dense = local_error(field, tab, zc, ec, hc, Lc)
    # a tolerance below what float64 resolves counts as round-off: a few ulps of z and of the
    # increments, the latter for each of the check's s + 1 coefficients, which carry their own
    # rounding (their sum measured up to 0.45 (s + 1) eps Σ|L| on Kepler and the oscillator, s = 8–16;
    # with 8 ulps a component through zero failed at s = 15, 16 with rtol 1e-15 and atol 0)
    eps = jnp.finfo(st.z.dtype).eps
    noise = eps * (8 * jnp.abs(zc) + max(8, 2 * (s + 1)) * jnp.sum(jnp.abs(Lc), axis=0))
    tol = jnp.maximum(atol + rtol * jnp.maximum(jnp.abs(zc), jnp.abs(z1)), noise)
    ratio = settings["safety"] * jnp.max(jnp.maximum(end, dense) / tol)
    # … and the field's own round-off over the window, where the check fails without it
    ratio = lax.cond(r.converged & (ratio > 1.0), lambda: settings["safety"] * jnp.max(
        jnp.maximum(end, dense) / jnp.maximum(tol, hc * field_roundoff(field, zc))), lambda: ratio)
    given = h_given > 0
    ok = r.converged & jnp.all(jnp.isfinite(r.z)) & (given | (jnp.isfinite(ratio) & (ratio <= 1.0)))
    fac = jnp.clip(0.9 * ratio ** (-1.0 / (s + 1)), 0.2, settings["growth"])
    fac = jnp.where(jnp.isfinite(fac), fac, 0.2)
    settled = st.settled
    if settings["steps"] == "constant":
        # the length is found over the warm-up, and for as long after it as it still grows by the
        # most a window may (a poor first guess); from then on an accepted window keeps it
        settled = jnp.where(ok & (st.accepted >= settings["warmup"]) & (fac < settings["growth"]), 1, settled)
        fac = jnp.where(ok & (settled > 0), 1.0, fac)
    fac = jnp.where(ok, fac, jnp.where(r.converged, jnp.minimum(fac, 0.9), 0.5))
    # the lengths are the control's, not functions of the state: a derivative of the march is that
    # of the map over the windows taken (the last one's length, T − t, carries T's)
    h_next = lax.stop_gradient(jnp.where(given, h_given, jnp.where(ok & last, st.h, h * fac)))
    return ok, r, h, ratio, h_next, last, settled.astype(st.settled.dtype)


def marching(st: GaussState, T, until: int | None = None):
    """Whether a march goes on: its clock before T and nothing failed."""
    return (clock(st, until) < T) & (st.failed == 0)


def try_window(system, tab, settings, st: GaussState, streak, T, rtol, atol, h_given):
    """One try of one window from ``st``: (the state after it, the rejections in a row, accepted?,
    its row: start, length, start state and compensation, L, check ratio). ``settings`` as the
    program's (with ``implicit``: the stage equations differentiated implicitly, for the traced
    core, :mod:`._gauss_core`)."""
    until = settings["until"]
    ends = T if until is None else jnp.maximum(jnp.abs(T), jnp.abs(st.t))  # the round-off of the march's time
    floor = 1e-14 * jnp.maximum(jnp.abs(ends), 1.0)
    ok, r, h, ratio, h_next, last, settled = _window(system, tab, settings, st, T, rtol, atol, h_given)
    t1, te1 = compensated_add(st.t, st.te, h)
    t1, te1 = jnp.where(last, T, t1), jnp.where(last, 0.0, te1)
    streak = jnp.where(ok, 0, streak + 1)
    failed = jnp.where(~r.converged & (h_given > 0), 3,
                       jnp.where(streak > settings["max_rejects"], jnp.where(r.converged, 2, 3),
                                 jnp.where(h_next < floor, 1, 0)))
    later = settings["newton"] == NEWTON_LATER
    if later:  # a window the fixed point cannot solve: the same window again, by the program with Newton
        failed = jnp.where(r.converged, failed, 5)
        h_next = jnp.where(r.converged, h_next, st.h)
    rejected = ~ok & r.converged if later else ~ok  # a try handed on to Newton is not a rejection
    keep = lambda new, old: jnp.where(ok, new, old)  # noqa: E731
    new = GaussState(keep(t1, st.t), keep(te1, st.te), keep(r.z, st.z), keep(r.e, st.e), h_next,
                     keep(h, st.h_prev), keep(r.L, st.L_prev), st.accepted + ok.astype(st.accepted.dtype),
                     st.rejected + rejected.astype(st.rejected.dtype), st.iterations + r.iterations,
                     st.newton + r.newton.astype(st.newton.dtype),
                     jnp.where(ok, 0, failed).astype(st.failed.dtype),
                     jnp.where(ok, jnp.maximum(st.worst, ratio), st.worst), settled)
    return new, streak, ok, (st.t + st.te, h, st.z, st.e, r.L, ratio)


@program_cache
@functools.lru_cache(maxsize=32)
def _cached(system, stages, steps, chunk, max_iterations, newton, growth, safety, warmup, max_rejects, until,
            settings_key):
    tab = tableau_arrays(gauss_tableau(stages))  # NumPy float64: constants of the program (traced in x64)
    settings = {"steps": steps, "max_iterations": max_iterations, "newton": newton, "growth": growth,
                "safety": safety, "warmup": warmup, "until": until, "max_rejects": max_rejects,
                "unroll": fixed_point_unroll(system)}

    def attempt(st, streak, T, rtol, atol, h_given):
        return try_window(system, tab, settings, st, streak, T, rtol, atol, h_given)

    def running(st, T):
        return marching(st, T, until)

    def alone(state: GaussState, T, rtol, atol, h_given, limit):
        """One member: a while loop that stops at T, or after ``limit`` accepted windows (at most
        ``chunk``: a host that looks at the first windows soon asks for fewer); row k of the buffers
        is the k-th accepted window (written in place whatever the outcome: a rejected try is
        overwritten by the next)."""
        st = started(system, tab, jax.tree_util.tree_map(lambda x: x[0], state), T, h_given, until)
        n, dt = st.z.shape[0], st.z.dtype
        buf = (jnp.zeros(chunk, dt), jnp.zeros(chunk, dt), jnp.zeros((chunk, n), dt), jnp.zeros((chunk, n), dt),
               jnp.zeros((chunk, stages, n), dt), jnp.zeros(chunk, dt))

        def body(c):
            k, st, streak, buf = c
            st, streak, ok, rows = attempt(st, streak, T, rtol, atol, h_given)
            return k + ok.astype(k.dtype), st, streak, tuple(b.at[k].set(x) for b, x in zip(buf, rows))

        most = jnp.minimum(chunk, limit.astype(jnp.int32))
        k, st, _, buf = lax.while_loop(lambda c: running(c[1], T) & (c[0] < most), body,
                                       (jnp.asarray(0), st, jnp.asarray(0), buf))
        out = GaussChunk(jnp.arange(chunk) < k, *buf, st)
        return jax.tree_util.tree_map(lambda x: x[None], out)

    def batched(state: GaussState, T, rtol, atol, h_given, limit):
        """Members on a leading axis: a while loop of tries, every member one try per trip (a
        finished one idling), until all are done or ``limit`` trips (at most ``chunk``); trip j's
        rows go to row j of the buffers for every member at once (written in place: a row index per
        member, under ``vmap``, would make every write a scatter that copies the buffers)."""
        st = jax.vmap(started, in_axes=(None, None, 0, None, None, None))(system, tab, state, T, h_given, until)
        b, n, dt = st.z.shape[0], st.z.shape[1], st.z.dtype
        buf = (jnp.zeros((chunk, b), bool), jnp.zeros((chunk, b), dt), jnp.zeros((chunk, b), dt),
               jnp.zeros((chunk, b, n), dt), jnp.zeros((chunk, b, n), dt), jnp.zeros((chunk, b, stages, n), dt),
               jnp.zeros((chunk, b), dt))
        tries = jax.vmap(attempt, in_axes=(0, 0, None, None, None, None))

        def body(c):
            j, st, streak, buf = c
            new, streak2, ok, rows = tries(st, streak, T, rtol, atol, h_given)
            active = running(st, T)
            pick = lambda a, b: jnp.where(active.reshape(active.shape + (1,) * (a.ndim - 1)), a, b)  # noqa: E731
            st = jax.tree_util.tree_map(pick, new, st)
            return (j + 1, st, jnp.where(active, streak2, streak),
                    tuple(bf.at[j].set(x) for bf, x in zip(buf, (ok & active, *rows))))

        most = jnp.minimum(chunk, limit.astype(jnp.int32))
        _, st, _, buf = lax.while_loop(lambda c: jnp.any(running(c[1], T)) & (c[0] < most), body,
                                       (jnp.asarray(0), st, jnp.zeros(b, jnp.int32), buf))
        return GaussChunk(*(jnp.moveaxis(x, 0, 1) for x in buf), st)

    def mapped(state: GaussState, T, rtol, atol, h_given, limit):
        """Members on a leading axis, marched one after the other inside the program (each its own
        while loop, as :func:`alone`): on a CPU the lock-step loop of :func:`batched` gains nothing
        from its vector width on these small states and pays for the slowest member's iterations,
        so one member at a time is faster there (``benchmarks.solver_batch``)."""
        def one(st):
            out = alone(jax.tree_util.tree_map(lambda x: x[None], st), T, rtol, atol, h_given, limit)
            return jax.tree_util.tree_map(lambda x: x[0], out)

        return lax.map(one, state)

    return {"lockstep": jax.jit(batched), "alone": jax.jit(alone), "sequential": jax.jit(mapped)}


#: the tree of a program's result, for its exported form
_OUT_TREE = jax.tree_util.tree_structure(
    GaussChunk(*([0] * (len(GaussChunk._fields) - 1)), GaussState(*([0] * len(GaussState._fields)))))


def batch_mode() -> str:
    """How a batch's members are marched: "sequential" on a CPU, "lockstep" on an accelerator."""
    return "sequential" if jax.default_backend() == "cpu" else "lockstep"


def compiled_gauss_march(system: Any, *, stages: int, steps: str, chunk: int, max_iterations: int, newton: bool | str,
                         growth: float, safety: float, warmup: int, max_rejects: int, members: int,
                         until: int | None = None):
    """The compiled Gauss march for a system and these settings over ``members`` members (a
    leading axis on the state, also for one); one program per shape, cached, keyed by the trace
    settings; served from its exported form on disk where the system qualifies. ``until``: the
    state's component that runs to T (module docstring; None: the march's own time). ``newton``:
    whether a window the fixed-point iteration cannot solve is solved by Newton's, or
    ``NEWTON_LATER``."""
    newton = NEWTON_LATER if newton == NEWTON_LATER else bool(newton)
    settings = (int(stages), str(steps), int(chunk), int(max_iterations), newton, float(growth), float(safety),
                int(warmup), int(max_rejects), None if until is None else int(until), trace_settings())
    return _served(system, settings, "alone" if members == 1 else batch_mode())


@program_cache
@functools.lru_cache(maxsize=64)
def _served(system, settings: tuple, members_mode: str):
    """The program :func:`compiled_gauss_march` returns, kept per system and settings (finding it
    again would write its disk key anew, a JSON text, on every call)."""
    jitted = _cached(system, *settings)[members_mode]
    return exported_program(jitted, system, {"settings": settings, "members": members_mode, "method": "gauss"},
                            _OUT_TREE, host=True, options=cpu_loop_options())


class ReplayState(NamedTuple):
    """Where a replay stands: the state and its compensation, the last window's length and stages."""

    z: jax.Array
    e: jax.Array
    h_prev: jax.Array
    L_prev: jax.Array
    failed: jax.Array


@program_cache
@functools.lru_cache(maxsize=32)
def _cached_replay(system, stages, max_iterations, newton, settings_key):
    tab = tableau_arrays(gauss_tableau(stages))  # NumPy float64: constants of the program (traced in x64)
    jac = (lambda x: system.jacobian(x[None])[0]) if newton else None

    def run(state: ReplayState, lengths):
        def begin(st):  # the first call: a guess of constant rate, as the march's first window
            return st._replace(h_prev=lengths[0], L_prev=lengths[0] * tab["b"][:, None]
                               * system.vector_field(st.z[None])[0][None, :])

        state = lax.cond(state.h_prev > 0, lambda st: st, begin, state)

        def body(st, h):
            active = h > 0
            hh = jnp.where(active, h, st.h_prev)
            Y0 = continued_stages(tab, st.z, st.e, st.L_prev, hh / st.h_prev)
            r = gauss_step(system.vector_field, jac, tab, st.z, st.e, hh, Y0, max_iterations=max_iterations,
                           linear=getattr(system, "linear_part", None), unroll=fixed_point_unroll(system))
            keep = lambda new, old: jnp.where(active, new, old)  # noqa: E731
            bad = (active & ~(r.converged & jnp.all(jnp.isfinite(r.z)))).astype(st.failed.dtype)
            new = ReplayState(keep(r.z, st.z), keep(r.e, st.e), keep(hh, st.h_prev), keep(r.L, st.L_prev),
                              jnp.maximum(st.failed, bad))
            return new, (st.z, st.e, r.L)

        return lax.scan(body, state, lengths)

    return jax.jit(run)


def compiled_gauss_replay(system: Any, *, stages: int, max_iterations: int, newton: bool):
    """The compiled march over given window lengths (no control): ``run(ReplayState, lengths)``
    returns the state after them and each window's (start state, compensation, L); a length of 0
    is a no-op (the padding of the last chunk). A state with h_prev = 0 starts with a guess of
    constant rate."""
    return _cached_replay(system, int(stages), int(max_iterations), bool(newton), trace_settings())


@program_cache
@functools.lru_cache(maxsize=32)
def _cached_windows(system, stages, max_iterations, newton, settings_key):
    tab = tableau_arrays(gauss_tableau(stages))  # NumPy float64: constants of the program (traced in x64)
    jac = (lambda x: system.jacobian(x[None])[0]) if newton else None

    def one(z, e, h):
        Y0 = z + (e + h * tab["c"][:, None] * system.vector_field(z[None])[0][None, :])
        r = gauss_step(system.vector_field, jac, tab, z, e, h, Y0, max_iterations=max_iterations,
                       linear=getattr(system, "linear_part", None), unroll=fixed_point_unroll(system))
        return r.L

    return jax.jit(jax.vmap(one))


def compiled_gauss_windows(system: Any, *, stages: int, max_iterations: int, newton: bool):
    """The compiled solve of independent windows: ``run(z (m, n), e (m, n), h (m,)) -> L (m, s, n)``,
    each from a guess of constant rate (a window kept without its polynomial, solved again)."""
    return _cached_windows(system, int(stages), int(max_iterations), bool(newton), trace_settings())

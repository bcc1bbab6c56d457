"""The compiled march of an explicit splitting method, and the step its tolerance asks for.

One program per system, scheme, batch size and buffer length: it takes the states of a batch
(B, 2d) with their compensations, a step h, ``every`` and ``slots`` (both traced: any interval, any
tolerance, the same program), takes ``slots`` × ``every`` steps and returns the state after each
block of ``every`` steps (a buffer of ``chunk`` rows, the first ``slots`` filled), rounded to
float64 (z + e): the compensation carries on in the march, and only the end state's is returned
(keeping every state's compensation too made a march that keeps every step 1.3–1.4× slower on
FPUT-β chains of 256 and 1 024 particles). The host calls it until the march is done (progress
between calls).

The step from the tolerance (:func:`pilot_step`): from a first guess (a tenth of the period of the
fastest linearised motion at z0, and never past the scheme's stability limit for that frequency:
a chain excited in its slow modes would otherwise blow up in its fast ones), a pilot of a few steps with h and with h/2 measures the error
constant of the method on this problem (the difference of the two, as the error estimate does);
a global error that grows linearly in t (as a symplectic method's does on a regular orbit) then
gives the step that meets the tolerance at T. The pilot grows h where its error is at round-off
and shrinks it where the march blew up.
"""

from __future__ import annotations

import functools
import math
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from atlasnn.compile_cache import program_cache, to_host
from atlasnn.errors import ConfigError
from atlasnn.limits import available_memory
from atlasnn.solutions import lax_steps, linear_splitting, splitting_scheme, stability_limit, start_state
from atlasnn.solver._gauss_march import _frequency

__all__ = ["MarchOut", "compiled_split_march", "march", "pilot_step", "step_bounds", "fastest_frequency",
           "batch_frequency"]

#: the pilot's steps at h (and twice as many at h/2)
PILOT_STEPS = 16
#: the buffer of the pilot's program (a call keeps up to this many states: the check's marches, and
#: a pilot's over the whole interval, each march of it in one call)
PILOT_CHUNK = 2 * PILOT_STEPS
#: the pilot's tries at most (each a factor 4 or 16 on h)
PILOT_TRIES = 12
#: the largest step as a fraction of the scheme's stability limit over the fastest frequency at z0
#: (the power iterations read that frequency to a few digits, and an orbit reaches faster ones:
#: at 0.7, FPUT-β N = 256 excited in its first mode blew up with McLachlan's scheme)
STABLE_FRACTION = 0.55


class MarchOut(NamedTuple):
    """A call's result: the end state and its compensation (B, 2d); the states after each block of
    steps, rounded (chunk, B, 2d)."""

    z: jax.Array
    e: jax.Array
    zs: jax.Array


def _joined(st) -> tuple[jax.Array, jax.Array]:
    return jnp.concatenate([st.q, st.p], axis=-1), jnp.concatenate([st.eq, st.ep], axis=-1)


def _rounded(st) -> jax.Array:
    return jnp.concatenate([st.q + st.eq, st.p + st.ep], axis=-1)


@program_cache
@functools.lru_cache(maxsize=32)
def compiled_split_march(system: Any, scheme: str, chunk: int, members: int):
    """The compiled march (module docstring) for ``members`` states at once and a buffer of
    ``chunk`` rows."""
    sch = splitting_scheme(scheme)

    def one(z, e, h, every, slots):
        def block(i, carry):
            st, zs = carry
            st = lax_steps(system, sch, st, h, every)
            return st, zs.at[i].set(_rounded(st))

        zs = jnp.zeros((chunk,) + z.shape, z.dtype)
        st, zs = lax.fori_loop(0, slots, block, (start_state(system, z, e), zs))
        return (*_joined(st), zs)

    def run(z, e, h, every, slots):
        z, e, zs = jax.vmap(one, in_axes=(0, 0, None, None, None), out_axes=(0, 0, 1))(z, e, h, every, slots)
        return MarchOut(z, e, zs)

    return jax.jit(run)


def march_to(program, z: np.ndarray, e: np.ndarray, h: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The states (B, 2d) after ``steps`` steps of h from z + e, in one call (one block)."""
    with jax.enable_x64(True):
        out = to_host(program(z, e, np.float64(h), np.int64(steps), np.int64(1)))
    return out.z, out.e


#: a march keeping more than this many bytes first checks the memory left
_READ_MEMORY_ABOVE = 64 << 20


def march(program, z0s: np.ndarray, h: float, steps: int, every: int, chunk: int,
          progress: Callable[[float], None] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``steps`` steps of h from the states ``z0s`` (B, 2d) by the compiled ``program``, keeping the
    state every ``every`` steps and at the end: the kept states (K, B, 2d), their compensations
    (zeros but at the end: the states between are kept rounded), and their step indices (K,)."""
    z, e = z0s, np.zeros_like(z0s)
    zs, kept, done = [z0s[None]], [0], 0
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
            kept.extend(done + size * np.arange(1, slots + 1))
            done += size * slots
            if progress is not None:
                progress(done / steps)
    zs = np.concatenate(zs)
    zs[-1] = z  # the end state whole: its compensation beside it
    es = np.zeros(zs.shape)  # not written but at the end: pages the system gives on first use
    es[-1] = e
    return zs, es, np.asarray(kept, np.int64)


@program_cache
@functools.lru_cache(maxsize=32)
def _compiled_frequency(system: Any):
    return jax.jit(lambda z: _frequency(system, z)[0])


def fastest_frequency(system: Any, z0: np.ndarray) -> float:
    """ω, the fastest linearised frequency at z0 (0 where there is none)."""
    with jax.enable_x64(True):
        omega = float(_compiled_frequency(system)(np.asarray(z0, np.float64)))
    return omega if math.isfinite(omega) and omega > 0 else 0.0


def batch_frequency(system: Any, z0s: np.ndarray) -> float:
    """ω, the fastest linearised frequency at any member's z0 (of N alone where S's flow is
    exact; 0 where there is none)."""
    return max(fastest_frequency(system, z) for z in z0s)


def step_bounds(system: Any, omega: float, span: float, scheme: Any) -> tuple[float, float]:
    """(a first step, the largest stable step) for the batch: a tenth of 2π/ω and
    ``STABLE_FRACTION`` of the scheme's stability limit over ω, ω the fastest linearised frequency
    (:func:`batch_frequency`; ``span``/16 and ``span`` where there is none)."""
    if omega == 0.0:
        return span / PILOT_STEPS, span
    # a linear splitting's stiff part is solved exactly: N's frequency sets no stability limit
    largest = span if linear_splitting(system) else STABLE_FRACTION * stability_limit(scheme) / omega
    return min(0.1 * 2 * math.pi / omega, largest, span / PILOT_STEPS), largest


class PilotMarches(NamedTuple):
    """A pilot's two marches over the whole interval, every state kept (``march``'s kept states,
    compensations and step indices): ``PILOT_STEPS`` steps and twice as many of half the length."""

    coarse: tuple[np.ndarray, np.ndarray, np.ndarray]
    fine: tuple[np.ndarray, np.ndarray, np.ndarray]


def pilot_step(program, z0s: np.ndarray, span: float, order: int, rtol: float, atol: float, h: float,
               largest: float, tries: int = PILOT_TRIES, keep: bool = True
               ) -> tuple[float, dict[str, Any], PilotMarches | None]:
    """The step that meets the tolerance over ``span`` (module docstring), at most ``largest`` (the
    stable steps), the pilot's record (``settled`` False where ``tries`` tries found none: the
    step returned is then the last tried), and, with ``keep``, where its last try marched over the
    whole interval, those two marches (:class:`PilotMarches`: a march of their steps need not be
    made again; keeping every state costs 20–35 µs more a march on FPUT-β with 64 particles). ``h``
    is the first guess; the batch's smallest step serves every member."""
    zero = np.zeros_like(z0s)
    record: dict[str, Any] = {"pilot_tries": 0, "settled": True}
    err = scale = math.nan
    marches = None
    for _ in range(tries):
        record["pilot_tries"] += 1
        pilot = min(PILOT_STEPS * h, span)
        h = pilot / PILOT_STEPS
        if keep and pilot >= span:  # over the whole interval: every state kept (the same steps, one call each)
            marches = PilotMarches(march(program, z0s, h, PILOT_STEPS, 1, PILOT_CHUNK, None),
                                   march(program, z0s, 0.5 * h, 2 * PILOT_STEPS, 1, PILOT_CHUNK, None))
            (z1, e1), (z2, e2) = ((run[0][-1], run[1][-1]) for run in marches)
        else:
            marches = None
            z1, e1 = march_to(program, z0s, zero, h, PILOT_STEPS)
            z2, e2 = march_to(program, z0s, zero, 0.5 * h, 2 * PILOT_STEPS)
        diff = np.abs((z2 - z1) + (e2 - e1)) * (2.0 ** order / (2.0 ** order - 1.0))
        scale = np.maximum(np.abs(z0s).max(axis=1), np.abs(z1).max(axis=1))  # (B,)
        if not np.all(np.isfinite(diff)) or np.any(diff.max(axis=1) > 0.1 * np.maximum(scale, 1e-300)):
            h *= 0.25  # unstable or far from the asymptotic regime
            continue
        floor = 64 * np.finfo(np.float64).eps * np.maximum(scale, np.abs(z1).max(axis=1)) * math.sqrt(PILOT_STEPS)
        err = float(np.max(diff.max(axis=1) / (atol + rtol * scale)))
        if np.all(diff.max(axis=1) <= floor) and pilot < span:
            if h >= largest:
                record.update(pilot_h=h, pilot_error=err, pilot_span=pilot, limited_by="stability")
                return min(largest, span), record, marches
            # at round-off: the error constant cannot be read here; 16 times longer (the error then
            # 16^p times larger, from below round-off: still within the pilot's reach)
            h = min(16.0 * h, largest)
            continue
        # the error grows linearly over the interval: what it would be at the end, in tolerances
        grown = err * span / pilot
        record.update(pilot_h=h, pilot_error=err, pilot_span=pilot)
        proposed = span if grown <= 0 else h * (0.5 / grown) ** (1.0 / order)
        if proposed > largest:
            record["limited_by"] = "stability"
            proposed = largest
        if proposed > 4.0 * h and pilot < span:
            h = proposed  # far from the pilot's step: measured again there
            continue
        return min(proposed, span), record, marches
    record.update(pilot_h=h, pilot_error=err, settled=False)
    return h, record, None

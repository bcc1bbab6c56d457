"""Classical integrators: the symplectic baselines and the high-accuracy reference solution.

Three explicit symplectic one-step methods with a fixed step on [t0, T] — symplectic Euler (the
paper's baseline "SE", eq. (5)), Störmer–Verlet and Yoshida's fourth-order composition — and a
reference ("benchmark") solution from SciPy's DOP853 at tight tolerances.

Everything here is computed in float64, whatever the global precision switch of
:mod:`atlasnn.precision` says: the stepping loops are ``jax.lax.scan`` inside ``jax.jit`` and are
traced and run under ``jax.enable_x64(True)``. Compiled steppers are cached per
(system, method, n_steps), so integrating the same system again with the same number of steps
(any interval, any initial state) does not recompile.

All three symplectic methods need a separable Hamiltonian H = T(p) + V(q): for such an H their
partial updates are exact flows and the composition is explicit and symplectic. A system not
declared separable is refused with a one-line :class:`~atlasnn.errors.SystemError_`; the
reference solver works for any H.
"""

from __future__ import annotations

import functools
import math
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

from atlasnn.compile_cache import program_cache
from atlasnn.errors import AtlasError, ConfigError
from atlasnn.precision import on_device
from atlasnn.systems import HamiltonianSystem

__all__ = [
    "symplectic_euler",
    "stormer_verlet",
    "yoshida4",
    "INTEGRATORS",
    "INTEGRATOR_ORDERS",
    "integrate",
    "reference_solution",
    "reference_rhs",
    "REFERENCE_DESCRIPTION",
    "REFERENCE_RTOL",
    "REFERENCE_ATOL",
]

REFERENCE_RTOL = 1e-12
REFERENCE_ATOL = 1e-12
REFERENCE_DESCRIPTION = "SciPy solve_ivp DOP853, rtol=atol=1e-12, float64"

# Yoshida (1990) triple-jump weights: w1 + w0 + w1 = 1 and 2 w1^3 + w0^3 = 0.
_CBRT2 = 2.0 ** (1.0 / 3.0)
_YOSHIDA_W1 = 1.0 / (2.0 - _CBRT2)
_YOSHIDA_W0 = -_CBRT2 / (2.0 - _CBRT2)


# ------------------------------------------------------------------ one step of each method
def _se_step(system: HamiltonianSystem, q: jax.Array, p: jax.Array, dt: jax.Array):
    # q first with the old p, then p with the new q (SPEC §5, paper eq. (5)).
    q_new = q + dt * system.dH_dp(q, p)
    p_new = p - dt * system.dH_dq(q_new, p)
    return q_new, p_new


def _verlet_step(system: HamiltonianSystem, q: jax.Array, p: jax.Array, dt: jax.Array):
    # Kick (half) - drift (full) - kick (half).
    p_half = p - 0.5 * dt * system.dH_dq(q, p)
    q_new = q + dt * system.dH_dp(q, p_half)
    p_new = p_half - 0.5 * dt * system.dH_dq(q_new, p_half)
    return q_new, p_new


def _yoshida_step(system: HamiltonianSystem, q: jax.Array, p: jax.Array, dt: jax.Array):
    q, p = _verlet_step(system, q, p, _YOSHIDA_W1 * dt)
    q, p = _verlet_step(system, q, p, _YOSHIDA_W0 * dt)
    q, p = _verlet_step(system, q, p, _YOSHIDA_W1 * dt)
    return q, p


_STEPS: dict[str, Callable[..., Any]] = {
    "symplectic_euler": _se_step,
    "stormer_verlet": _verlet_step,
    "yoshida4": _yoshida_step,
}

_METHOD_LABELS = {
    "symplectic_euler": "symplectic Euler",
    "stormer_verlet": "Störmer–Verlet",
    "yoshida4": "Yoshida 4th-order",
}

INTEGRATOR_ORDERS = {"symplectic_euler": 1, "stormer_verlet": 2, "yoshida4": 4}


@program_cache
@functools.lru_cache(maxsize=64)
def _compiled_stepper(system: HamiltonianSystem, method: str, n_steps: int):
    """A jitted ``(z0, dt) -> trajectory`` for this system, method and step count."""
    step = _STEPS[method]
    d = system.dim

    def run(z0: jax.Array, dt: jax.Array) -> jax.Array:
        def body(carry, _):
            q, p = step(system, carry[0], carry[1], dt)
            return (q, p), jnp.concatenate([q, p])

        _, zs = jax.lax.scan(body, (z0[:d], z0[d:]), None, length=n_steps)
        return jnp.concatenate([z0[None, :], zs], axis=0)

    return jax.jit(run)


# ------------------------------------------------------------------------ argument checks
def _check_interval(t0: Any, T: Any, n_steps: Any) -> tuple[float, float, int]:
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
        raise ConfigError(f"n_steps must be a positive integer, got {n_steps!r}")
    try:
        t0f = float(t0)
    except (TypeError, ValueError):
        raise ConfigError(f"t0 must be a number, got {t0!r}") from None
    try:
        Tf = float(T)
    except (TypeError, ValueError):
        raise ConfigError(f"T must be a number, got {T!r}") from None
    if not math.isfinite(t0f):
        raise ConfigError(f"t0 must be finite, got {t0!r}")
    if not math.isfinite(Tf):
        raise ConfigError(f"T must be finite, got {T!r}")
    if not Tf > t0f:
        raise ConfigError(f"T must be greater than t0, got T={Tf!r} and t0={t0f!r}")
    return t0f, Tf, int(n_steps)


def _run(method: str, system: HamiltonianSystem, z0: Any, t0: Any, T: Any, n_steps: Any):
    if not isinstance(system, HamiltonianSystem):
        raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    system.require_separable(_METHOD_LABELS[method])
    t0f, Tf, n = _check_interval(t0, T, n_steps)
    z_init = system.initial_state(z0)
    t = np.linspace(t0f, Tf, n + 1, dtype=np.float64)
    dt = (Tf - t0f) / n
    fn = _compiled_stepper(system, method, n)
    with jax.enable_x64(True):
        Z = fn(on_device(z_init, np.float64), on_device(dt, np.float64))
        Z = np.asarray(Z, dtype=np.float64)
    return t, Z


# --------------------------------------------------------------------------- public methods
def symplectic_euler(system: HamiltonianSystem, z0: Any, t0: float, T: float, n_steps: int):
    """Symplectic Euler method (the paper's baseline "SE", eq. (5)).

    1st order, fixed step Δt = (T − t0)/n_steps, explicit, symplectic. Needs a separable
    Hamiltonian H = T(p) + V(q). Each step updates q first with the old momentum, then p with the
    new position:

        q_{n+1} = q_n + Δt ∂H/∂p(q_n, p_n)
        p_{n+1} = p_n − Δt ∂H/∂q(q_{n+1}, p_n)

    Computed in float64 whatever the global precision.

    Args:
        system: a :class:`~atlasnn.systems._hamiltonian.HamiltonianSystem` declared separable.
        z0: the initial state (q then p, length 2d), or ``None`` for the system's default.
        t0, T: the interval, T > t0.
        n_steps: the number of steps, a positive integer.

    Returns:
        ``(t, Z)``: float64 arrays of shapes (n_steps+1,) and (n_steps+1, 2d); ``Z[0]`` is z0.

    Raises:
        SystemError_: H is not declared separable, or z0 is malformed.
        ConfigError: n_steps is not a positive integer, or T ≤ t0.
    """
    return _run("symplectic_euler", system, z0, t0, T, n_steps)


def stormer_verlet(system: HamiltonianSystem, z0: Any, t0: float, T: float, n_steps: int):
    """Störmer–Verlet (leapfrog) method, kick–drift–kick form.

    2nd order, fixed step Δt = (T − t0)/n_steps, explicit, symplectic, time-reversible. Needs a
    separable Hamiltonian H = T(p) + V(q). One step:

        p_{n+1/2} = p_n − (Δt/2) ∂H/∂q(q_n, p_n)
        q_{n+1}   = q_n + Δt ∂H/∂p(q_n, p_{n+1/2})
        p_{n+1}   = p_{n+1/2} − (Δt/2) ∂H/∂q(q_{n+1}, p_{n+1/2})

    Computed in float64 whatever the global precision. Arguments, return value and errors as
    for :func:`symplectic_euler`.
    """
    return _run("stormer_verlet", system, z0, t0, T, n_steps)


def yoshida4(system: HamiltonianSystem, z0: Any, t0: float, T: float, n_steps: int):
    """Yoshida's 4th-order symplectic method (triple-jump composition of Störmer–Verlet).

    4th order, fixed step Δt = (T − t0)/n_steps, explicit, symplectic, time-reversible. Needs a
    separable Hamiltonian H = T(p) + V(q). Each step is three Störmer–Verlet substeps of sizes
    w1 Δt, w0 Δt, w1 Δt with w1 = 1/(2 − 2^{1/3}), w0 = −2^{1/3}/(2 − 2^{1/3}) (Yoshida 1990);
    the middle substep goes backwards in time.

    Computed in float64 whatever the global precision. Arguments, return value and errors as
    for :func:`symplectic_euler`.
    """
    return _run("yoshida4", system, z0, t0, T, n_steps)


INTEGRATORS: dict[str, Callable[..., tuple[np.ndarray, np.ndarray]]] = {
    "symplectic_euler": symplectic_euler,
    "stormer_verlet": stormer_verlet,
    "yoshida4": yoshida4,
}


def integrate(method: str, system: HamiltonianSystem, z0: Any, t0: float, T: float, n_steps: int):
    """Run the fixed-step integrator named ``method``, in float64 whatever the global precision.

    Args:
        method: ``"symplectic_euler"`` (the paper's baseline "SE"), ``"stormer_verlet"`` or
            ``"yoshida4"`` (the keys of ``INTEGRATORS``); each needs H declared separable.
        system: the Hamiltonian system.
        z0: the initial state (q then p, length 2d), or ``None`` for the system's default.
        t0: the start of the interval.
        T: its end, after ``t0``.
        n_steps: the number of steps of length (T − t0)/n_steps, a positive integer.

    Returns ``(t, Z)``: float64 arrays of shapes (n_steps + 1,) and (n_steps + 1, 2d); ``Z[0]`` is
    z0. An unknown name is a one-line ConfigError.
    """
    if method not in INTEGRATORS:
        raise ConfigError(f"unknown integrator {method!r}; choose one of {sorted(INTEGRATORS)}")
    return INTEGRATORS[method](system, z0, t0, T, n_steps)


# ------------------------------------------------------------------------ reference solution
@program_cache
@functools.lru_cache(maxsize=64)
def _jitted_vector_field(system: HamiltonianSystem):
    return jax.jit(system.vector_field)


def reference_rhs(system: HamiltonianSystem) -> Callable[[float, np.ndarray], np.ndarray]:
    """The right-hand side ``f(t, z) = J∇H(z)`` as a NumPy float64 function, for SciPy.

    J∇H is the system's own (autodiff of H), jitted once. Called inside ``jax.enable_x64(True)``
    (as :func:`reference_solution` calls it) with a NumPy array, a call takes jit's C++ fast
    path: about 16 µs on this CPU, against 80–260 µs when the x64 context and a ``jnp`` copy were
    made per call (round 2), and about 1 µs for a hand-written NumPy function. Outside an x64
    context the context is entered per call.
    """
    vf = _jitted_vector_field(system)

    def rhs(t: float, z: np.ndarray) -> np.ndarray:
        z = np.asarray(z, dtype=np.float64)
        if jax.config.jax_enable_x64:
            out = np.asarray(vf(z))
        else:
            with jax.enable_x64(True):
                out = np.asarray(vf(z))
        if not np.all(np.isfinite(out)):
            # a NaN/inf slope makes DOP853's step control shrink the step for ever: stop here
            raise _NonFiniteField(t, z)
        return out

    return rhs


class _NonFiniteField(Exception):
    def __init__(self, t: float, z: np.ndarray):
        super().__init__(t, z)
        self.t, self.z = float(t), np.asarray(z, dtype=np.float64).tolist()


def _check_t_eval(t_eval: Any) -> np.ndarray:
    try:
        t = np.asarray(t_eval, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"t_eval must be an array of times, got {type(t_eval).__name__}") from None
    if t.ndim != 1 or t.size < 1:
        raise ConfigError(f"t_eval must be a non-empty 1-D array of times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ConfigError("t_eval must be finite, got non-finite values")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        i = int(np.argmax(~(np.diff(t) > 0)))
        raise ConfigError(
            f"t_eval must be strictly increasing, got t_eval[{i}]={t[i]!r} >= t_eval[{i + 1}]={t[i + 1]!r}"
        )
    return t


def reference_solution(
    system: HamiltonianSystem,
    z0: Any,
    t_eval: Any,
    rtol: float = REFERENCE_RTOL,
    atol: float = REFERENCE_ATOL,
) -> np.ndarray:
    """High-accuracy reference ("benchmark") trajectory at the times ``t_eval``.

    Solver: SciPy ``solve_ivp`` with method DOP853 (explicit Runge–Kutta of order 8, adaptive
    step), rtol = atol = 1e-12 by default, integrating from ``t_eval[0]`` to ``t_eval[-1]`` and
    reporting the solution at ``t_eval`` (dense output of the solver, not interpolation by
    atlasnn). The vector field J∇H is evaluated in float64 by a jitted JAX function, whatever the
    global precision. Works for any Hamiltonian, separable or not. (The authors' release used
    ``scipy.integrate.odeint`` at default tolerances; see ``REFERENCE_DESCRIPTION``.)

    Args:
        system: the Hamiltonian system.
        z0: the state at ``t_eval[0]`` (length 2d), or ``None`` for the system's default.
        t_eval: strictly increasing, finite 1-D array of times.
        rtol: the solver's relative tolerance.
        atol: the solver's absolute tolerance.

    Returns:
        Z: float64 array of shape (len(t_eval), 2d); ``Z[0]`` is z0.

    Raises:
        ConfigError: t_eval is not a finite, strictly increasing 1-D array, or bad tolerances.
        AtlasError: the solver fails (message on one line).
    """
    if not isinstance(system, HamiltonianSystem):
        raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
    t = _check_t_eval(t_eval)
    for name, val in (("rtol", rtol), ("atol", atol)):
        try:
            ok = math.isfinite(float(val)) and float(val) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ConfigError(f"{name} must be a positive number, got {val!r}")
    z_init = system.initial_state(z0)
    if t.size == 1:
        return z_init[None, :].copy()
    return dop853(system, z_init, t, float(rtol), float(atol))[0]


def reference_solutions(system: HamiltonianSystem, z0: Any, grids: Sequence[Any],
                        rtol: float = REFERENCE_RTOL, atol: float = REFERENCE_ATOL) -> list[np.ndarray]:
    """:func:`reference_solution` on each of several grids, with one DOP853 solve for all the grids
    that share their first and last times (on the union of their times). The solver's steps do not
    depend on the times it reports, so each grid gets the values a solve of its own gives, bit for bit."""
    grids = [_check_t_eval(g) for g in grids]
    out: list[np.ndarray | None] = [None] * len(grids)
    spans: dict[tuple[float, float], list[int]] = {}
    for i, g in enumerate(grids):
        spans.setdefault((float(g[0]), float(g[-1])), []).append(i)
    for members in spans.values():
        union = np.unique(np.concatenate([grids[i] for i in members]))
        Z = reference_solution(system, z0, union, rtol, atol)
        for i in members:
            out[i] = Z[np.searchsorted(union, grids[i])]
    return out


def dop853(system: HamiltonianSystem, z_init: np.ndarray, t: np.ndarray, rtol: float,
           atol: float, rhs: Callable[[float, np.ndarray], np.ndarray] | None = None) -> tuple[np.ndarray, int]:
    """(Z at the times ``t``, the number of right-hand-side evaluations): SciPy's DOP853 from
    ``z_init`` at ``t[0]`` (checked inputs; :func:`reference_solution` is the public face);
    ``rhs``: the field as a NumPy function (default: the system's compiled one)."""
    rhs = reference_rhs(system) if rhs is None else rhs
    try:
        with jax.enable_x64(True):
            sol = solve_ivp(
                rhs, (float(t[0]), float(t[-1])), z_init, method="DOP853", t_eval=t,
                rtol=float(rtol), atol=float(atol),
            )
    except _NonFiniteField as exc:
        raise AtlasError(
            f"reference solver DOP853 stopped for system {system.name!r}: J∇H is not finite at "
            f"t = {exc.t:.6g}, z = {[float(f'{v:.6g}') for v in exc.z]}"
        ) from None
    if not sol.success:
        msg = " ".join(str(sol.message).split())
        raise AtlasError(f"reference solver DOP853 failed for system {system.name!r}: {msg}")
    Z = np.asarray(sol.y, dtype=np.float64).T
    if Z.shape != (t.size, system.state_dim) or not np.all(np.isfinite(Z)):
        raise AtlasError(
            f"reference solver DOP853 returned an unusable solution for system {system.name!r} "
            f"(shape {Z.shape}, finite={bool(np.all(np.isfinite(Z)))})"
        )
    return Z, int(sol.nfev)

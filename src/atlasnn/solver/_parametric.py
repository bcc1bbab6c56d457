"""The parametric Gauss solve: z(t_i; θ, z0) at given times and, where asked, its sensitivities
∂z(t_i)/∂(θ, z0) along given directions — one compiled program per system, with θ, z0, the
directions, the window length and the times as its arguments (a new θ compiles nothing).

The march takes windows of one length h from t0 (as many as reach the last time), each solved by
:func:`._gauss_step.gauss_step` from the previous window's polynomial continued, and evaluates
every window's polynomial at the observation times inside it (the dense output, order s + 1
between the window ends). Every window's Picard check (:func:`._gauss_step.local_error`) is
recorded, not acted on: h is chosen by the caller (:class:`ParametricGauss`), once per fit, so that
the computed z(t_i) is one smooth function of (θ, z0) — the same windows and the same equations
whatever the parameters — rather than one whose steps change with them.

The sensitivities are the variational equations dS/dt = A(z, θ) S + ∂f/∂θ D (A = ∂f/∂z, one
column per direction, each a forward-mode derivative of f: ``jax.jvp``) solved beside z by the same
windows, the same stage equations and the same dense output. For a Runge–Kutta method whose stage
equations are solved exactly that is the derivative of the discrete solution itself, so the
Jacobian a least-squares fit gets is consistent with its residuals to round-off (the stage
iteration's rule covers the columns too). It is the same number, to 1e-16, as ``jax.jvp`` through
the whole march (forward mode goes through ``lax.while_loop``; reverse mode does not), which was
measured against it: 2–3× less to trace (the derivative of nested loops is traced a few times over
at every level), 20 % faster a solve. The simplified Newton iteration of a window that needs it
takes blocks A(z) on its diagonal: the coupling of S to z it leaves out changes how fast it
converges, not to what.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from atlasnn.compile_cache import program_cache, to_host
from atlasnn.errors import ConfigError, ParametricSolveFailed
from atlasnn.precision import trace_settings
from atlasnn.solutions import gauss_tableau, shifted_legendre
from atlasnn.solver._collocation import require_float64
from atlasnn.solver._exported import exported_program
from atlasnn.solver._gauss_step import continued_stages, gauss_step, local_error, small_matmul, tableau_arrays
from atlasnn.systems import HamiltonianSystem, parametric_field, require_float64_field

__all__ = ["ParametricGauss", "ParametricSolveFailed"]

#: the fewest observation times a program is compiled for; more are padded to the next power of two
#: (one program serves data sets of similar size)
_MIN_TIMES = 8


class _Marched(NamedTuple):
    Z: jax.Array  # (M, n) the state at the times
    S: jax.Array  # (M, n, m) its derivatives along the m directions
    worst: jax.Array  # the largest Picard check ratio over the windows (safety included)
    ok: jax.Array  # every window solved to round-off, every state finite
    windows: jax.Array  # windows marched
    evaluations: jax.Array  # evaluations of the field (stage iterations and checks)


def _march(field1, tab, value, settings, theta, z0, S0, D, t0, h, times, rtol, atol):
    """The march of the module docstring for one θ, z0 and the m directions (S0 (n, m), D (P, m)):
    the state y = (z, vec S) of the system and its variational equations, ``times`` (M,) ≥ t0."""
    s = tab["b"].shape[0]
    n, m = S0.shape

    def rates(y):  # f(z, θ) and, beside it, A S_k + ∂f/∂θ D_k: one forward derivative of f per column
        if m == 0:
            return field1(y, theta)
        f, dS = jax.vmap(lambda sk, dk: jax.jvp(field1, (y[:n], theta), (sk, dk)), in_axes=(1, 1),
                         out_axes=(None, 1))(y[n:].reshape(n, m), D)
        return jnp.concatenate([f, dS.reshape(-1)])

    stages_rates = jax.vmap(rates)
    jac = (lambda y: jnp.kron(jnp.eye(1 + m, dtype=y.dtype), jax.jacfwd(field1)(y[:n], theta))) \
        if settings["newton"] else None
    count = jnp.maximum(jnp.ceil((jnp.max(times) - t0) / h), 1.0).astype(jnp.int32)
    k_obs = jnp.clip(jnp.floor((times - t0) / h), 0, count - 1).astype(jnp.int32)
    phase = ((times - t0) - k_obs * h) / h  # θ of each time in its window
    weights = phase[:, None] * (shifted_legendre(phase, s - 1, jnp) @ value.T)  # (M, s): ŷ(θ) − y_k = W L
    y0 = jnp.concatenate([z0, S0.reshape(-1)])
    L_first = h * tab["b"][:, None] * rates(y0)[None, :]  # a guess of constant rate

    def going(c):
        k, _, _, _, _, ok, _, _ = c
        return (k < count) & ok

    def body(c):
        k, y, e, L_prev, out, ok, worst, evals = c
        Y0 = continued_stages(tab, y, e, L_prev, 1.0)
        r = gauss_step(stages_rates, jac, tab, y, e, h, Y0, max_iterations=settings["max_iterations"])
        # the check is the state's: the tolerance is for z
        end, dense = local_error(jax.vmap(lambda z: field1(z, theta)), tab, y[:n], e[:n], h, r.L[:, :n])
        noise = 8 * jnp.finfo(y.dtype).eps * (jnp.abs(y[:n]) + jnp.sum(jnp.abs(r.L[:, :n]), axis=0))
        tol = jnp.maximum(atol + rtol * jnp.maximum(jnp.abs(y[:n]), jnp.abs(r.z[:n])), noise)
        ratio = settings["safety"] * jnp.max(jnp.maximum(end, dense) / tol)
        out = jnp.where((k_obs == k)[:, None], y + (e + small_matmul(weights, r.L)), out)
        good = r.converged & jnp.all(jnp.isfinite(r.z)) & jnp.isfinite(ratio)
        return (k + 1, r.z, r.e, r.L, out, good, jnp.maximum(worst, jnp.where(good, ratio, jnp.inf)),
                evals + r.iterations * s + s + 1)

    start = (jnp.asarray(0, jnp.int32), y0, jnp.zeros_like(y0), L_first,
             jnp.zeros((times.shape[0], y0.shape[0]), y0.dtype), jnp.asarray(True), jnp.asarray(0.0, y0.dtype),
             jnp.asarray(1, jnp.int32))
    k, _, _, _, out, ok, worst, evals = lax.while_loop(going, body, start)
    return _Marched(out[:, :n], out[:, n:].reshape(out.shape[0], n, m), worst, ok, k, evals)


@program_cache
@functools.lru_cache(maxsize=32)
def _program(system: HamiltonianSystem, stages: int, max_iterations: int, newton: bool, safety: float, settings_key):
    """The jitted march (one program per shape: the values alone are the march with m = 0)."""
    tab = tableau_arrays(gauss_tableau(stages))
    value = np.asarray(gauss_tableau(stages).value, np.float64)
    settings = {"max_iterations": max_iterations, "newton": newton, "safety": safety}
    return jax.jit(functools.partial(_march, parametric_field(system), tab, value, settings))


_OUT_TREE = jax.tree_util.tree_structure(_Marched(*([0] * len(_Marched._fields))))


class ParametricGauss:
    """z(t_i; θ, z0) and ∂z(t_i)/∂(θ, z0) by the Gauss collocation (module docstring), for one fit.

    The window length is chosen on the first call (the longest whose Picard check is within
    atol + rtol·|z| everywhere, found in a few marches from one window) and kept: a later call
    whose check exceeds the tolerance, or whose stage equations fail, shortens it (and keeps the
    shorter one), so every call of a fit marches the same windows unless the parameters demand
    shorter ones. ``evaluations`` counts the field's evaluations of every call.

    Args:
        rtol, atol: every window's error along it, as its Picard check bounds it (times
            ``safety``), within atol + rtol·|z| per component of z.
        stages, newton, max_iterations: as :class:`atlasnn.solver.GaussCollocation`'s.
        max_windows: a length that would take more windows than this is refused (an orbit that
            escapes is refused rather than marched on ever shorter windows).
    """

    def __init__(self, system: HamiltonianSystem, *, rtol: float = 1e-10, atol: float = 1e-10, stages: int = 12,
                 newton: bool = True, max_iterations: int = 100, safety: float = 2.0, max_windows: int = 200_000):
        if not isinstance(system, HamiltonianSystem):
            raise ConfigError(f"system must be a HamiltonianSystem, got {type(system).__name__}")
        system.require_parametric("the parametric Gauss solve")
        require_float64_field(system)
        for name, val in (("rtol", rtol), ("atol", atol)):
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val) or val <= 0:
                raise ConfigError(f"{name} must be a positive number, got {val!r}")
        gauss_tableau(stages)  # refuses a stage count out of range
        self.system, self.rtol, self.atol, self.stages = system, float(rtol), float(atol), int(stages)
        self.max_windows = int(max_windows)
        self.h: float | None = None
        self.evaluations = 0
        self._reached = 0.0
        self._key = (int(stages), int(max_iterations), bool(newton), float(safety))

    def _program(self):
        return exported_program(_program(self.system, *self._key, trace_settings()), self.system,
                                {"parametric": list(self._key)}, _OUT_TREE, host=True)

    def _run(self, h, theta, z0, t0, times, S0, D):
        span = float(times.max()) - t0
        if span / h > self.max_windows:
            raise ParametricSolveFailed(f"the window length fell to {h:.3g}: more than {self.max_windows} windows "
                                        f"over [{t0:.6g}, {t0 + span:.6g}]")
        if S0 is None:  # the values alone: no directions
            S0, D = np.zeros((z0.size, 0)), np.zeros((theta.size, 0))
        with jax.enable_x64(True):
            out = to_host(self._program()(theta, z0, S0, D, np.float64(t0), np.float64(h), times,
                                          np.float64(self.rtol), np.float64(self.atol)))
        self.evaluations += int(out.evaluations)
        good = bool(out.ok) and np.all(np.isfinite(out.Z)) and np.all(np.isfinite(out.S))
        if not good:  # where the march stopped: the start of the window that failed
            self._reached = t0 + max(int(out.windows) - 1, 0) * h
        return out, good

    def _failed(self, h, t_end) -> ParametricSolveFailed:
        return ParametricSolveFailed(
            f"the Gauss solve did not reach t = {t_end:.6g}: stopped at t = {self._reached:.6g} with windows down to "
            f"{h:.3g} (rtol={self.rtol:g}, atol={self.atol:g})")

    def _first_length(self, theta, z0, t0, times) -> float:
        """The longest length (up to the span) whose check passes at (θ, z0): from one window over
        the span, shortened or lengthened by the check's order (its error goes as h^(s+1))."""
        span = float(times.max()) - t0
        h, best = span, None
        self._reached = t0
        for _ in range(12):
            tried = h
            out, good = self._run(h, theta, z0, t0, times, None, None)
            worst = float(out.worst)
            if good and worst <= 1.0:
                best = h
                grow = 0.9 * max(worst, 1e-300) ** (-1.0 / (self.stages + 1))
                if h >= span or grow < 1.25:
                    break
                h = min(span, h * min(grow, 4.0))
                continue
            if best is not None:  # lengthened too far: the last good one
                break
            h = self._shorter(h, good, worst, 0.5)
        if best is None:
            raise self._failed(tried, t0 + span)
        return best

    def _shorter(self, h, good, worst, most) -> float:
        """The next length to try after a window failed its check (by the check's order, at least
        ×``most`` and at most ×0.1 shorter) or its stage equations (halved)."""
        fac = 0.9 * worst ** (-1.0 / (self.stages + 1)) if good and math.isfinite(worst) else 0.5
        return h * min(max(fac, 0.1), most)

    def __call__(self, z_init, theta, t0, times, S_init=None, dtheta=None):
        """(Z (len(times), n), S (len(times), n, m) or None): the state at ``times`` (≥ t0, any order)
        from ``z_init`` at ``t0`` with parameters ``theta``; with ``S_init`` (n, m) and ``dtheta``
        (P, m) also the derivatives along those directions, S(t) = ∂z/∂z0 S_init + ∂z/∂θ dtheta."""
        require_float64()
        z0 = np.asarray(z_init, np.float64).reshape(-1)
        theta = np.asarray(theta, np.float64).reshape(-1)
        times = np.asarray(times, np.float64).reshape(-1)
        t0 = float(t0)
        n, P = self.system.state_dim, len(self.system.param_names)
        if z0.size != n or theta.size != P:
            raise ConfigError(f"the parametric Gauss solve needs a state of {n} and {P} parameters, got "
                              f"{z0.size} and {theta.size}")
        if not np.all(np.isfinite(times)) or np.any(times < t0):
            raise ConfigError(f"the parametric Gauss solve needs finite times from t0 = {t0:g} on")
        with_s = dtheta is not None
        if with_s:
            S0 = np.asarray(S_init, np.float64).reshape(n, -1)
            D = np.asarray(dtheta, np.float64).reshape(P, S0.shape[1])
        if times.size == 0 or float(times.max()) <= t0:
            Z = np.repeat(z0[None], times.size, axis=0)
            return Z, (np.repeat(S0[None], times.size, axis=0) if with_s else None)
        order = np.argsort(times, kind="stable")
        size = max(_MIN_TIMES, 1 << int(math.ceil(math.log2(times.size))))
        padded = np.concatenate([times[order], np.full(size - times.size, times[order[-1]])])
        if self.h is None:
            self.h = self._first_length(theta, z0, t0, padded)
        h = self.h
        for attempt in range(12):
            if attempt:
                h = self._shorter(h, good, worst, 0.9)
            out, good = self._run(h, theta, z0, t0, padded, S0 if with_s else None, D if with_s else None)
            worst = float(out.worst)
            if good and worst <= 1.0:
                break
        else:  # the length kept is the one that worked before: the fit may step back to where it works
            raise self._failed(h, float(times.max()))
        self.h = h  # a shorter one kept: the rest of the fit marches the same windows
        inverse = np.empty_like(order)
        inverse[order] = np.arange(order.size)
        Z = np.asarray(out.Z)[:times.size][inverse]
        return Z, (np.asarray(out.S)[:times.size][inverse] if with_s else None)

"""atlasnn's methods as Diffrax solvers, for ``diffrax.diffeqsolve``: the Gauss collocation
(``GaussLegendre``) and the explicit splitting methods (``SplittingSolver``).

This module imports Diffrax (the ``atlasnn[diffrax]`` extra); nothing else in atlasnn imports it, so
atlasnn works without Diffrax. The step is :func:`._gauss_step.gauss_step`, the one that
``atlasnn.solve``'s march takes (same fixed-point iteration to round-off, simplified-Newton fallback,
warm start from the previous window's polynomial, compensated summation, symplectic coefficients):
one implementation, two doors. What this module adds is the face Diffrax expects:

* the solver state carries what the next step needs: the last step's end state and its compensation
  e (the part of z + e float64 could not hold), the stage increments L and the length of the last
  step. Diffrax keeps the state of the last *accepted* step when a step is rejected (as it keeps y),
  so a rejected try leaves them untouched; and e is used only when the y a step starts from is the
  very state it was made for (anything else, such as a state changed by the user between solves,
  starts uncompensated);
* the dense output is the window's polynomial itself (:class:`GaussLegendreInterpolation`);
* the error estimate is the window's Picard check (:func:`._gauss_step.local_error`);
* gradients: the stage equations are solved in loops that reverse-mode autodiff cannot go through;
  the step differentiates their solution by the implicit function theorem instead
  (``gauss_step(..., implicit_gradients=True)``), so ``RecursiveCheckpointAdjoint`` (the default)
  and forward mode work.

``SplittingSolver`` is a scheme of :mod:`atlasnn.solutions._splitting_tables` (leapfrog to order
10) on the pair of terms (dq/dt = T'(p), dp/dt = −V'(q)) that Diffrax's ``SemiImplicitEuler``
takes. It follows :func:`atlasnn.solutions._splitting_step.split_step`, the step of
``SplittingComposition``: the same flows in the same order, the same compensated summation, the
force carried from one step to the next; for the same steps the two give the same numbers to
round-off. Its dense output is the cubic Hermite interpolant of the step's ends and rates.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

try:
    import diffrax
except ImportError:  # the optional extra
    raise ImportError("atlasnn.solver.diffrax needs Diffrax: pip install diffrax (or, in atlasnn's source folder, "
                      "pip install -e '.[diffrax]')") from None
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import optimistix as optx  # a dependency of Diffrax: the results of a nonlinear solve
from jax import lax
from jax.flatten_util import ravel_pytree

from atlasnn.errors import ConfigError
from atlasnn.solutions import (MAX_STAGES, SPLITTING_SCHEMES, SplittingScheme, gauss_tableau, shifted_legendre,
                               splitting_scheme, window_value)
from atlasnn.solver._gauss_step import continued_stages, gauss_step, local_error, tableau_arrays

__all__ = ["GaussLegendre", "GaussLegendreInterpolation", "GaussLegendreState", "SplittingSolver",
           "SplittingSolverState"]


class GaussLegendreState(NamedTuple):
    """What a step hands the next: the state it ended at (flattened) and that state's compensation,
    its stage increments L (s, n) and its length (the warm start continues L's polynomial)."""

    z: jax.Array
    e: jax.Array
    L: jax.Array
    h: jax.Array


def _rescaled(t0, t, t1):
    """θ = (t − t0)/(t1 − t0), 0 where the window is empty."""
    empty = t1 == t0
    return jnp.where(empty, 0.0, t - t0) / jnp.where(empty, 1.0, t1 - t0)


class GaussLegendreInterpolation(diffrax.AbstractLocalInterpolation):
    """The dense output of one step: the window's collocation polynomial,

        ẑ(t0 + θh) = y0 + (e0 + Σ_j w_j(θ) L_j),

    the trial solution z0 + θh·N(θ) of ``atlasnn.solutions._tableau`` (w from ``window_value``),
    exact at θ = 0 and of order s + 1 in h in between (2s at the window's end). Its derivative is the
    polynomial's own (``rate``), which equals f at the s Gauss nodes."""

    t0: Any
    t1: Any
    y0: Any
    e0: jax.Array
    L: jax.Array

    def _weights(self, t):
        tab = gauss_tableau(self.L.shape[0])
        theta = jnp.asarray(_rescaled(self.t0, t, self.t1))
        return window_value(tab, theta, jnp)

    def evaluate(self, t0, t1=None, left: bool = True):
        del left
        flat, unravel = ravel_pytree(self.y0)
        if t1 is not None:  # the increment, without the start state's cancellation
            return unravel((self._weights(t1) - self._weights(t0)) @ self.L)
        return unravel(flat + (self.e0 + self._weights(t0) @ self.L))

    def derivative(self, t, left: bool = True):
        del left
        _, unravel = ravel_pytree(self.y0)
        tab = gauss_tableau(self.L.shape[0])
        theta = jnp.asarray(_rescaled(self.t0, t, self.t1))
        rate = shifted_legendre(theta, tab.stages, jnp) @ tab.rate.T @ self.L
        h = self.t1 - self.t0
        return unravel(rate / jnp.where(h == 0, 1.0, h))


class GaussLegendre(diffrax.AbstractAdaptiveSolver):
    """The s-stage Gauss–Legendre Runge–Kutta method (ATLAS-NN's trial solution collocated at the s
    Gauss nodes of every step), for ``diffrax.diffeqsolve`` with an ``ODETerm``.

    Symplectic, symmetric, of order 2s at the step ends and s + 1 in between (the dense output);
    conserves every quadratic invariant (angular momentum) to round-off. The stage equations are
    solved by fixed-point iteration until the update stops shrinking (round-off, no tolerance to
    tune), by simplified Newton where that fails; the state is summed with compensation; the
    coefficients satisfy the symplecticity condition exactly in float64. It is the step of
    ``atlasnn.solve(..., solver=GaussCollocation(...))``, and for the same step lengths the two give
    the same numbers to round-off. Needs float64 (``jax.config.update("jax_enable_x64", True)``).

    * ``ConstantStepSize``: the symplectic use. The energy error of a Hamiltonian system stays
      bounded over long times (no drift).
    * ``PIDController``: steps from an embedded error estimate, the window's Picard check (s + 1
      more evaluations of f a step): it bounds the error of the dense output along the step, of
      order s + 1 (``error_order``); the step ends are more accurate than it says (order 2s).
      Like every variable-step method (Diffrax's documentation says the same of its own), adaptive
      steps give up exact symplecticity: over long times the energy error can drift.
    * Dense output (``SaveAt(ts=...)``, ``SaveAt(dense=True)``, events): the window's polynomial.
    * Gradients (``RecursiveCheckpointAdjoint``, ``ForwardMode``) through the implicit function
      theorem on the stage equations: exact derivatives of the discrete solution, for a linear
      solve of s·n unknowns a step in the backward pass.
    * ``jax.vmap`` over initial states or parameters.

    A time-dependent vector field is evaluated at the nodes' times; the state may be any PyTree of
    float64 arrays (flattened inside the step).

    Attributes:
        stages: s (1–16; order 2s). Default 12 (``GaussCollocation`` chooses its s from its rtol).
        max_iterations: iterations of each kind (fixed point, Newton) per step at most.
        newton: fall back on simplified Newton iterations (the vector field's Jacobian at the step's
            start, decoupled into ⌈s/2⌉ complex systems of the state's size) where the fixed-point
            iteration does not reach round-off. A step whose equations are not solved either way
            fails: rejected (infinite error) under a PIDController, an error result under
            ConstantStepSize.
    """

    term_structure: ClassVar = diffrax.ODETerm
    interpolation_cls: ClassVar = GaussLegendreInterpolation

    stages: int = eqx.field(default=12, static=True)
    max_iterations: int = eqx.field(default=100, static=True)
    newton: bool = eqx.field(default=True, static=True)

    def __check_init__(self):
        for name, low in (("stages", 1), ("max_iterations", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ConfigError(f"GaussLegendre {name} must be an integer >= {low}, got {value!r}")
        if self.stages > MAX_STAGES:
            raise ConfigError(f"GaussLegendre stages must be an integer from 1 to {MAX_STAGES}, got {self.stages!r}")
        if not isinstance(self.newton, bool):
            raise ConfigError(f"GaussLegendre newton must be True or False, got {self.newton!r}")

    # ------------------------------------------------------------------ orders
    def order(self, terms) -> int:
        """2s, at the step ends."""
        del terms
        return 2 * self.stages

    def error_order(self, terms) -> int:
        """s + 1: the order of what the error estimate estimates (the dense output's error)."""
        del terms
        return self.stages + 1

    # ------------------------------------------------------------------ the step
    def _tableau(self) -> dict:
        tab = tableau_arrays(gauss_tableau(self.stages))
        x, _ = np.polynomial.legendre.leggauss(self.stages + 1)
        tab["check_nodes"] = 0.5 * (x + 1.0)  # where the Picard check evaluates f (its check_values)
        return tab

    @staticmethod
    def _flat(y0):
        flat, unravel = ravel_pytree(y0)
        if flat.dtype != jnp.float64:
            raise ConfigError(f"GaussLegendre needs a float64 state (jax.config.update('jax_enable_x64', True)); "
                              f"got {flat.dtype}")
        return flat, unravel

    @staticmethod
    def _field(terms, args, unravel, times):
        """f at stage values Y (m, n) and the m times."""
        def one(t, y):
            return ravel_pytree(terms.vf(t, unravel(y), args))[0]

        return lambda Y: jax.vmap(one)(times, Y)

    def init(self, terms, t0, t1, y0, args) -> GaussLegendreState:
        flat, unravel = self._flat(y0)
        tab = self._tableau()
        h = jnp.asarray(t1 - t0, flat.dtype)
        return GaussLegendreState(flat, jnp.zeros_like(flat), self._line(terms, args, unravel, tab, t0, flat, h), h)

    def _line(self, terms, args, unravel, tab, t0, flat, h):
        """A first window's guess: constant rate f(t0, y0), as the stage increments of a previous
        window of length h (as ``atlasnn.solve``'s march starts)."""
        f0 = ravel_pytree(terms.vf(t0, unravel(flat), args))[0]
        return h * tab["b"][:, None] * f0[None, :]

    def step(self, terms, t0, t1, y0, args, solver_state: GaussLegendreState, made_jump):
        flat, unravel = self._flat(y0)
        tab = self._tableau()
        h = jnp.asarray(t1 - t0, flat.dtype)
        st = solver_state
        e = jnp.where(jnp.all(flat == st.z), st.e, jnp.zeros_like(st.e))
        L_prev, h_prev = st.L, st.h
        if made_jump is not False:  # across a jump the previous polynomial says nothing of this window
            L_prev, h_prev = lax.cond(made_jump, lambda: (self._line(terms, args, unravel, tab, t0, flat, h), h),
                                      lambda: (L_prev, h_prev))
        Y0 = continued_stages(tab, flat, e, L_prev, h / h_prev)
        field = self._field(terms, args, unravel, t0 + h * tab["c"])
        jacobian = None
        if self.newton:
            jacobian = jax.jacfwd(lambda y: ravel_pytree(terms.vf(t0, unravel(y), args))[0])
        r = gauss_step(field, jacobian, tab, flat, e, h, Y0, max_iterations=self.max_iterations,
                       implicit_gradients=True)
        _, bound = local_error(self._field(terms, args, unravel, t0 + h * tab["check_nodes"]), tab, flat, e, h, r.L)
        finite = jnp.all(jnp.isfinite(r.z))
        ok = r.converged & finite
        result = diffrax.RESULTS.where(
            ok, diffrax.RESULTS.successful,
            diffrax.RESULTS.where(finite, diffrax.RESULTS.promote(optx.RESULTS.nonlinear_max_steps_reached),
                                  diffrax.RESULTS.promote(optx.RESULTS.nonlinear_divergence)))
        y_error = jnp.where(ok, bound, jnp.inf)
        dense_info = dict(y0=y0, e0=e, L=r.L)
        return unravel(r.z), unravel(y_error), dense_info, GaussLegendreState(r.z, r.e, r.L, h), result

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


# ====================================================================== splitting methods
class SplittingSolverState(NamedTuple):
    """What a splitting step hands the next: the state (q, p) it ended at, the compensation of each
    (the part of the sum float64 could not hold), and the kick term's vector field at that q
    (None for a scheme that does not begin and end with a kick: nothing is carried then)."""

    y: Any
    e: Any
    force: Any


def _carries_force(scheme: SplittingScheme) -> bool:
    """Whether the step begins and ends with a kick: the force at its end is the next one's first."""
    b = scheme.b_f
    return float(b[0]) != 0.0 and float(b[-1]) != 0.0


def _scaled(control: Any, c: float) -> Any:
    """A step's control times a flow's coefficient (for an ``ODETerm``: c·h)."""
    return jtu.tree_map(lambda x: c * x, control)


def _compensated_add(x: Any, e: Any, d: Any) -> tuple[Any, Any]:
    """(x, e) + d leaf by leaf, x + e being the value before and after (Kahan–Babuška)."""
    y = jtu.tree_map(lambda di, ei: di + ei, d, e)
    s = jtu.tree_map(lambda xi, yi: xi + yi, x, y)
    return s, jtu.tree_map(lambda xi, si, yi: (xi - si) + yi, x, s, y)


def _same(a: Any, b: Any) -> jax.Array:
    """Whether two PyTrees of arrays hold the same numbers (a scalar bool)."""
    leaves = [jnp.all(x == y) for x, y in zip(jtu.tree_leaves(a), jtu.tree_leaves(b))]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


class _Flows(NamedTuple):
    """A step's flows: kick i at t0 + κ_i·(t1 − t0), drift i at t0 + δ_i·(t1 − t0)."""

    a: tuple[float, ...]
    b: tuple[float, ...]
    kick_at: tuple[float, ...]  # κ_i = a_0 + … + a_{i−1}: time moves with the drifts
    drift_at: tuple[float, ...]  # δ_i = b_0 + … + b_i: time moves with the kicks


def _flows(scheme: SplittingScheme) -> _Flows:
    a = tuple(float(x) for x in scheme.a_f)
    b = tuple(float(x) for x in scheme.b_f)
    kick_at = tuple(float(x) for x in np.concatenate([[0.0], np.cumsum(a)]))
    drift_at = tuple(float(x) for x in np.cumsum(b)[:len(a)])
    return _Flows(a, b, kick_at, drift_at)


class SplittingSolver(diffrax.AbstractSolver):
    """An explicit symplectic splitting method for a separable H = T(p) + V(q), for
    ``diffrax.diffeqsolve`` on the pair of terms Diffrax's ``SemiImplicitEuler`` takes:

        terms = (ODETerm(lambda t, p, args: dT/dp), ODETerm(lambda t, q, args: −dV/dq)),
        y0 = (q0, p0)   (two PyTrees).

    A step of length h is the composition B(b_0) A(a_0) B(b_1) … A(a_{m−1}) B(b_m) of the scheme's
    drifts A(c): q ← q + (first term over c·h) and kicks B(c): p ← p + (second term over c·h),
    each the exact flow of its part: symplectic, and time-reversible for a symmetric scheme, for
    any h; of the scheme's order (2 to 10; ``atlasnn.solutions.SPLITTING_SCHEMES``; a Nyström
    scheme, ``nystrom=True``, has it only for T quadratic in p). It is the step
    of ``atlasnn.solve(..., solver=SplittingComposition(scheme=...))`` (same flows, same order of
    operations, the state summed with compensation) and for the same step lengths gives the same
    numbers to round-off.

    * Steps: fixed (``diffrax.ConstantStepSize``, or ``StepTo``); there is no error estimate, so no
      adaptive controller. Constant steps keep the method symplectic: the energy error of a
      Hamiltonian system stays bounded over long times.
    * Cost: a scheme that begins and ends with a kick carries its last force into the next step
      (kept in the solver state, recomputed after a jump of the vector field): one evaluation of
      the kick term per nonzero kick minus one, and one of the drift term per nonzero drift.
    * Dense output (``SaveAt(ts=...)``, ``SaveAt(dense=True)``, events): the cubic Hermite
      interpolant of the step's two ends and the vector field there (``diffrax``'s
      ``ThirdOrderHermitePolynomialInterpolation``): between the step ends its error is the
      scheme's plus O(h⁴) (the step ends have the scheme's order). Its end rates cost two more
      evaluations of the drift term a step (and two of the kick term for a scheme that does not
      carry its force), only where dense output is asked for.
    * Time-dependent terms: a kick is evaluated at the time the drifts before it have reached, a
      drift at the time the kicks before it have reached; with only V (or only T) depending on t
      the scheme keeps its order. The control of each flow is the step's control ``contr(t0, t1)``
      times the flow's coefficient (exact for ``ODETerm``).
    * Gradients through ``RecursiveCheckpointAdjoint`` (the default) and ``ForwardMode``;
      ``jax.vmap``; any float dtype (float64 for round-off-level results).

    Attributes:
        scheme: the scheme's name: one of ``atlasnn.solutions.SPLITTING_SCHEMES`` (for example
            ``"leapfrog"``, ``"yoshida4"``, ``"kahan_li8"``).
    """

    term_structure: ClassVar = (diffrax.AbstractTerm, diffrax.AbstractTerm)
    interpolation_cls: ClassVar[Callable[..., diffrax.ThirdOrderHermitePolynomialInterpolation]] = (
        diffrax.ThirdOrderHermitePolynomialInterpolation)

    scheme: str = eqx.field(static=True)

    def __check_init__(self):
        if not isinstance(self.scheme, str) or self.scheme not in SPLITTING_SCHEMES:
            raise ConfigError(f"SplittingSolver scheme must be one of {', '.join(SPLITTING_SCHEMES)}; "
                              f"got {self.scheme!r}")

    @property
    def table(self) -> SplittingScheme:
        """The scheme's coefficients."""
        return splitting_scheme(self.scheme)

    def order(self, terms) -> int:
        """The scheme's order at the step ends (a Nyström scheme's for T quadratic in p)."""
        del terms
        return int(self.table.order)

    def error_order(self, terms) -> None:
        """None: the solver makes no error estimate."""
        del terms
        return None

    # ------------------------------------------------------------------ the step
    def init(self, terms, t0, t1, y0, args) -> SplittingSolverState:
        del t1
        zeros = jtu.tree_map(lambda x: jnp.zeros_like(jnp.asarray(x)), y0)
        force = terms[1].vf(t0, y0[0], args) if _carries_force(self.table) else None
        return SplittingSolverState(y0, zeros, force)

    def _first_force(self, kick_term, t0, q0, args, state: SplittingSolverState, same, made_jump):
        """The kick term's field at (t0, q0): the carried one unless the vector field jumped at t0 or
        y0 is not the state the carried force was made for (then evaluated again)."""
        if not _carries_force(self.table):
            return None
        stale = jnp.logical_not(same) if made_jump is False else jnp.logical_not(same) | made_jump
        return lax.cond(eqxi.unvmap_any(stale), lambda: kick_term.vf(t0, q0, args), lambda: state.force)

    def step(self, terms, t0, t1, y0, args, solver_state: SplittingSolverState, made_jump):
        drift_term, kick_term = terms
        q0, p0 = y0
        same = _same(y0, solver_state.y)
        eq, ep = jtu.tree_map(lambda e: jnp.where(same, e, jnp.zeros_like(e)), solver_state.e)
        drift_control, kick_control = drift_term.contr(t0, t1), kick_term.contr(t0, t1)
        dt = t1 - t0
        fl = _flows(self.table)
        first = force = self._first_force(kick_term, t0, q0, args, solver_state, same, made_jump)
        q, p = q0, p0
        for i, b in enumerate(fl.b):
            if b != 0.0:
                if force is None:  # the previous flow moved q (or nothing is carried): evaluate here
                    force = kick_term.vf(t0 + fl.kick_at[i] * dt, q, args)
                p, ep = _compensated_add(p, ep, kick_term.prod(force, _scaled(kick_control, b)))
            if i < len(fl.a) and fl.a[i] != 0.0:
                velocity = drift_term.vf_prod(t0 + fl.drift_at[i] * dt, p, args, _scaled(drift_control, fl.a[i]))
                q, eq = _compensated_add(q, eq, velocity)
                force = None
        y1 = (q, p)
        last = force if force is not None else kick_term.vf(t1, q, args)  # the field at q1
        dense_info = {"y0": y0, "y1": y1,
                      "k0": self._rates(terms, t0, y0, args, first, drift_control, kick_control),
                      "k1": self._rates(terms, t1, y1, args, last, drift_control, kick_control)}
        carried = force if _carries_force(self.table) else None
        return y1, None, dense_info, SplittingSolverState(y1, (eq, ep), carried), diffrax.RESULTS.successful

    @staticmethod
    def _rates(terms, t, y, args, force, drift_control, kick_control) -> tuple[Any, Any]:
        """h·dy/dt at (t, y) (the Hermite interpolant's end rates), the kick term's field being
        ``force`` when known (evaluated otherwise)."""
        drift_term, kick_term = terms
        q, p = y
        if force is None:
            force = kick_term.vf(t, q, args)
        return drift_term.vf_prod(t, p, args, drift_control), kick_term.prod(force, kick_control)

    def func(self, terms, t0, y0, args):
        """(dq/dt, dp/dt) at (t0, y0)."""
        q0, p0 = y0
        return terms[0].vf(t0, p0, args), terms[1].vf(t0, q0, args)

"""The Gauss collocation as a Diffrax solver: ``GaussLegendre`` for ``diffrax.diffeqsolve``.

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
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

try:
    import diffrax
except ImportError:  # the optional extra
    raise ImportError("atlasnn.solver.diffrax needs Diffrax: pip install 'atlasnn[diffrax]'") from None
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx  # a dependency of Diffrax: the results of a nonlinear solve
from jax import lax
from jax.flatten_util import ravel_pytree

from atlasnn.errors import ConfigError
from atlasnn.solutions import MAX_STAGES, gauss_tableau, shifted_legendre, window_value
from atlasnn.solver._gauss_step import continued_stages, gauss_step, local_error, tableau_arrays

__all__ = ["GaussLegendre", "GaussLegendreInterpolation", "GaussLegendreState"]


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

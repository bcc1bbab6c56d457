"""The parametric DOP853 solve: dz/dt = J∇H(z; θ) with θ an argument, optionally with forward
sensitivities S = ∂z/∂(θ, z0) integrated beside it (the variational equations
dS/dt = A(z, θ) S + ∂f/∂θ · D, A = ∂f/∂z, one column per direction; a column is one forward-mode
derivative of f). f is built from ``system.parametric`` and jitted once per system in float64;
θ reaches it as an argument of SciPy's ``solve_ivp``, so a new θ compiles nothing. The vectorised
members' reference (:func:`reference_members`) uses it, and shooting where asked for it
(``solver="dop853"``, :func:`atlasnn.inverse.parametric_solver`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

from atlasnn.compile_cache import program_cache
from atlasnn.errors import ParametricSolveFailed
from atlasnn.systems import HamiltonianSystem, parametric_field

__all__ = ["solve_parametric", "ParametricSolveFailed"]


@program_cache
@functools.lru_cache(maxsize=32)
def _compiled(system: HamiltonianSystem):
    """(f, g): jitted f(z, θ) = J∇H(z; θ) and g(y, θ, D) = d/dt [z, S] for the variational system."""
    n = system.state_dim
    field_ = parametric_field(system)

    def augmented(y, theta, dtheta):
        z, S = y[:n], y[n:].reshape(n, dtheta.shape[1])
        # column k: A S_k + ∂f/∂θ D_k, one forward-mode derivative of f in the direction (S_k, D_k)
        dS = jax.vmap(lambda s, dth: jax.jvp(field_, (z, theta), (s, dth))[1], in_axes=(1, 1), out_axes=1)(S, dtheta)
        return jnp.concatenate([field_(z, theta), dS.reshape(-1)])

    return jax.jit(field_), jax.jit(augmented)


def _rhs(fn):
    def rhs(t, y, *args):
        out = np.asarray(fn(y, *args))
        if not np.all(np.isfinite(out)):
            raise ParametricSolveFailed(f"the right-hand side is not finite at t = {t:.6g}")
        return out
    return rhs


def solve_parametric(system, z_init, theta, t0, times, rtol, atol, S_init=None, dtheta=None):
    """(Z (len(times), 2d), S (len(times), 2d, m) or None, nfev) from z_init at t0; times sorted ≥ t0."""
    f, g = _compiled(system)
    n = system.state_dim
    grid, inverse = np.unique(times, return_inverse=True)
    with_s = dtheta is not None
    y0 = np.concatenate([z_init, S_init.reshape(-1)]) if with_s else np.asarray(z_init, np.float64)
    if grid[-1] <= t0:
        Y, nfev = np.repeat(y0[None], grid.size, axis=0), 0
    else:
        with jax.enable_x64(True):
            args = (jnp.asarray(theta, jnp.float64),) + ((jnp.asarray(dtheta, jnp.float64),) if with_s else ())
            try:
                sol = solve_ivp(_rhs(g if with_s else f), (t0, float(grid[-1])), y0, method="DOP853",
                                t_eval=grid, rtol=rtol, atol=atol, args=args)
            except ParametricSolveFailed as exc:
                raise ParametricSolveFailed(f"DOP853 stopped: {exc}") from None
        if not sol.success or sol.y.shape[1] != grid.size or not np.all(np.isfinite(sol.y)):
            raise ParametricSolveFailed(f"DOP853 failed: {' '.join(str(sol.message).split())}")
        Y, nfev = sol.y.T, int(sol.nfev)
    Y = Y[inverse]
    S = Y[:, n:].reshape(len(times), n, -1) if with_s else None
    return Y[:, :n], S, nfev

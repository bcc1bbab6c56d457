"""One window of the Gauss collocation: the stage equations solved, the end state added with
compensated summation. Pure JAX functions (traceable, batched by ``vmap``); the march
(:mod:`._gauss_march`) and the Diffrax solver (:mod:`atlasnn.solver.diffrax`) both step with
:func:`gauss_step`, so the two doors compute the same numbers.

The equations, with L_i = h b_i f(Y_i) (:mod:`atlasnn.solutions._tableau`):

    L = hb ⊙ f(z + (e + μ L)),     z_{n+1} + e_{n+1} = z_n + (e_n + Σ_i L_i),

e the compensation of the summation (the part of z_n + e_n float64 could not hold). They are solved
by fixed-point iteration over all stages at once, from a guess of the stages (the previous window's
polynomial continued into this one), until the update is zero or has not shrunk for two iterations
in a row: the iteration has reached round-off, which needs no tolerance to tune. Where it does not
get there — it diverges or stalls above round-off: a stiff term, or a step too long for the
iteration to contract — the window is solved again by simplified Newton iterations with the
Jacobian at z_n, the matrix I − (diag(hb) μ) ⊗ A(z_n) decoupled into ⌈s/2⌉ complex n × n systems
by the eigenvectors of diag(b) μ (:func:`_newton`).
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from atlasnn.compile_cache import program_cache
from atlasnn.solutions import shifted_legendre

__all__ = ["StepResult", "gauss_step", "solved_step", "solve_stages", "compensated_add", "small_matmul", "continued_stages",
           "local_error", "tableau_arrays", "FIXED_POINT_FLOOR", "stage_share",
           "fixed_point_unroll"]

#: fixed-point iterations per trip of the loop (measured on Hénon–Heiles, s = 12: 6.1 µs a window
#: with 1, 4.1 µs with 3)
FIXED_POINT_UNROLL = 3
#: a field traced to more operations than this is iterated once per trip: each unrolled iteration
#: is another copy of it to trace and compile, and a trip's overhead is small beside it (the outer
#: solar system as an expression, 778 operations: a cold first solve 4.7 → 3.9 s, the march as fast;
#: Hénon–Heiles 67, FPUT and NLS on arrays 63 and 106, the Pythagorean problem's expression 166)
LARGE_FIELD = 150


@program_cache
@functools.lru_cache(maxsize=64)
def fixed_point_unroll(system) -> int:
    """The fixed-point iterations per trip of the loop for ``system``'s field: FIXED_POINT_UNROLL,
    or 1 where the field is large (LARGE_FIELD operations, counted on its trace for one state)."""
    with jax.enable_x64(True):
        jaxpr = jax.make_jaxpr(system.vector_field)(jax.ShapeDtypeStruct((1, system.state_dim), jnp.float64))
    return 1 if _operations(jaxpr.jaxpr) > LARGE_FIELD else FIXED_POINT_UNROLL


def _operations(jaxpr) -> int:
    """The equations of a jaxpr, those of the jaxprs inside its equations included."""
    n = 0
    for eqn in jaxpr.eqns:
        n += 1
        for param in eqn.params.values():
            inner = getattr(param, "jaxpr", None)
            if inner is not None:
                n += _operations(getattr(inner, "jaxpr", inner))
    return n


#: the fixed-point iteration counts as converged when its smallest update is at most this times
#: max|L| (round-off of the stages, with room for a vector field that loses a few digits)
FIXED_POINT_FLOOR = 1e-12


#: the share of the tolerance that the stage equations' error may take, spread over the interval's
#: windows (:func:`stage_share`)
STAGE_SHARE = 1e-2


def stage_share(rtol, windows):
    """How far above round-off the fixed-point iteration may stop: at an update of
    ``STAGE_SHARE · rtol / windows`` of each component's size, the windows the march's interval
    will take — so that the equations' error, added up over every window (it is the map's own and
    may drift), stays a hundredth of rtol. 0 (round-off) where that is below FIXED_POINT_FLOOR: at
    rtol 1e-11, or over thousands of windows, nothing changes; at 1e-5 over 50 windows it stops at
    2e-9 (Hénon–Heiles: 26 → 13 iterations a window, the same error; docs/SOLVER.md)."""
    share = STAGE_SHARE * rtol / jnp.maximum(windows, 1.0)
    return jnp.where(share > FIXED_POINT_FLOOR, share, 0.0)


class StepResult(NamedTuple):
    """One window solved: the end state and its compensation, the stage increments L (s, n), the
    iterations spent, whether the equations were solved (to round-off, or to ``enough``:
    :func:`stage_share`), and whether Newton was used."""

    z: jax.Array
    e: jax.Array
    L: jax.Array
    iterations: jax.Array
    converged: jax.Array
    newton: jax.Array


#: M @ X is a fused broadcast product while X (s × n) has at most this many entries, a dot above
#: (per fixed-point iteration on a CPU, FPUT chains: the product 0.7 µs against the dot's 1.9 at
#: 12 × 4, even at 12 × 8, the dot 2.3× faster at 12 × 32 and 3.3× at 12 × 2 048)
SMALL_PRODUCT = 96


def small_matmul(M, X: jax.Array) -> jax.Array:
    """M @ X for the small matrices of a window (s × s by s × n). For a few entries, a broadcast
    product and a sum, which XLA fuses with the field around it (the dot is a library call of fixed
    cost: 3× slower per fixed-point iteration on Hénon–Heiles, s = 12); for more, the dot (XLA's
    reduction over the middle axis of the product does not vectorise: per iteration it cost 4–5×
    the field's evaluations at n = 512, measured on FPUT chains)."""
    if X.shape[-2] * X.shape[-1] <= SMALL_PRODUCT:
        return jnp.sum(M[:, :, None] * X[None, :, :], axis=1)
    return jnp.matmul(M, X, precision=lax.Precision.HIGHEST)


def compensated_add(z: jax.Array, e: jax.Array, increment: jax.Array) -> tuple[jax.Array, jax.Array]:
    """z + e + increment as a new (z, e) pair: Kahan's compensated summation, so that the rounding
    of the many small increments of a long march does not accumulate."""
    total = e + increment
    new = z + total
    return new, (z - new) + total


def continued_stages(tab, z: jax.Array, e: jax.Array, L_prev: jax.Array, ratio) -> jax.Array:
    """The guess of this window's stage values: the previous window's polynomial continued to the
    nodes of this one, Y_i = z_n + (ẑ_prev(1 + ratio·c_i) − ẑ_prev(1)), ``ratio`` the new length
    over the previous one (the previous window's values are relative to its start, its end
    is z_n)."""
    s = tab["c"].shape[0]
    theta = 1.0 + ratio * tab["c"]
    basis = shifted_legendre(theta, s, jnp) - shifted_legendre(jnp.ones(1, theta.dtype), s, jnp)  # (s, s + 1)
    return z + (e + small_matmul(basis @ tab["series"].T, L_prev))


def _iterate(update, L0, scale, max_iterations, unroll=1, enough=0.0):
    """Iterate ``L ← update(L)`` from L0 until round-off: until the update is zero, or its size has
    not fallen below its smallest so far for two iterations in a row (IRKGL16's rule, on the
    largest entry of the update relative to ``scale``, its component's size (n,): the rule entry by
    entry, as IRKGL16 states it for a few components, keeps going while any of them happens to
    reach a new low by round-off, which with thousands of components took 80 iterations where 10
    sufficed). ``unroll`` iterations per trip of the loop (the rule is checked after each, the
    loop left between trips: a trip of XLA's loop costs several iterations' worth on a CPU, so a
    few iterations at round-off are cheaper than the trips they save). Returns (L, iterations, the
    smallest update's largest entry, the last update's largest entry). ``enough``: an update whose
    largest entry relative to ``scale`` is at most this also ends it (0: only round-off does)."""

    def body(carry):
        L, k, rmin, stall, dmin, dlast = carry
        for _ in range(unroll):
            new = update(L)
            d = jnp.abs(new - L)
            r = jnp.max(d / scale)
            dmax = jnp.max(d)
            L, k, stall = new, k + 1, jnp.where(r < rmin, 0, stall + 1)
            rmin, dmin, dlast = jnp.minimum(r, rmin), jnp.minimum(dmax, dmin), dmax
        return L, k, rmin, stall, dmin, dlast

    def going(carry):
        _, k, rmin, stall, _, dmax = carry
        return (k < max_iterations) & (stall < 2) & (dmax > 0) & jnp.isfinite(dmax) & ~(rmin <= enough)

    inf = jnp.asarray(jnp.inf, L0.dtype)
    big = jnp.asarray(jnp.finfo(L0.dtype).max, L0.dtype)
    start = (L0, jnp.asarray(0), inf, jnp.asarray(0), inf, big)
    L, k, _, _, dmin, dlast = lax.while_loop(going, body, start)
    return L, k, dmin, dlast


def _scale(z, L0):
    """Each component's size for the iteration's rule: |z| + the largest stage increment, never zero."""
    w = jnp.abs(z) + jnp.max(jnp.abs(L0), axis=0)
    return jnp.maximum(w, jnp.finfo(w.dtype).tiny)


def _fixed_point(field, tab, z, e, hb, L0, max_iterations, enough=0.0, unroll=FIXED_POINT_UNROLL):
    """L by fixed-point iteration from L0 = hb ⊙ f(Y0), Y0 the stage guess: (L, iterations counting
    L0's evaluation, whether it reached round-off — or, with ``enough`` > 0, an update whose largest
    entry relative to its component's size is at most ``enough``)."""
    mu = tab["mu"]
    scale = _scale(z, L0)
    L, k, dmin, dlast = _iterate(lambda L: hb[:, None] * field(z + (e + small_matmul(mu, L))), L0,
                                 scale, max_iterations, unroll=unroll, enough=enough)
    return L, k + 1, _solved(L, L0, dmin, dlast, enough * jnp.max(scale))


def _dense_factor(jacobian: Callable) -> Callable:
    """The Newton matrix from the field's Jacobian at z_n: ``factor(z, shifts)`` LU-factorises
    I − c_j A(z) for each shift and returns the solve of those systems (one right-hand side each)."""
    def factor(z, shifts):
        a = jacobian(z).astype(shifts.dtype)
        eye = jnp.eye(a.shape[0], dtype=a.dtype)
        factors = jax.vmap(lambda c: jax.scipy.linalg.lu_factor(eye - c * a))(shifts)
        return lambda r: jax.vmap(lambda lu, piv, rj: jax.scipy.linalg.lu_solve((lu, piv), rj))(*factors, r)

    return factor


#: with a declared linear part, each component's size for the iteration's rule is at least this
#: times the largest one's: the shifted solves are global (FFTs), so every component carries
#: round-off of the largest, and a component near zero (a soliton's tail) would otherwise stop the
#: iteration on its noise while the others still converge (NLS, 1 024 points: stopped at 3e-11;
#: with 1e-8 here, 512 points stopped at 1e-13 of max|L| now and then, and the window was halved:
#: the noise of a component of relative size f is eps/f of the largest's, so f must be ≫ eps/1e-12)
GLOBAL_FLOOR = 1e-2


def _mode_solve(factor, tab, z, h) -> Callable:
    """r ↦ (I − h (diag(b) μ) ⊗ A)⁻¹ r for stage arrays r (s, n), decoupled (Hairer & Wanner, *Solving
    ODEs II*, IV.8): the matrix is block-diagonalised by the eigenvectors V of diag(b) μ, so that
    the solve is one of I − hλ_j A per eigenvalue λ_j — s/2 complex systems of size n (the conjugate
    of each pair gives the conjugate solution), not one of size s·n. ``factor(z, shifts)``: the
    solves of I − c A (:func:`_dense_factor`, or a declared linear part's ``factor``, which ignores
    z). Linear in r (reverse mode transposes it: :func:`_tangent_solve`)."""
    lam, to_modes, from_modes = tab["newton_lam"], tab["newton_to"], tab["newton_from"]
    m = lam.shape[0]
    cdtype = jnp.result_type(z.dtype, jnp.complex64)  # complex of the state's precision
    solve = factor(z, h * jnp.asarray(lam, cdtype))
    # the maps to the modes and back as real products (the residual and the update are real): a
    # complex product of a real array cost 4-5x as much (NLS, 1 024 components, s = 16)
    to_real = jnp.asarray(np.concatenate([to_modes.real, to_modes.imag]), z.dtype)  # (2m, s)
    from_real = jnp.asarray(np.concatenate([from_modes.real, -from_modes.imag], axis=1), z.dtype)  # (s, 2m)

    def apply(r):
        r = jnp.matmul(to_real, r, precision=lax.Precision.HIGHEST)
        x = solve(lax.complex(r[:m], r[m:]))
        return jnp.matmul(from_real, jnp.concatenate([jnp.real(x), jnp.imag(x)]), precision=lax.Precision.HIGHEST)

    return apply


def _newton(field, factor, tab, z, e, hb, L0, max_iterations, floor=0.0, noise=0.0):
    """L by simplified Newton iterations from L0, each step one decoupled solve with the window's
    matrix I − h (diag(b) μ) ⊗ A (:func:`_mode_solve`), A the field's Jacobian at z_n or a declared
    linear part. V's conditioning (1e6 at s = 12) only slows the iteration a little: each step is
    checked against the true residual, so the result is the same to round-off. Returns (L,
    iterations, whether it reached round-off)."""
    mu = tab["mu"]
    solve = _mode_solve(factor, tab, z, jnp.sum(hb))

    def update(L):
        return L - solve(L - hb[:, None] * field(z + (e + small_matmul(mu, L))))

    scale = _scale(z, L0)
    L, k, dmin, dlast = _iterate(update, L0, jnp.maximum(scale, floor * jnp.max(scale)), max_iterations)
    return L, k, _solved(L, L0, dmin, dlast, noise)


def _solved(L, L0, dmin, dlast, noise=0.0):
    """Whether the iteration reached round-off: finite, its smallest update at most
    FIXED_POINT_FLOOR and its last at most 100·FIXED_POINT_FLOOR of the stages' size (the smaller of
    the guess's and the result's, so that a diverging iteration, whose result grows, is not judged
    by its own size) — or at most ``noise``, the round-off of the field's evaluation itself where
    that is larger (a stiff linear part: its products carry eps·‖JS‖·|z|)."""
    scale = jnp.minimum(jnp.max(jnp.abs(L)), jnp.max(jnp.abs(L0)))
    floor = jnp.maximum(FIXED_POINT_FLOOR * scale, noise)
    return (jnp.all(jnp.isfinite(L)) & jnp.isfinite(dlast) & (dmin <= floor) & (dlast <= 100 * floor))


def solve_stages(field: Callable, jacobian: Callable | None, tab: dict, z: jax.Array, e: jax.Array, hb: jax.Array,
                 L0: jax.Array, max_iterations: int, linear=None, enough=0.0,
                 unroll: int = FIXED_POINT_UNROLL) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """The stage equations L = hb ⊙ f(z + (e + μL)) solved from L0 = hb ⊙ f(Y0): by fixed-point
    iteration, and by simplified Newton where that fails and ``jacobian`` is given; with a
    ``linear`` part (:class:`atlasnn.systems.LinearPart`), by simplified Newton with it as the
    matrix from the start (the fixed-point iteration would not contract on its stiff modes).
    ``enough``: the fixed-point iteration may stop above round-off, at an update of at most this
    relative to each component's size (:func:`stage_share`; 0: round-off); ``unroll``: its
    iterations per trip of the loop (:func:`fixed_point_unroll`). Returns (L, iterations,
    whether it reached round-off or ``enough``, whether Newton was used). Forward only:
    its loops cannot be differentiated in reverse (:func:`gauss_step` with ``implicit_gradients``)."""
    if linear is not None:
        # the round-off an evaluation of the stiff part carries into L: a few ulps of ‖JS‖·|z| times h·b_i
        # (NLS with 4 096 points, ‖JS‖ = 2e4: above FIXED_POINT_FLOOR of the stages' size)
        noise = 8 * jnp.finfo(z.dtype).eps * linear.norm() * jnp.max(jnp.abs(z)) * jnp.max(jnp.abs(hb))
        L, k, ok = _newton(field, lambda _, shifts: linear.factor(shifts), tab, z, e, hb, L0, max_iterations,
                           GLOBAL_FLOOR, noise)
        return L, k, ok, jnp.asarray(True)
    L, k, ok = _fixed_point(field, tab, z, e, hb, L0, max_iterations, enough, unroll)
    used_newton = jnp.asarray(False)
    if jacobian is not None:
        # a loop that runs once when the fixed-point iteration failed and not at all otherwise: in a
        # batch (vmap) only a member that needs it makes the batch pay for the factorisation
        def newton(carry):
            _, _, k_fp, _, _ = carry
            L_n, k_n, ok_n = _newton(field, _dense_factor(jacobian), tab, z, e, hb, L0, max_iterations)
            return L_n, ok_n, k_fp + k_n, jnp.asarray(False), jnp.asarray(True)

        L, ok, k, _, used_newton = lax.while_loop(lambda c: c[3], newton, (L, ok, k, ~ok, used_newton))
    return L, k, ok, used_newton


#: the tangent iteration stops once its update is at most this relative to the right-hand side (a
#: derivative to ~1e-14 of its size; iterating on to round-off cost a third more iterations)
TANGENT_ENOUGH = 1e-14
#: the largest stage system (s·n unknowns) whose tangent solve falls back to a dense LU when the
#: linear iteration does not converge (the window was a stiff one, solved by Newton)
DENSE_TANGENT_SIZE = 1024


def _dense_tangent_solve(linear: Callable, y: jax.Array) -> jax.Array:
    """x with linear(x) = y: the (sn × sn) matrix of ``linear`` from sn products with the unit
    vectors, then one LU solve."""
    shape = y.shape
    size = y.size
    columns = jax.vmap(linear)(jnp.eye(size, dtype=y.dtype).reshape((size,) + shape))
    return jnp.linalg.solve(columns.reshape(size, size).T, y.reshape(-1)).reshape(shape)


def _linear_iteration(linear: Callable, y: jax.Array, max_iterations: int, precondition=None) -> jax.Array:
    """x with linear(x) = y, ``linear`` = I − K the stage equations' residual linearised at their
    solution (or its transpose), by the iteration x ← y + K x from x = y: it contracts as the
    fixed-point iteration of the stages did (the same K), at the cost of one derivative of the
    field at the stages an iteration. With ``precondition`` (P⁻¹, P the Newton matrix of a declared
    linear part, or its transpose), x ← x + P⁻¹(y − linear(x)) from x = P⁻¹y: it contracts as the
    Newton iteration of the stages did. Where it does not reach round-off (the window was stiff and
    solved by Newton, or a declared linear part far from H's own preconditions it), the dense solve
    for at most DENSE_TANGENT_SIZE unknowns, else restarted GMRES; a derivative neither finds
    raises (TANGENT_FAILED), never a silent NaN."""
    scale = jnp.full(y.shape[-1], jnp.maximum(jnp.max(jnp.abs(y)), jnp.finfo(y.dtype).tiny))
    if precondition is None:
        x, _, dmin, dlast = _iterate(lambda x: y + (x - linear(x)), y, scale, max_iterations,
                                     unroll=FIXED_POINT_UNROLL, enough=TANGENT_ENOUGH)
    else:
        x, _, dmin, dlast = _iterate(lambda x: x + precondition(y - linear(x)), precondition(y), scale,
                                     max_iterations, enough=TANGENT_ENOUGH)
    size = jnp.maximum(jnp.max(jnp.abs(x)), jnp.max(jnp.abs(y)))
    ok = jnp.isfinite(dlast) & (dmin <= FIXED_POINT_FLOOR * size)
    fallback = (lambda: _dense_tangent_solve(linear, y)) if y.size <= DENSE_TANGENT_SIZE \
        else (lambda: _krylov_tangent_solve(linear, y, precondition))
    # a loop that runs once where the iteration failed (under vmap only such members pay for it)
    x = lax.while_loop(lambda c: ~c[1], lambda c: (fallback(), jnp.asarray(True)), (x, ok))[0]
    return eqx.error_if(x, ~jnp.all(jnp.isfinite(x)), TANGENT_FAILED)


#: the one line a derivative raises when its stage equations' linear solve found no solution
TANGENT_FAILED = ("solve: the derivative of a window's stage equations did not converge (the stage equations are "
                  "singular there, or a declared linear_part is far from H's quadratic part: declare the exact S, "
                  "or none); no gradient was returned")


def _krylov_tangent_solve(linear: Callable, y: jax.Array, precondition=None) -> jax.Array:
    """x with linear(x) = y by restarted GMRES (JAX's), preconditioned as the stationary iteration
    was: it converges where that one's iteration matrix has eigenvalues outside the unit disc (a
    declared linear part far from H's own, whose Newton matrix is a poor inverse). NaN where its
    residual stays above TANGENT_RESIDUAL of y."""
    x, _ = jax.scipy.sparse.linalg.gmres(linear, y, M=precondition, tol=1e-13, atol=0.0, restart=40, maxiter=20)
    residual = jnp.max(jnp.abs(linear(x) - y))
    return jnp.where(residual <= TANGENT_RESIDUAL * jnp.max(jnp.abs(y)), x, jnp.nan)


#: the relative residual a Krylov tangent solve must reach to be taken
TANGENT_RESIDUAL = 1e-10


def _tangent_solve(max_iterations: int, tab: dict | None = None, linear=None, z=None, h=None) -> Callable:
    """``lax.custom_root``'s tangent solve: :func:`_linear_iteration` as a ``lax.custom_linear_solve``
    (so that reverse mode transposes it: the same iteration on the transposed equations). With a
    declared ``linear`` part, preconditioned by the window's Newton matrix with it (:func:`_mode_solve`
    at the window's z and length h, which carry no derivative here), transposed for the transposed
    equations."""
    if linear is None:
        forward = transposed = None
    else:
        z, h = lax.stop_gradient(z), lax.stop_gradient(h)
        forward = _mode_solve(lambda _, shifts: linear.factor(shifts), tab, z, h)
        like = jnp.zeros((tab["mu"].shape[0], z.shape[-1]), z.dtype)

        def transposed(r):
            return jax.linear_transpose(forward, like)(r)[0]

    def solve(operator, y):
        return _linear_iteration(operator, y, max_iterations, forward)

    def transpose_solve(operator, y):
        return _linear_iteration(operator, y, max_iterations, transposed)

    return lambda operator, y: lax.custom_linear_solve(operator, y, solve, transpose_solve=transpose_solve)


def gauss_step(field: Callable, jacobian: Callable | None, tab: dict, z: jax.Array, e: jax.Array, h, Y0: jax.Array,
               *, max_iterations: int = 100, implicit_gradients: bool = False, linear=None,
               enough=0.0, unroll: int = FIXED_POINT_UNROLL) -> StepResult:
    """One window of length ``h`` from (z, e) with the stage guess Y0 (s, n).

    ``field`` maps stage values (s, n) to f(Y) (s, n); ``jacobian`` maps a state (n,) to A(z)
    (n, n), for the simplified Newton iteration (None: fixed-point only); ``tab`` holds the
    tableau's arrays (:func:`tableau_arrays`); ``linear``: the system's declared linear part, the
    Newton iteration's matrix from the start (:func:`solve_stages`); ``enough``: where the
    fixed-point iteration may stop above round-off (:func:`stage_share`; 0: it does not).

    ``implicit_gradients``: differentiable (forward and reverse) with respect to z, e, h and
    whatever ``field`` closes over, by the implicit function theorem on the stage equations
    (``lax.custom_root``: the solve is not differentiated; the derivative of its solution is one
    linear solve with the equations' Jacobian at the solution). The values are the same either way."""
    hb = h * tab["b"]
    L0 = hb[:, None] * field(Y0)
    if implicit_gradients:
        mu = tab["mu"]

        def residual(L):
            return L - hb[:, None] * field(z + (e + small_matmul(mu, L)))

        def solve(_, guess):
            # the counts travel as floats: custom_root gives its auxiliary outputs zero tangents of their
            # own dtype, which JAX refuses for integers and booleans (their tangents must be float0)
            L, k, ok, used = solve_stages(field, jacobian, tab, z, e, hb, guess, max_iterations, linear, enough, unroll)
            return L, jnp.stack([k, ok, used]).astype(L.dtype)

        L, aux = lax.custom_root(residual, L0, solve, _tangent_solve(max_iterations, tab, linear, z, h), has_aux=True)
        k, ok, used_newton = aux[0].astype(jnp.int32), aux[1] > 0, aux[2] > 0
    else:
        L, k, ok, used_newton = solve_stages(field, jacobian, tab, z, e, hb, L0, max_iterations, linear, enough, unroll)
    z1, e1 = compensated_add(z, e, jnp.sum(L, axis=0))
    return StepResult(z1, e1, L, k, ok, used_newton)


def solved_step(field: Callable, tab: dict, z: jax.Array, e: jax.Array, h, L: jax.Array,
                max_iterations: int = 100, linear=None) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(L, z_{n+1}, e_{n+1}) of a window whose stage equations were already solved (``L``, their
    solution from z, e and h), as a function of z, e, h and whatever ``field`` closes over: the
    values are L's own, the derivatives those of the implicit function (as ``gauss_step`` with
    ``implicit_gradients``), and nothing is iterated but the derivative's linear solve. The
    adjoint of a march walks its windows back through this (:mod:`._gauss_core`)."""
    hb = h * tab["b"]
    mu = tab["mu"]

    def residual(L):
        return L - hb[:, None] * field(z + (e + small_matmul(mu, L)))

    L = lax.custom_root(residual, lax.stop_gradient(L), lambda _, guess: guess,
                        _tangent_solve(max_iterations, tab, linear, z, h))
    z1, e1 = compensated_add(z, e, jnp.sum(L, axis=0))
    return L, z1, e1


def local_error(field: Callable, tab: dict, z: jax.Array, e: jax.Array, h, L: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The window's local error, estimated by its Picard correction D(θ) = ∫_0^θ f(ẑ) dt − (ẑ(θ) − z_n):
    the field at the s + 1 Gauss nodes of the window, integrated exactly for ẑ's degree (s + 1
    evaluations of f). Returns (|D(1)|, Σ_k |D_k|) per component: the error at the window's end and
    a bound of its largest value along the window (|P̃_k| ≤ 1), the dense output's error (order
    s + 1, larger than the end's 2s + 1 wherever h is not tiny). Measured against the true local
    error on Kepler and Hénon–Heiles: within 0.3–6× of it where it is above round-off."""
    F = field(z + (e + small_matmul(tab["check_values"], L)))
    D = h * small_matmul(tab["picard"], F) - small_matmul(tab["poly"], L)
    return jnp.abs(jnp.sum(D, axis=0)), jnp.sum(jnp.abs(D), axis=0)


def tableau_arrays(tab) -> dict:
    """The tableau's arrays that a step and its check read, as float64 NumPy arrays (traced or
    baked into a program by its caller), with the decoupled Newton iteration's (complex128): one
    eigenvalue λ of diag(b) μ per real one and per conjugate pair (``newton_lam``), the map of the
    stages onto those modes (rows of V⁻¹, ``newton_to``) and back (columns of V, a pair's doubled:
    the real part of V x sums the pair, ``newton_from``)."""
    out = {k: np.asarray(getattr(tab, k), np.float64) for k in ("b", "mu", "c", "series", "check_values", "picard",
                                                                "poly")}
    lam, vectors = np.linalg.eig(np.diag(out["b"]) @ out["mu"])
    inverse = np.linalg.inv(vectors)
    real = np.abs(lam.imag) <= 1e-12 * np.abs(lam)
    keep = np.flatnonzero(real | (lam.imag > 0))  # LAPACK returns a pair's vectors as conjugates
    out["newton_lam"] = np.where(real, lam.real, lam)[keep].astype(np.complex128)
    out["newton_to"] = inverse[keep].astype(np.complex128)
    out["newton_from"] = (vectors[:, keep] * np.where(real[keep], 1.0, 2.0)).astype(np.complex128)
    return out

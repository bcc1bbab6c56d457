"""sin and cos together in float32, for the sin network on a CPU (one range reduction, polynomials).

On CPU, XLA's sine and cosine are slow (about 2.7 ns per element on the reference machine, against
0.5 ns for exp) and XLA recomputes them inside every fused kernel that uses them, while the sin
network needs sin and cos of every pre-activation in the forward, tangent and backward passes. In
float32, :func:`sin_cos` evaluates both with one shared range reduction and polynomials (absolute
error ≤ 5e-8 for |x| ≤ 8192, ≤ 0.8 ulp for |x| ≤ 100; XLA's sin/cos are used for larger arguments
and in float64), 3–4× faster than XLA's pair on a [500, 80] array; through its custom JVP the
tangent and backward passes reuse the same sin and cos (docs/PERFORMANCE.md).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["sin_cos", "sin", "SINCOS_FAST_LIMIT"]

# Cody–Waite reduction by π/2 = P1 + P2 + P3: P1 has 8 significant bits, P2 11, so j·P1 and
# j·P2 are exact for |j| < 2^13; the two subtractions are carried with their rounding errors.
_PIO2_1 = np.float32(1.5703125)
_PIO2_2 = np.float32(4.837512969970703125e-4)
_PIO2_3 = np.float32(7.54978995489188216e-8)
_TWO_OVER_PI = np.float32(2 / np.pi)


def _fit_sincos_coefficients() -> tuple[tuple[np.float32, ...], tuple[np.float32, ...]]:
    """Polynomial coefficients for sin and cos on [−π/4, π/4], fitted here in float64.

    sin r = r + r·z·(s0 + s1 z + s2 z² + s3 z³) and cos r = 1 − z/2 + z²·(c0 + c1 z + c2 z²),
    z = r², by least squares on 400 Chebyshev nodes in z (max error 3e-12 for sin and 1e-10 for
    cos in float64, far below float32's rounding; tests/training/test_model_and_loss.py checks the float32
    result against jnp.sin/cos).
    """
    zmax = (np.pi / 4) ** 2
    k = np.arange(400)
    z = zmax * (1 - np.cos(np.pi * (k + 0.5) / 400)) / 2
    r = np.sqrt(z)
    s = np.linalg.lstsq(np.vander(z, 4, increasing=True) * (r * z)[:, None], np.sin(r) - r, rcond=None)[0]
    c = np.linalg.lstsq(np.vander(z, 3, increasing=True) * (z * z)[:, None], np.cos(r) - 1 + z / 2, rcond=None)[0]
    return tuple(np.float32(v) for v in s), tuple(np.float32(v) for v in c)


_S, _C = _fit_sincos_coefficients()
# Largest |x| for the polynomial path; beyond it XLA's sin/cos are used.
SINCOS_FAST_LIMIT = 8192.0


def _two_diff(a, b):
    """a − b = s + e exactly (Knuth's TwoSum)."""
    s = a - b
    bv = s - a
    av = s - bv
    return s, (a - av) - (b + bv)


def _sin_cos_poly(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(sin x, cos x) in float32 for |x| ≤ SINCOS_FAST_LIMIT, with one shared range reduction."""
    f32 = np.float32
    j = jnp.round(x * _TWO_OVER_PI)
    r1, e1 = _two_diff(x - j * _PIO2_1, j * _PIO2_2)
    r, e2 = _two_diff(r1, j * _PIO2_3)
    lo = e1 + e2  # x − jπ/2 = r + lo to about 2^-48 relative
    z = r * r
    hz = f32(0.5) * z
    w = f32(1) - hz
    sin_r = r + ((r * z) * (_S[0] + z * (_S[1] + z * (_S[2] + z * _S[3]))) + lo * w)
    cos_r = w + ((((f32(1) - w) - hz) + z * z * (_C[0] + z * (_C[1] + z * _C[2]))) - r * lo)
    q = j.astype(jnp.int32)
    odd = (q & 1) == 1
    s = jnp.where(odd, cos_r, sin_r)
    c = jnp.where(odd, sin_r, cos_r)
    return jnp.where((q & 2) == 2, -s, s), jnp.where(((q + 1) & 2) == 2, -c, c)


def _sin_cos_xla(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    return jnp.sin(x), jnp.cos(x)


@jax.custom_batching.custom_vmap
def _sin_cos_f32(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    fast = jnp.max(jnp.abs(x), initial=0.0) <= SINCOS_FAST_LIMIT
    return jax.lax.cond(fast, _sin_cos_poly, _sin_cos_xla, x)


@_sin_cos_f32.def_vmap
def _sin_cos_f32_batched(axis_size, in_batched, x):
    # Elementwise, so a batch (e.g. of seeds trained together) is one array: one test of the
    # range for the whole batch keeps a single branch, where plain vmap would turn the cond into
    # a select and evaluate both branches.
    return _sin_cos_f32(x), (in_batched[0], in_batched[0])


@jax.custom_jvp
def sin_cos(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(sin x, cos x) elementwise, differentiable to any order (d sin = cos, d cos = −sin).

    float32 arguments with |x| ≤ ``SINCOS_FAST_LIMIT`` use a shared Cody–Waite reduction and
    minimax polynomials: absolute error ≤ 5e-8 (XLA's: 3.3e-8), at most 0.8 ulp for |x| ≤ 100
    (XLA's: 0.56), mean 0.25 ulp like XLA's; near the zeros of sin/cos at |x| ≳ 1000 the error in
    ulps of the (tiny) result grows, the absolute error does not. Otherwise (a larger argument
    anywhere in x, NaN, float64, or a backend other than the CPU) ``jnp.sin`` and ``jnp.cos``;
    under ``vmap`` the range test covers the whole batch.
    """
    x = jnp.asarray(x)
    if x.dtype != jnp.float32:
        return _sin_cos_xla(x)
    # the polynomials pay on a CPU, where XLA's float32 sin/cos are slow; a GPU's are fast
    return jax.lax.platform_dependent(x, cpu=_sin_cos_f32, default=_sin_cos_xla)


@sin_cos.defjvp
def _sin_cos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sin_cos(x)
    return (s, c), (c * dx, -s * dx)


def sin(x: jax.Array) -> jax.Array:
    """sin x by :func:`sin_cos` (the network's default activation)."""
    return sin_cos(x)[0]

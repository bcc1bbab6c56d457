"""The s-stage Gauss–Legendre collocation tableau, in the form that keeps it symplectic in float64.

A window [t_n, t_n + h] of ATLAS-NN's trial solution with the linear time scaling and a polynomial
network of degree s − 1,

    ẑ(t_n + θh) = z_n + θh · N(θ),   θ ∈ [0, 1],

collocated at the s Gauss–Legendre nodes c_1..c_s of (0, 1) (dẑ/dt = J∇H(ẑ) there, as many
equations as unknowns) is the s-stage Gauss–Legendre Runge–Kutta method: with L_i = h b_i f(Y_i),

    Y_i = z_n + Σ_j μ_ij L_j,   z_{n+1} = z_n + Σ_i L_i,   μ_ij = a_ij / b_j,

symplectic, symmetric, of order 2s at the window ends, conserving every quadratic invariant
(Hairer, Lubich & Wanner, *Geometric Numerical Integration*, II.1.3 and VI.4). In this form the
condition for symplecticity, b_i a_ij + b_j a_ji = b_i b_j, reads μ_ij + μ_ji = 1 whatever the
weights are; the coefficients below are machine numbers that satisfy it exactly (μ_ij rounded to a
multiple of 2⁻⁵², μ_ji = 1 − μ_ij, μ_ii = 1/2), so the method that float64 computes is symplectic
up to the round-off of its arithmetic, not also up to that of its coefficients (Antoñana, Makazaga
& Murua, IRKGL16, Numer. Algorithms 2017).

The coefficients are computed once per s with mpmath at 40 digits. The window's polynomial (the
dense output) is held in the shifted Legendre basis P̃_k(θ) = P_k(2θ − 1), which is well
conditioned on [0, 1] and beyond it (the warm start of the next window evaluates it on [1, 2]),
in the trial solution's own form (exact at θ = 0 whatever L is):

    ẑ(t_n + θh) = z_n + θ Σ_{k<s} P̃_k(θ) Σ_j V_jk L_j,    dẑ/dt = (1/h) Σ_k P̃_k(θ) Σ_j W_jk L_j.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from atlasnn.errors import ConfigError

__all__ = ["GaussTableau", "gauss_tableau", "shifted_legendre", "legendre_integral", "window_value", "MAX_STAGES"]

#: more stages than this gain nothing in float64 (order 2s; s = 16 is order 32) and cost s² per iteration
MAX_STAGES = 16


@dataclass(frozen=True, eq=False)
class GaussTableau:
    """The coefficients of the s-stage Gauss–Legendre collocation (float64 NumPy arrays).

    Attributes:
        stages: s.
        c: the nodes c_i in (0, 1), increasing; ``b``: the quadrature weights (sum 1).
        mu: μ_ij = a_ij / b_j, with μ_ij + μ_ji = 1 exactly in float64.
        value: V (s, s): the window's value ẑ(θ) − z_n = θ·Σ_k P̃_k(θ) (Vᵀ L)_k, i.e. θh·N(θ).
        series: (s, s + 1): the same polynomial as one Legendre series, ẑ(θ) − z_n = Σ_k P̃_k(θ) (·ᵀ L)_k.
        rate: W (s, s + 1): its rate h·dẑ/dt = Σ_k P̃_k(θ) (Wᵀ L)_k (column s is zero).
        check_values: (s + 1, s): ẑ − z_n at the s + 1 Gauss nodes of (0, 1), from L.
        picard, poly: (s + 2, s + 1) and (s + 2, s): the Legendre coefficients of the window's
            Picard correction D(θ) = ∫_0^θ f(ẑ) dt − (ẑ(θ) − z_n) are ``h·picard @ F − poly @ L``,
            F the field at those s + 1 nodes (the quadrature is exact for ẑ's degree).
        halves: (2, s + 1, s + 1): the Legendre coefficients of a degree-s polynomial on the
            window, re-expanded on its first and second half (θ = (j + φ)/2, φ ∈ [0, 1]).
    """

    stages: int
    c: np.ndarray
    b: np.ndarray
    mu: np.ndarray
    value: np.ndarray
    series: np.ndarray
    rate: np.ndarray
    check_values: np.ndarray
    picard: np.ndarray
    poly: np.ndarray
    halves: np.ndarray

    @property
    def order(self) -> int:
        """2s, the order at the window ends."""
        return 2 * self.stages


def shifted_legendre(theta, degree: int, xp=np):
    """P̃_0..P̃_degree at θ (any shape) by the three-term recurrence; returns shape θ.shape + (degree + 1,).
    ``xp``: ``numpy`` or ``jax.numpy`` (the same recurrence inside a compiled program)."""
    x = 2.0 * theta - 1.0
    if degree == 0:
        return xp.ones_like(x)[..., None]
    cols = [xp.ones_like(x), x]
    for k in range(1, degree):
        cols.append(((2 * k + 1) * x * cols[k] - k * cols[k - 1]) / (k + 1))
    return xp.stack(cols[: degree + 1], axis=-1)


def legendre_integral(k: int) -> np.ndarray:
    """(k + 1, k): the shifted-Legendre coefficients of ∫_0^θ p from those of p (degree < k):
    ∫_0^θ P̃_j = (P̃_{j+1} − P̃_{j−1}) / (2(2j + 1)) for j ≥ 1, and (P̃_1 + P̃_0)/2 for j = 0."""
    out = np.zeros((k + 1, k))
    out[0, 0] = out[1, 0] = 0.5
    for j in range(1, k):
        out[j + 1, j] = 1.0 / (2 * (2 * j + 1))
        out[j - 1, j] = -1.0 / (2 * (2 * j + 1))
    return out


def window_value(tab: "GaussTableau", theta, xp=np):
    """(len(θ), s): the weights of L in ẑ(θ) − z_n = θh·N(θ) (computed as θ times N's series, so
    that θ = 0 gives exactly 0)."""
    return theta[..., None] * (shifted_legendre(theta, tab.stages - 1, xp) @ tab.value.T)


def _picard(s: int, value: np.ndarray):
    """The matrices of the window's local-error check (GaussTableau's docstring)."""
    m = s + 1
    x, w = np.polynomial.legendre.leggauss(m)
    xi, w = 0.5 * (x + 1.0), 0.5 * w
    basis = shifted_legendre(xi, m - 1)  # (m, m): P̃_k(ξ_j)
    from_values = (2 * np.arange(m) + 1)[:, None] * (basis * w[:, None]).T  # Legendre coefficients of F
    check_values = shifted_legendre(xi, s) @ value.T
    poly = np.zeros((s + 2, s))
    poly[: s + 1] = value.T
    return check_values, legendre_integral(m) @ from_values, poly


def _halves(s: int) -> np.ndarray:
    """The re-expansion of a degree-s Legendre series on the two halves of [0, 1] (exact: the
    s + 1-point Gauss quadrature integrates degree 2s + 1)."""
    x, w = np.polynomial.legendre.leggauss(s + 1)
    phi, w = 0.5 * (x + 1.0), 0.5 * w
    to_coeffs = (2 * np.arange(s + 1) + 1)[:, None] * (shifted_legendre(phi, s) * w[:, None]).T
    return np.stack([to_coeffs @ shifted_legendre(0.5 * (j + phi), s) for j in (0, 1)])


def _exact(s: int):
    """Nodes, weights and the Legendre coefficients of ℓ_j and of ∫_0^θ ℓ_j, at 40 digits."""
    import mpmath as mp

    mp.mp.dps = 40
    x0, _ = np.polynomial.legendre.leggauss(s)
    nodes = []
    for guess in x0:  # Newton from float64 on P_s(x) = 0
        x = mp.mpf(float(guess))
        for _ in range(8):
            x -= mp.legendre(s, x) / mp.diff(lambda y: mp.legendre(s, y), x)
        nodes.append(x)
    dp = [mp.diff(lambda y: mp.legendre(s, y), x) for x in nodes]
    c = [(1 + x) / 2 for x in nodes]
    b = [1 / ((1 - x ** 2) * d ** 2) for x, d in zip(nodes, dp)]  # the weights on [-1, 1], halved
    # ℓ_j = Σ_k D_jk P̃_k (k < s): the Gauss quadrature of ℓ_j P̃_k is exact, and ℓ_j(c_i) = δ_ij
    d = [[(2 * k + 1) * b[j] * mp.legendre(k, nodes[j]) for k in range(s)] for j in range(s)]
    # ∫_0^θ P̃_k = (P̃_{k+1} − P̃_{k−1}) / (2(2k + 1)) for k ≥ 1, and (P̃_1 + P̃_0)/2 for k = 0
    integral = [[mp.mpf(0)] * (s + 1) for _ in range(s)]
    for j in range(s):
        for k in range(s):
            if k == 0:
                integral[j][0] += d[j][0] / 2
                integral[j][1] += d[j][0] / 2
            else:
                integral[j][k + 1] += d[j][k] / (2 * (2 * k + 1))
                integral[j][k - 1] -= d[j][k] / (2 * (2 * k + 1))
    a = [[sum(integral[j][k] * mp.legendre(k, 2 * c[i] - 1) for k in range(s + 1)) for j in range(s)]
         for i in range(s)]
    # N_j(θ) = Λ_j(θ)/θ, of degree s − 1: its Legendre coefficients by s-point Gauss quadrature (exact)
    # Λ_j(c_i) is a_ij: evaluated once, not once per coefficient k (1.4 s of a 1.5 s tableau at s = 12)
    n = [[(2 * k + 1) * sum(b[i] * a[i][j] / c[i] * mp.legendre(k, nodes[i]) for i in range(s))
          for k in range(s)] for j in range(s)]
    return c, b, d, integral, a, n


def _symplectic_mu(mu_exact) -> np.ndarray:
    """μ as machine numbers with μ_ij + μ_ji = 1 exactly: the lower triangle rounded to a multiple
    of 2⁻⁵² (exactly representable below 2 in magnitude, and so is 1 − μ when μ > −1), the upper
    its complement."""
    s = len(mu_exact)
    quantum = Fraction(1, 2 ** 52)
    out = np.empty((s, s))
    for i in range(s):
        out[i, i] = 0.5
        for j in range(i):
            q = round(Fraction(str(mu_exact[i][j])) / quantum) * quantum
            if not -1 < q < 2:
                raise AssertionError(f"μ[{i},{j}] = {float(q)} is out of the exactly representable range")
            out[i, j] = float(q)
            out[j, i] = float(1 - q)
            if Fraction(out[i, j]) + Fraction(out[j, i]) != 1:
                raise AssertionError("a μ pair does not sum to 1 exactly")
    return out


@functools.lru_cache(maxsize=None)
def gauss_tableau(stages: int) -> GaussTableau:
    """The tableau of ``stages`` Gauss–Legendre nodes (1 ≤ stages ≤ MAX_STAGES), computed once."""
    if isinstance(stages, bool) or not isinstance(stages, (int, np.integer)) or not 1 <= stages <= MAX_STAGES:
        raise ConfigError(f"stages must be an integer from 1 to {MAX_STAGES}, got {stages!r}")
    s = int(stages)
    c, b, d, integral, a, n = _exact(s)
    mu_exact = [[a[i][j] / b[j] for j in range(s)] for i in range(s)]
    mu = _symplectic_mu(mu_exact)
    f = lambda rows: np.array([[float(x) for x in r] for r in rows])  # noqa: E731
    series = f([[integral[j][k] / b[j] for k in range(s + 1)] for j in range(s)])
    value = f([[n[j][k] / b[j] for k in range(s)] for j in range(s)])
    rate = np.zeros((s, s + 1))
    rate[:, :s] = f([[d[j][k] / b[j] for k in range(s)] for j in range(s)])
    return GaussTableau(s, np.array([float(x) for x in c]), np.array([float(x) for x in b]), mu, value, series,
                        rate, *_picard(s, series), _halves(s))

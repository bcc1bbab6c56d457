"""A Hamiltonian's stiff linear part, H = ½ zᵀ S z + N(z), declared so that the Gauss stage
equations can be solved with it exactly.

A Hamiltonian PDE discretised in space (Fourier pseudo-spectral or finite differences) has a
linear part whose frequencies grow with the grid: up to k_max² for the Schrödinger equation, k_max
for wave equations. The fixed-point iteration of the stage equations contracts only for windows
shorter than about 1/k_max², and a dense Newton step costs (s·n)³. A declared linear part is used
as the matrix of the simplified Newton iteration instead of the field's Jacobian: the iteration
then contracts at the rate of the nonlinear part N, whatever k_max, and each of its ⌈s/2⌉ linear
solves (I − c·JS) x = r is cheap — diagonal in Fourier space, or one small dense LU.

H stays the truth: the residual of every iteration is H's own vector field, so S only steers the
iteration. A poor S costs work (slower iterations, shorter windows), never accuracy.

Kinds: :class:`FourierLinearPart` (S = diag(K_q, K_p) with K_q, K_p circulant on one periodic grid,
given by their real, even symbols) and :class:`DenseLinearPart` (S any symmetric matrix, for
small systems).
"""

from __future__ import annotations

import abc
import hashlib
from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import SystemError_

__all__ = ["LinearPart", "FourierLinearPart", "DenseLinearPart", "fourier_wavenumbers"]


def fourier_wavenumbers(points: int, length: float) -> np.ndarray:
    """The angular wavenumbers k of a periodic grid of ``points`` over ``length``, in FFT order
    (k = 2π·m/length, m = 0, 1, …, −1): the symbol of −∂²ₓ is k², of ∂ₓ i·k."""
    if not isinstance(points, (int, np.integer)) or points < 2:
        raise SystemError_(f"a Fourier grid needs at least 2 points, got {points!r}")
    if not np.isfinite(length) or length <= 0:
        raise SystemError_(f"a Fourier grid's length must be positive, got {length!r}")
    return 2.0 * np.pi * np.fft.fftfreq(int(points), d=float(length) / int(points))


class LinearPart(abc.ABC):
    """S of H = ½ zᵀ S z + N(z), for a state z = (q, p) of ``size`` components: its field
    JS z and the solves of (I − c·JS) x = r for complex shifts c (the Gauss stages' simplified
    Newton iteration, decoupled: c = h·λ with λ an eigenvalue of the Gauss matrix)."""

    size: int

    @abc.abstractmethod
    def matrix(self) -> np.ndarray:
        """S as a dense (size × size) float64 array (for checks and small systems)."""

    @abc.abstractmethod
    def field(self, z: jax.Array) -> jax.Array:
        """JS z for a state z of shape (size,)."""

    @abc.abstractmethod
    def flow(self, z: jax.Array, t: jax.Array) -> jax.Array:
        """exp(t·JS) z, the exact flow of ½ zᵀ S z over a time t (any sign), for one state."""

    @abc.abstractmethod
    def norm(self) -> float:
        """‖JS‖, the largest |eigenvalue| of JS (the fastest frequency of the linear part)."""

    @abc.abstractmethod
    def factor(self, shifts: jax.Array) -> Callable[[jax.Array], jax.Array]:
        """For shifts c (m,) complex: a function taking r (m, size) complex to x (m, size) with
        (I − c_j·JS) x_j = r_j for each j."""

    def describe(self) -> dict:
        """A JSON-able summary."""
        return {"kind": type(self).__name__, "size": int(self.size)}


def _real_array(what: str, value, ndim: int) -> np.ndarray:
    """``value`` as a float64 array of ``ndim`` dimensions, or a one-line refusal (a complex value,
    another shape, or what is not numbers)."""
    try:
        arr = np.asarray(value)
        if np.iscomplexobj(arr):
            raise SystemError_(f"{what} must be real: S is a real symmetric matrix (an odd derivative's symbol "
                               "i·k is not a part of S)")
        arr = arr.astype(np.float64)
    except (TypeError, ValueError):
        raise SystemError_(f"{what} must be real numbers, got {value!r}") from None
    if arr.ndim != ndim:
        raise SystemError_(f"{what} must have {ndim} dimension(s), got shape {arr.shape}")
    if arr.size == 0 or not np.all(np.isfinite(arr)):
        raise SystemError_(f"{what} must hold finite numbers, got {arr.size} of them")
    return arr


def _check_symbol(name: str, symbol) -> np.ndarray:
    arr = _real_array(f"FourierLinearPart {name}", symbol, 1)
    if arr.size < 2:
        raise SystemError_(f"FourierLinearPart {name} must have at least 2 entries, got {arr.size}")
    mirror = arr[(-np.arange(arr.size)) % arr.size]
    worst = float(np.max(np.abs(arr - mirror)))
    if worst > 1e-12 * max(float(np.max(np.abs(arr))), 1e-300):
        raise SystemError_(f"FourierLinearPart {name} must be even (symbol[k] = symbol[-k], in FFT order), for S "
                           f"to be real and symmetric; it differs by {worst:.3g}")
    return arr


def _digest(*arrays: np.ndarray) -> str:
    """A short hash of the arrays that define S (a kept program's key must tell two S apart)."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, np.float64).tobytes())
    return h.hexdigest()[:16]


@dataclass(frozen=True, eq=False)
class FourierLinearPart(LinearPart):
    """S = diag(K_q, K_p) on a periodic grid of M points (the state q then p, M each): K_q and K_p
    circulant, given by their symbols in FFT order (real and even, so that S is real and
    symmetric). The nonlinear Schrödinger equation has K_q = K_p = −½∂²ₓ (symbol ½k²); a wave
    equation u_tt = u_xx − V'(u) with q = u, p = u_t has K_q = −∂²ₓ (k²) and K_p = I (ones).
    A solve is two FFTs each way and a 2 × 2 solve per wavenumber: O(M log M).

    Args:
        q_symbol: K_q's symbol, M real numbers in FFT order (``fourier_wavenumbers``), even.
        p_symbol: K_p's symbol, likewise."""

    q_symbol: np.ndarray
    p_symbol: np.ndarray

    def __post_init__(self) -> None:
        kq, kp = _check_symbol("q_symbol", self.q_symbol), _check_symbol("p_symbol", self.p_symbol)
        if kq.size != kp.size:
            raise SystemError_(f"FourierLinearPart q_symbol and p_symbol must have one length, got {kq.size} and "
                               f"{kp.size}")
        object.__setattr__(self, "q_symbol", kq)
        object.__setattr__(self, "p_symbol", kp)

    @property
    def size(self) -> int:  # type: ignore[override]
        return 2 * self.q_symbol.size

    def matrix(self) -> np.ndarray:
        m = self.q_symbol.size
        F = np.fft.fft(np.eye(m), axis=0)
        Fi = np.fft.ifft(np.eye(m), axis=0)
        blocks = [np.real(Fi @ np.diag(k) @ F) for k in (self.q_symbol, self.p_symbol)]
        zero = np.zeros((m, m))
        return np.block([[blocks[0], zero], [zero, blocks[1]]])

    def norm(self) -> float:
        return float(np.sqrt(np.max(np.abs(self.q_symbol * self.p_symbol))))

    def field(self, z: jax.Array) -> jax.Array:
        m = self.q_symbol.size
        q, p = z[:m], z[m:]
        apply = lambda k, x: jnp.real(jnp.fft.ifft(k * jnp.fft.fft(x)))  # noqa: E731
        return jnp.concatenate([apply(self.p_symbol, p), -apply(self.q_symbol, q)])

    def flow(self, z: jax.Array, t: jax.Array) -> jax.Array:
        # per wavenumber q̂' = K_p p̂, p̂' = −K_q q̂: with w² = K_q K_p, c = cos(wt) and s = sin(wt)/w
        # (cosh and sinh/w where w² < 0, t where w = 0) q̂(t) = c q̂ + K_p s p̂, p̂(t) = c p̂ − K_q s q̂
        # the symbols are even and q, p real: the half spectrum of a real FFT holds all of it
        m = self.q_symbol.size
        half = m // 2 + 1
        kq, kp = jnp.asarray(self.q_symbol[:half]), jnp.asarray(self.p_symbol[:half])
        w2 = kq * kp
        w = jnp.sqrt(jnp.abs(w2))
        wt = w * t
        c = jnp.where(w2 >= 0, jnp.cos(wt), jnp.cosh(wt))
        safe = jnp.where(w > 0, w, 1.0)
        s = jnp.where(w > 0, jnp.where(w2 >= 0, jnp.sin(wt), jnp.sinh(wt)) / safe, t)
        qh, ph = jnp.fft.rfft(z[:m]), jnp.fft.rfft(z[m:])
        return jnp.concatenate([jnp.fft.irfft(c * qh + kp * s * ph, n=m), jnp.fft.irfft(c * ph - kq * s * qh, n=m)])

    def factor(self, shifts: jax.Array) -> Callable[[jax.Array], jax.Array]:
        m = self.q_symbol.size
        c = shifts[:, None]
        kq, kp = jnp.asarray(self.q_symbol), jnp.asarray(self.p_symbol)
        det = 1.0 + c * c * (kq * kp)

        def solve(r):
            rq, rp = jnp.fft.fft(r[:, :m], axis=-1), jnp.fft.fft(r[:, m:], axis=-1)
            xq = (rq + c * kp * rp) / det
            xp = (rp - c * kq * rq) / det
            return jnp.concatenate([jnp.fft.ifft(xq, axis=-1), jnp.fft.ifft(xp, axis=-1)], axis=-1)

        return solve

    def describe(self) -> dict:
        return {**super().describe(), "points": int(self.q_symbol.size),
                "digest": _digest(self.q_symbol, self.p_symbol)}


@dataclass(frozen=True, eq=False)
class DenseLinearPart(LinearPart):
    """S any symmetric (size × size) matrix: each solve one LU of the complex matrix I − c·JS (for
    small systems, or a stiff linear coupling of a few components).

    Args:
        S: the symmetric matrix, rows and columns ordered as the state (q, then p)."""

    S: np.ndarray

    def __post_init__(self) -> None:
        S = _real_array("DenseLinearPart S", self.S, 2)
        if S.shape[0] != S.shape[1] or S.shape[0] % 2:
            raise SystemError_(f"DenseLinearPart S must be square with an even side (q then p), got shape {S.shape}")
        worst = float(np.max(np.abs(S - S.T)))
        if worst > 1e-12 * max(float(np.max(np.abs(S))), 1e-300):
            raise SystemError_(f"DenseLinearPart S must be symmetric; S - S.T reaches {worst:.3g}")
        object.__setattr__(self, "S", S)

    @property
    def size(self) -> int:  # type: ignore[override]
        return self.S.shape[0]

    def _js(self) -> np.ndarray:
        d = self.size // 2
        return np.concatenate([self.S[d:], -self.S[:d]])

    def matrix(self) -> np.ndarray:
        return self.S.copy()

    def describe(self) -> dict:
        return {**super().describe(), "digest": _digest(self.S)}

    def norm(self) -> float:
        return float(np.linalg.norm(self._js(), 2))

    def field(self, z: jax.Array) -> jax.Array:
        return jnp.asarray(self._js()) @ z

    def flow(self, z: jax.Array, t: jax.Array) -> jax.Array:
        return jax.scipy.linalg.expm(t * jnp.asarray(self._js(), z.dtype)) @ z

    def factor(self, shifts: jax.Array) -> Callable[[jax.Array], jax.Array]:
        js = jnp.asarray(self._js(), shifts.dtype)
        eye = jnp.eye(self.size, dtype=shifts.dtype)
        factors = jax.vmap(lambda c: jax.scipy.linalg.lu_factor(eye - c * js))(shifts)
        return lambda r: jax.vmap(lambda lu, piv, rj: jax.scipy.linalg.lu_solve((lu, piv), rj))(*factors, r)

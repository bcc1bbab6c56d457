"""Hamiltonian PDEs on a periodic grid, as built-in systems with their stiff linear part declared
(:mod:`._linear`), their exact solutions, and the FPUT chain with its normal modes.

Each grid point carries one canonical pair (q_j, p_j); the Hamiltonian is the PDE's own, summed
over the grid with the spatial derivatives taken spectrally (Fourier), so its quadratic invariants
(NLS's mass Σ q² + p²) are exact invariants of the Gauss method too. (The momentum is not an
invariant of the grid's equations: their nonlinear term is invariant under shifts by whole grid
steps only.)

* ``nls``: the focusing cubic nonlinear Schrödinger equation i ψ_t + ½ ψ_xx + |ψ|² ψ = 0 with
  ψ = q + i p: H = ½ Σ (q·Kq + p·Kp) − ¼ Σ (q² + p²)², K = −½∂²ₓ (symbol ½k²). Its moving
  soliton ψ = a sech(a(x − x₀ − vt)) exp(i(vx + (a² − v²)t/2)) (:func:`nls_soliton`).
* ``sine_gordon``: u_tt = u_xx − sin u with q = u, p = u_t: H = Σ ½p² + ½ u·(−∂²ₓ u) + 1 − cos u,
  K_q = 1 − ∂²ₓ (1 + k², with the quadratic part of 1 − cos u), K_p = I. Its breather
  (:func:`sine_gordon_breather`) on a domain wide enough for its tails.
* ``fput``: the Fermi–Pasta–Ulam–Tsingou chain of N particles between fixed ends, H = Σ ½p² +
  Σ_{j=0}^{N} ½Δ² + α/3 Δ³ + β/4 Δ⁴ with Δ = q_{j+1} − q_j (q_0 = q_{N+1} = 0); its normal modes
  Q_k = √(2/(N+1)) Σ_j q_j sin(jkπ/(N+1)) of frequency ω_k = 2 sin(kπ/(2(N+1))) and their
  energies ½(P_k² + ω_k² Q_k²) (:func:`fput_modes`), which sum to H when α = β = 0.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from atlasnn.errors import SystemError_
from atlasnn.systems._builtins import BuiltinSystem, register_system
from atlasnn.systems._hamiltonian import HamiltonianSystem
from atlasnn.systems._linear import FourierLinearPart, fourier_wavenumbers

__all__ = ["nls", "nls_soliton", "nls_mass", "sine_gordon", "sine_gordon_breather", "periodic_grid", "fput",
           "fput_modes"]


def periodic_grid(points: int, length: float) -> np.ndarray:
    """The points of a periodic grid over [−length/2, length/2): x_j = −length/2 + j·length/points."""
    points, length = _points(points), _length(length)
    return -0.5 * length + np.arange(points) * (length / points)


def _points(points) -> int:
    try:
        ok = not isinstance(points, (bool, str)) and float(points) == int(points) and int(points) >= 4
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise SystemError_(f"points must be an integer of at least 4, got {points!r}")
    return int(points)


def _length(length) -> float:
    try:
        value = float(length)
    except (TypeError, ValueError):
        value = float("nan")
    if isinstance(length, (bool, str)) or not (np.isfinite(value) and value > 0):
        raise SystemError_(f"length must be a positive number, got {length!r}")
    return value


def _grid(points, length) -> tuple[int, float]:
    """(points, length) checked, with the grid's largest wavenumber squared a finite float."""
    points, length = _points(points), _length(length)
    if np.pi * points / length >= np.sqrt(np.finfo(np.float64).max):
        raise SystemError_(f"length = {length!r} is too short for {points} grid points: the largest "
                           "wavenumber squared overflows float64; lengthen the domain")
    return points, length


def _half_spectrum(symbol: np.ndarray) -> np.ndarray:
    """An even symbol on the real FFT's bins, each weighted by how many bins of the full spectrum it
    stands for (2, but 1 for k = 0 and, M even, k = M/2), divided by 2M: the factor of ½ x·Kx."""
    m = symbol.size
    half = symbol[: m // 2 + 1].copy()
    half[1: (m + 1) // 2] *= 2.0
    return half / (2.0 * m)


def _spectral_quadratic(x, weights):
    """½ x·(K x) for K circulant and even, by Parseval on the real FFT (``weights`` from
    :func:`_half_spectrum`): half the work of the complex FFT."""
    xh = jnp.fft.rfft(x)
    return jnp.sum(weights * (jnp.real(xh) ** 2 + jnp.imag(xh) ** 2))


def _periodic_speed(speed: float, length: float) -> float:
    """The speed rounded to a multiple of 2π/length, so that the soliton's phase exp(ivx) is periodic."""
    unit = 2.0 * np.pi / float(length)
    return float(np.round(float(speed) / unit) * unit)


def nls_soliton(t, points: int = 512, length: float = 64.0, amplitude: float = 1.0, speed: float = 1.0,
                center: float = 0.0) -> np.ndarray:
    """The moving soliton of ``nls`` at times ``t`` (a number or an array): states (…, 2·points),
    q = Re ψ then p = Im ψ on the grid, summed over the periodic images that reach it (its tails,
    a·2e^{−a·length/2} at the domain's edge, are below 1e-12 for a·length ≥ 60)."""
    points, length = _points(points), _length(length)
    v, a = _periodic_speed(speed, length), float(amplitude)
    x = periodic_grid(points, length)
    t = np.asarray(t, np.float64)[..., None]
    offset = ((x - center - v * t + 0.5 * length) % length) - 0.5 * length  # the nearest image
    images = sum(1.0 / np.cosh(a * (offset + k * length)) for k in (-1, 0, 1))
    psi = a * images * np.exp(1j * (v * x + 0.5 * (a * a - v * v) * t))
    return np.concatenate([psi.real, psi.imag], axis=-1)


def nls_mass(z) -> np.ndarray:
    """The discrete mass Σ_j q_j² + p_j² of NLS states (…, 2M): a quadratic invariant, kept exactly
    by the Gauss method (to round-off)."""
    z = np.asarray(z, np.float64)
    return np.sum(z * z, axis=-1)


def nls(points: int = 512, length: float = 64.0, amplitude: float = 1.0, speed: float = 1.0) -> HamiltonianSystem:
    """The focusing cubic NLS i ψ_t + ½ψ_xx + |ψ|²ψ = 0 on a periodic Fourier grid, ψ = q + ip, its
    linear part (½k² on q and on p) declared.

    Args:
        points: grid points M (the state has 2M components: Re ψ, then Im ψ).
        length: the periodic domain's length.
        amplitude: a of the default z0, the soliton a·sech(a x)·e^{ivx} at t = 0.
        speed: v of that soliton, rounded to a multiple of 2π/length (its phase must be periodic).

    Returns the system, its H summed over the grid (the PDE's energy divided by 2Δx)."""
    points, length = _grid(points, length)
    v = _periodic_speed(speed, length)
    symbol = 0.5 * fourier_wavenumbers(points, length) ** 2
    weights = _half_spectrum(symbol)

    def h(q, p):
        return _spectral_quadratic(q, weights) + _spectral_quadratic(p, weights) - 0.25 * jnp.sum((q * q + p * p) ** 2)

    return HamiltonianSystem(
        h, points, name="nls", q_names=tuple(f"re{j}" for j in range(points)),
        p_names=tuple(f"im{j}" for j in range(points)), z0=nls_soliton(0.0, points, length, amplitude, v),
        spec={"kind": "builtin", "name": "nls",
              "params": {"points": points, "length": length, "amplitude": float(amplitude), "speed": v}},
        linear_part=FourierLinearPart(symbol, symbol), nonlinear_flow=_nls_rotation,
    )


def _nls_rotation(z, t):
    """The exact flow of the NLS's N = −¼ Σ (q² + p²)²: each point's ψ = q + ip turned by |ψ|²·t
    (|ψ| is constant along it)."""
    m = z.shape[-1] // 2
    q, p = z[:m], z[m:]
    angle = (q * q + p * p) * t
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.concatenate([c * q - s * p, s * q + c * p])


def sine_gordon_breather(t, points: int = 256, length: float = 80.0, omega: float = 0.5) -> np.ndarray:
    """The sine-Gordon breather u = 4 arctan(√(1−ω²) cos(ωt) / (ω cosh(√(1−ω²) x))) and u_t, states
    (…, 2·points) on the grid (its tails, e^{−√(1−ω²)·length/2}, are below 1e-12 for the defaults)."""
    points, length = _points(points), _length(length)
    if not 0.0 < omega < 1.0:
        raise SystemError_(f"the breather's omega must be in (0, 1), got {omega!r}")
    x = periodic_grid(points, length)
    t = np.asarray(t, np.float64)[..., None]
    k = np.sqrt(1.0 - omega * omega)
    g = k * np.cos(omega * t) / (omega * np.cosh(k * x))
    dg = -k * np.sin(omega * t) / np.cosh(k * x)  # ∂g/∂t
    return np.concatenate([np.broadcast_to(4.0 * np.arctan(g), dg.shape), 4.0 * dg / (1.0 + g * g)], axis=-1)


def sine_gordon(points: int = 256, length: float = 80.0, omega: float = 0.5) -> HamiltonianSystem:
    """The sine-Gordon equation u_tt = u_xx − sin u on a periodic Fourier grid, q = u and p = u_t,
    its linear part (1 + k² on q, 1 on p) declared.

    Args:
        points: grid points M (the state has 2M components: u, then u_t).
        length: the periodic domain's length.
        omega: the frequency of the default z0, the breather at t = 0 (0 < omega < 1)."""
    points, length = _grid(points, length)
    symbol = fourier_wavenumbers(points, length) ** 2
    weights = _half_spectrum(symbol)

    def h(q, p):
        return 0.5 * jnp.sum(p * p) + _spectral_quadratic(q, weights) + jnp.sum(1.0 - jnp.cos(q))

    return HamiltonianSystem(
        h, points, name="sine_gordon", q_names=tuple(f"u{j}" for j in range(points)),
        p_names=tuple(f"v{j}" for j in range(points)), z0=sine_gordon_breather(0.0, points, length, omega),
        separable=True,
        spec={"kind": "builtin", "name": "sine_gordon",
              "params": {"points": points, "length": length, "omega": float(omega)}},
        linear_part=FourierLinearPart(1.0 + symbol, np.ones(points)), nonlinear_flow=_sine_gordon_kick,
    )


def _sine_gordon_kick(z, t):
    """The exact flow of sine-Gordon's N = Σ (1 − cos u − u²/2), which depends on u only: a kick
    v ← v − t·(sin u − u)."""
    m = z.shape[-1] // 2
    u = z[:m]
    return jnp.concatenate([u, z[m:] - t * (jnp.sin(u) - u)])


def _fput_h(q, p, alpha, beta):
    zero = jnp.zeros(1, q.dtype)
    dq = jnp.diff(jnp.concatenate([zero, q, zero]))
    return 0.5 * jnp.sum(p * p) + jnp.sum(0.5 * dq ** 2 + alpha / 3.0 * dq ** 3 + beta / 4.0 * dq ** 4)


def _fput_basis(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The chain's normal modes: the orthogonal sine matrix (k, j) and the frequencies ω_k."""
    j = np.arange(1, n + 1)
    basis = np.sqrt(2.0 / (n + 1)) * np.sin(np.outer(j, j) * np.pi / (n + 1))
    return basis, 2.0 * np.sin(j * np.pi / (2.0 * (n + 1)))


def fput_modes(z, particles: int) -> np.ndarray:
    """The energies ½(P_k² + ω_k² Q_k²) of the chain's N normal modes for states (…, 2N)."""
    z = np.asarray(z, np.float64)
    basis, omega = _fput_basis(int(particles))
    Q, P = z[..., :particles] @ basis.T, z[..., particles:] @ basis.T
    return 0.5 * (P * P + (omega * Q) ** 2)


def _finite(name: str, value) -> float:
    """``value`` as a finite float, or a one-line refusal naming ``name``."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = float("nan")
    if isinstance(value, (bool, str)) or not np.isfinite(out):
        raise SystemError_(f"{name} must be a finite number, got {value!r}")
    return out


def fput(particles: int = 32, alpha: float = 0.25, beta: float = 0.0, amplitude: float = 1.0) -> HamiltonianSystem:
    """The Fermi–Pasta–Ulam–Tsingou chain: unit masses and springs between fixed ends.

    Args:
        particles: N, the moving particles (the state has 2N components).
        alpha: the cubic coefficient of each spring's energy (α/3 Δ³).
        beta: the quartic coefficient (β/4 Δ⁴).
        amplitude: of the default z0, Fermi's: all the energy in the first normal mode,
            q_j = amplitude·sin(jπ/(N+1)), p = 0."""
    try:
        n = int(particles)
        ok = not isinstance(particles, (bool, str)) and float(particles) == n and n >= 2
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise SystemError_(f"particles must be an integer of at least 2, got {particles!r}")
    alpha, beta, amplitude = (_finite(name, v) for name, v in (("alpha", alpha), ("beta", beta),
                                                               ("amplitude", amplitude)))
    z0 = np.concatenate([float(amplitude) * np.sin(np.pi * np.arange(1, n + 1) / (n + 1)), np.zeros(n)])
    return HamiltonianSystem(
        lambda q, p: _fput_h(q, p, alpha, beta), n, name="fput", z0=z0, separable=True,
        params={"alpha": alpha, "beta": beta},
        spec={"kind": "builtin", "name": "fput",
              "params": {"particles": n, "alpha": alpha, "beta": beta, "amplitude": float(amplitude)}},
        parametric=lambda q, p, th: _fput_h(q, p, th[0], th[1]),
    )


def _circulant_numpy(symbol: np.ndarray):
    return lambda x: np.real(np.fft.ifft(symbol * np.fft.fft(x)))


def _nls_numpy(points: int = 512, length: float = 64.0, **_):
    apply = _circulant_numpy(0.5 * fourier_wavenumbers(_points(points), length) ** 2)
    m = _points(points)

    def field(t, z):
        q, p = z[:m], z[m:]
        r2 = q * q + p * p
        return np.concatenate([apply(p) - r2 * p, r2 * q - apply(q)])

    return field


def _sine_gordon_numpy(points: int = 256, length: float = 80.0, **_):
    apply = _circulant_numpy(fourier_wavenumbers(_points(points), length) ** 2)
    m = _points(points)
    return lambda t, z: np.concatenate([z[m:], -apply(z[:m]) - np.sin(z[:m])])


def _fput_numpy(particles: int = 32, alpha: float = 0.25, beta: float = 0.0, **_):
    n = int(particles)

    def field(t, z):
        dq = np.diff(np.concatenate([[0.0], z[:n], [0.0]]))
        force = dq + alpha * dq ** 2 + beta * dq ** 3
        return np.concatenate([z[n:], force[1:] - force[:-1]])

    return field


register_system(BuiltinSystem(
    "fput", fput, "d=particles (32)",
    "H = Σ p²/2 + Σ Δ²/2 + alpha·Δ³/3 + beta·Δ⁴/4, Δ = q_{j+1} − q_j, fixed ends",
    "Fermi's: q_j = sin(jπ/(N+1)), p = 0", _fput_numpy))
register_system(BuiltinSystem(
    "nls", nls, "d=points (512)",
    "H = ½Σ(q·Kq + p·Kp) − ¼Σ(q²+p²)², K = −½∂²ₓ spectral (focusing cubic NLS, ψ = q + ip)",
    "the soliton a = 1, v ≈ 1", _nls_numpy))
register_system(BuiltinSystem(
    "sine_gordon", sine_gordon, "d=points (256)",
    "H = Σ ½p² + ½q·(−∂²ₓ q) + 1 − cos q, spectral (sine-Gordon, q = u, p = u_t)", "the breather ω = 0.5",
    _sine_gordon_numpy))

"""Residual-based error bounds of the Gronwall kind, for comparison with the linearised estimate.

Along ẑ, any solution δ of δ' = A(t) δ − r(t) satisfies d‖δ‖/dt ≤ κ(t) ‖δ‖ + ‖r(t)‖ with
κ = μ(A), the logarithmic norm (the largest eigenvalue of (A + Aᵀ)/2; of S A S⁻¹ in a weighted
norm ‖Sx‖), hence

    ‖δ(t)‖ ≤ β(t),   β' = κ(t) β + ‖r(t)‖,   β(t0) = ‖z0 − ẑ(t0)‖,   β += ‖j_k‖ at window edges.

With one constant κ = L ≥ max_t ‖A(t)‖ this is the classical ∫ e^{L(t−s)} ‖r(s)‖ ds of the PINN
certification literature (Hillebrecht & Unger, "Certified machine learning", 2022); the
time-varying log-norm form is the one-sided-Lipschitz kind (arXiv 2606.12050). Evaluated along ẑ
they are rigorous for the linearised problem only (a nonlinear f needs κ on the segment between ẑ
and z, not checked) and only up to the quadrature of the sampled residual. On a Hamiltonian flow
μ(A) ≥ 0 (A is trace-free), so β can only grow, exponentially, even on a stable orbit: measured
(docs/ESTIMATE.md) it stays within 10× of the true error only for t ≲ 0.2–1.6 and exceeds it by
10⁵–10¹⁶⁸ over the paper's intervals. Use it to certify one short window, not a long run.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from atlasnn.solutions._estimate import _sample
from atlasnn.solutions._linearised import propagate, residual_and_jacobian

__all__ = ["log_norm", "residual_bound"]


def log_norm(A: Any, metric: Any = None) -> np.ndarray:
    """μ_S(A) = λ_max of the symmetric part of S A S⁻¹ for a batch A of shape (N, m, m) (S = I)."""
    A = np.asarray(A, dtype=np.float64)
    if metric is not None:
        S = np.asarray(metric, dtype=np.float64)
        A = S @ A @ np.linalg.inv(S)
    return np.linalg.eigvalsh(0.5 * (A + np.swapaxes(A, -1, -2)))[..., -1]


def residual_bound(system: Any, pieces: list, steps: list[int], *, kind: str = "lognorm",
                   z0: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """(node times, β) for a solution given as pieces (``AbstractSolution.pieces()``) on a grid of
    ``steps`` RK4 steps per piece; ``kind``: "lognorm" (κ = μ(A(t))) or "lipschitz" (κ = max ‖A‖)."""
    t, z, dz = _sample(pieces, steps)
    r, A = residual_and_jacobian(system, z, dz)
    if kind == "lognorm":
        kappa = log_norm(A)
    elif kind == "lipschitz":
        kappa = np.full(t.size, float(np.linalg.norm(A, ord=2, axis=(1, 2)).max()))
    else:
        raise ValueError(f"kind must be 'lognorm' or 'lipschitz', got {kind!r}")
    cut = np.nonzero(np.diff(t) == 0)[0]
    jumps = np.linalg.norm(z[cut + 1] - z[cut], axis=1)
    b0 = 0.0 if z0 is None else float(np.linalg.norm(np.asarray(z0, np.float64).reshape(-1) - z[0]))
    tn, beta, _ = propagate(t, kappa[:, None, None], -np.linalg.norm(r, axis=1)[:, None],
                            jumps=-jumps[:, None], y0=np.array([b0]))
    return tn, beta[:, 0]

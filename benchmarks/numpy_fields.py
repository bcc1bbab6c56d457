"""Right-hand sides written out in NumPy for the benchmark problems that are not built-in systems
(a built-in's is atlasnn.systems.numpy_field): SciPy's DOP853 at its best
calls a NumPy function, not a compiled JAX one (3–4× slower per call)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["numpy_rhs"]


def numpy_rhs(name, system):
    """(rhs(t, z), kind): the problem's field as NumPy code where one is written here (kind
    "numpy", checked against the system's at a random state), else the system's compiled JAX field
    called per step (kind "jax-jit", slower per call)."""
    rhs, kind = _written(name, system)
    if kind == "numpy":
        _check(name, system, rhs)
    return rhs, kind


def _written(name, system):
    from atlasnn.systems import builtin_system, numpy_field

    built_in = numpy_field(system)  # the built-in systems' own (Hénon–Heiles, the oscillators)
    if built_in is not None:
        return built_in, "numpy"
    if name.startswith("henon-heiles"):  # Hénon–Heiles written as an expression: the built-in's field
        return numpy_field(builtin_system("henon_heiles", lam=float(system.params.get("lam", 1.0)))), "numpy"
    if name.startswith("kepler") and system.dim == 2:
        def rhs(t, z):
            q1, q2, p1, p2 = z
            r3 = (q1 * q1 + q2 * q2) ** 1.5
            return np.array([p1, p2, -q1 / r3, -q2 / r3])
        return rhs, "numpy"
    if name == "pendulum-separatrix":
        return (lambda t, z: np.array([z[1], -np.sin(z[0])])), "numpy"
    if name == "toda-3":
        def rhs(t, z):
            q1, q2, q3, p1, p2, p3 = z
            e12, e23, e31 = math.exp(q1 - q2), math.exp(q2 - q3), math.exp(q3 - q1)
            return np.array([p1, p2, p3, e31 - e12, e12 - e23, e23 - e31])
        return rhs, "numpy"
    if name == "figure-eight":
        def rhs(t, z):
            q, p = z[:6].reshape(3, 2), z[6:]
            d = q[:, None, :] - q[None, :, :]
            r3 = np.sum(d * d, axis=-1) ** 1.5
            np.fill_diagonal(r3, np.inf)
            return np.concatenate([p, -(d / r3[..., None]).sum(axis=1).ravel()])
        return rhs, "numpy"
    from atlasnn.evaluation import reference_rhs
    return reference_rhs(system), "jax-jit"



def _check(name, system, rhs):
    """Refuse a written field that is not the system's to round-off."""
    from atlasnn.evaluation import reference_rhs

    z = np.asarray(system.z0, np.float64) + 0.01 * np.random.default_rng(0).standard_normal(system.state_dim)
    gap = float(np.abs(rhs(0.0, z) - np.asarray(reference_rhs(system)(0.0, z))).max())
    if gap > 1e-12 * max(1.0, float(np.abs(rhs(0.0, z)).max())):
        raise SystemExit(f"{name}: the NumPy right-hand side differs from the system's by {gap:.3g}")

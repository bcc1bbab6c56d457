"""The system of a config checked before anything trains: it builds, H and J∇H are finite at z0
(in float64, and small enough for float32 training: the loss squares them), and ``separable =
true`` holds for an expression."""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.experiments.config._types import _fail, _fmt, _one_line
from atlasnn.precision import x64_enabled


def check_system_builds(system: Any) -> None:
    """Build the system of a SystemConfig now, so that a bad expression or z0 fails before any
    training."""
    try:
        sysm = system.build()
        z0 = sysm.initial_state()
    except ConfigError:
        raise
    except Exception as exc:  # AtlasError subclasses carry one-line messages
        if isinstance(exc, AtlasError):
            raise ConfigError(_one_line(f"system: {exc}")) from None
        raise
    _check_finite_at_z0(sysm, z0, system)


FLOAT32_SQUARE_LIMIT = 1e18  # |H|, |J∇H| at z0 in float32 training: their squares must not overflow


def _check_finite_at_z0(sysm, z0, system: Any) -> None:
    """H and J∇H must be finite at z0 (in float64): a singular or overflowing start would give
    non-finite losses from the first epoch and a reference solver that cannot start."""
    with jax.enable_x64(True):
        z = jnp.asarray(z0, jnp.float64)
        energy = float(sysm.energy(z))
        field = np.asarray(sysm.vector_field(z), dtype=np.float64)
    where = "system.z0" if system.z0 is not None else ("system.hamiltonian" if system.hamiltonian else "system.params")
    value = list(system.z0) if system.z0 is not None else (system.hamiltonian or dict(system.params))
    at = "there" if where == "system.z0" else f"at z0 = {[float(x) for x in z0]}"
    if system.params and where != "system.params":
        at += f" with params {_fmt(dict(system.params))}"
    if not (math.isfinite(energy) and np.all(np.isfinite(field))):
        _fail(where, value, f"the Hamiltonian or its gradient is not finite {at} "
              f"(H = {energy:g}, J∇H = {[float(x) for x in field]})")
    if not x64_enabled():  # training runs in float32, and its loss squares H − E0 and J∇H
        energy32 = float(sysm.energy(jnp.asarray(z0, jnp.float32)))
        field32 = np.asarray(sysm.vector_field(jnp.asarray(z0, jnp.float32)), dtype=np.float64)
        size = max(abs(energy32), float(np.abs(field32).max()))
        if not size <= FLOAT32_SQUARE_LIMIT:
            _fail(where, value, f"H or J∇H is too large for float32 training {at} (in float64: H = {energy:.3g}, "
                  f"max |J∇H| = {float(np.abs(field).max()):.3g}; the loss squares them and float32 ends at "
                  f"3.4e38, so they must stay below {FLOAT32_SQUARE_LIMIT:g}); rescale the problem or set "
                  "ATLASNN_X64=1")
    if system.hamiltonian is not None and system.separable:
        _check_separable(sysm, np.asarray(z0, np.float64))


def _check_separable(sysm, z0) -> None:
    """``separable = true`` lets the symplectic integrators run (they need H = T(p) + V(q)): the
    mixed second derivatives ∂²H/∂q∂p must vanish (checked at z0 and three nearby states)."""
    d = sysm.dim
    shifts = [np.zeros_like(z0), np.full_like(z0, 0.1), np.resize([0.3, -0.2], z0.shape), np.full_like(z0, -0.25)]
    with jax.enable_x64(True):
        hess = jax.hessian(lambda z: sysm.energy(z))
        for shift in shifts:
            h = np.asarray(hess(jnp.asarray(z0 + shift, jnp.float64)), dtype=np.float64)
            cross = np.abs(h[:d, d:])
            if not np.all(np.isfinite(h)):
                continue
            if cross.max() > 1e-9 * (1.0 + np.abs(h).max()):
                at = [round(float(x), 6) for x in z0 + shift]
                _fail("system.separable", True, f"the Hamiltonian is not separable (d²H/dq dp = "
                      f"{float(h[:d, d:].flat[int(np.argmax(cross))]):g} at {at}); set separable = false")

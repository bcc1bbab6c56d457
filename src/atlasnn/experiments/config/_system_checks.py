"""The system of a config checked before anything trains: it builds, H and J∇H are finite at z0
(in float64, and small enough for float32 training: the loss squares them), and ``separable =
true`` holds for an expression or a Python file; and a Python file's path resolved against the
config file's folder."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import jax
import numpy as np

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.experiments.config._types import _fail, _fmt, _one_line
from atlasnn.precision import on_device, x64_enabled


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
    at_z0 = jax.jit(lambda z: (sysm.energy(z), sysm.vector_field(z)))  # one program, not op by op
    with jax.enable_x64(True):
        energy, field = at_z0(on_device(z0, np.float64))
        energy, field = float(energy), np.asarray(field, dtype=np.float64)
    own = "system.python" if system.python else "system.hamiltonian"
    where = "system.z0" if system.z0 is not None else (own if not system.is_builtin else "system.params")
    value = list(system.z0) if system.z0 is not None else (system.hamiltonian or system.python or dict(system.params))
    at = "there" if where == "system.z0" else f"at z0 = {[float(x) for x in z0]}"
    if system.params and where != "system.params":
        at += f" with params {_fmt(dict(system.params))}"
    if not (math.isfinite(energy) and np.all(np.isfinite(field))):
        _fail(where, value, f"the Hamiltonian or its gradient is not finite {at} "
              f"(H = {energy:g}, J∇H = {[float(x) for x in field]})")
    if not x64_enabled():  # training runs in float32, and its loss squares H − E0 and J∇H
        energy32, field32 = at_z0(on_device(z0, np.float32))
        energy32, field32 = float(energy32), np.asarray(field32, dtype=np.float64)
        size = max(abs(energy32), float(np.abs(field32).max()))
        if not size <= FLOAT32_SQUARE_LIMIT:
            _fail(where, value, f"H or J∇H is too large for float32 training {at} (in float64: H = {energy:.3g}, "
                  f"max |J∇H| = {float(np.abs(field).max()):.3g}; the loss squares them and float32 ends at "
                  f"3.4e38, so they must stay below {FLOAT32_SQUARE_LIMIT:g}); rescale the problem or set "
                  "ATLASNN_X64=1")
    if not system.is_builtin and system.separable:
        _check_separable(sysm, np.asarray(z0, np.float64))


def _check_separable(sysm, z0) -> None:
    """``separable = true`` lets the symplectic integrators run (they need H = T(p) + V(q)): the
    mixed second derivatives ∂²H/∂q∂p must vanish (checked at z0 and three nearby states)."""
    d = sysm.dim
    shifts = [np.zeros_like(z0), np.full_like(z0, 0.1), np.resize([0.3, -0.2], z0.shape), np.full_like(z0, -0.25)]
    with jax.enable_x64(True):
        hessians = jax.jit(jax.vmap(jax.hessian(lambda z: sysm.energy(z))))
        stack = np.asarray(hessians(on_device(z0 + np.stack(shifts), np.float64)), dtype=np.float64)
        for shift, h in zip(shifts, stack):
            cross = np.abs(h[:d, d:])
            if not np.all(np.isfinite(h)):
                continue
            if cross.max() > 1e-9 * (1.0 + np.abs(h).max()):
                at = [round(float(x), 6) for x in z0 + shift]
                _fail("system.separable", True, f"the Hamiltonian is not separable (d²H/dq dp = "
                      f"{float(h[:d, d:].flat[int(np.argmax(cross))]):g} at {at}); set separable = false")


def _config_folder(source: str) -> Path | None:
    """The folder of the config file ``source`` names (None for a config not read from a file)."""
    path = Path(source)
    return path.parent if path.suffix == ".toml" and path.is_file() else None


def _python_target(value: str, base: Path | None) -> str:
    """"FILE.py:FUNCTION" (FUNCTION defaults to hamiltonian) with FILE made absolute (relative
    to ``base``, the config file's folder)."""
    path, sep, function = value.rpartition(":")
    if not sep or not path or "/" in function or "\\" in function:  # no function named ("C:\\x.py" too)
        path, function = value, "hamiltonian"
    if not function.isidentifier():
        _fail("system.python", value, f"{function!r} is not a Python function name (write FILE.py:FUNCTION)")
    file = Path(path).expanduser()
    if not file.is_absolute() and base is not None:
        file = base / file
    if file.suffix != ".py":
        _fail("system.python", value, "expected FILE.py:FUNCTION (a Python file)")
    if not file.is_file():
        _fail("system.python", value, f"file {str(file)!r} not found")
    return f"{file.resolve()}:{function}"

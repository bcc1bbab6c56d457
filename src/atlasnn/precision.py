"""Floating-point precision switches.

atlasnn trains in float32 by default (as the authors' PyTorch release does). Setting the
environment variable ``ATLASNN_X64=1`` before import, or calling :func:`enable_x64`, switches
JAX to float64 for everything created afterwards. The reference solver always evaluates the
vector field in float64, whatever this switch says.

Matrix products: on a GPU, JAX's default runs float32 products as TF32 (a 10-bit mantissa), which
a physics loss driven to 1e-6 notices. atlasnn asks for full float32 products
(``jax_default_matmul_precision = "highest"``) unless ``ATLASNN_MATMUL_PRECISION`` names another of
JAX's settings (``default`` keeps JAX's own) or JAX's own ``JAX_DEFAULT_MATMUL_PRECISION`` is set.
A CPU computes float32 products in full either way, so its results do not change.
"""

import os

import jax

if os.environ.get("ATLASNN_X64", "").strip() not in ("", "0", "false", "False"):
    jax.config.update("jax_enable_x64", True)

MATMUL_ENV = "ATLASNN_MATMUL_PRECISION"
#: the values ATLASNN_MATMUL_PRECISION takes ("default": leave JAX's own default alone)
MATMUL_CHOICES = ("highest", "high", "default", "float32", "tensorfloat32", "bfloat16")


def _matmul_setting() -> str | None:
    """The matrix-product precision to set at import (None: leave JAX's as it is)."""
    if os.environ.get("JAX_DEFAULT_MATMUL_PRECISION"):
        return None  # the user set JAX's own flag
    value = os.environ.get(MATMUL_ENV, "").strip().lower() or "highest"
    if value not in MATMUL_CHOICES:
        raise SystemExit(f"atlasnn: {MATMUL_ENV}={value!r} is not one of {', '.join(MATMUL_CHOICES)}")
    return None if value == "default" else value


def apply_matmul_precision() -> str | None:
    """Set JAX's default matrix-product precision from the environment (once, at import); returns
    what was set (None: JAX's own default or the user's JAX flag)."""
    value = _matmul_setting()
    if value is not None:
        jax.config.update("jax_default_matmul_precision", value)
    return value


def matmul_precision() -> str:
    """The matrix-product precision in force now ("default" when JAX's own applies)."""
    return jax.config.jax_default_matmul_precision or "default"


def trace_settings() -> tuple[bool, str | None]:
    """The global settings a traced program depends on (float64 mode, matrix-product precision):
    part of the key of every cache of compiled programs atlasnn keeps itself, so that a program
    traced under other settings is never reused."""
    return bool(jax.config.read("jax_enable_x64")), jax.config.jax_default_matmul_precision


def enable_x64(on: bool = True) -> None:
    """Turn JAX's 64-bit mode on (or off) globally."""
    jax.config.update("jax_enable_x64", bool(on))


def x64_enabled() -> bool:
    """True when JAX creates float64 arrays by default."""
    return bool(jax.config.read("jax_enable_x64"))


def on_device(value, dtype) -> jax.Array:
    """``jnp.asarray(value, dtype)`` for a value on the host (a number, a NumPy array), made by a plain
    copy to the device: done eagerly, ``jnp.asarray`` and friends run a small program, compiled (or
    loaded from the cache) once per new shape and dtype — a few hundredths of a second each, dozens
    of them in a run. The value is rounded to ``dtype`` as ``jnp.asarray`` rounds it; float64 needs
    JAX's float64 mode in force, as it does for ``jnp.asarray``."""
    import numpy as np

    return jax.device_put(np.asarray(value, dtype=dtype))


def default_float():
    """The float dtype JAX uses now (float32 or float64)."""
    import jax.numpy as jnp

    return jnp.float64 if x64_enabled() else jnp.float32

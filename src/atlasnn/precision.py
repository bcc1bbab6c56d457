"""Floating-point precision switch.

atlasnn trains in float32 by default (as the authors' PyTorch release does). Setting the
environment variable ``ATLASNN_X64=1`` before import, or calling :func:`enable_x64`, switches
JAX to float64 for everything created afterwards. The reference solver always evaluates the
vector field in float64, whatever this switch says.
"""

import os

import jax

if os.environ.get("ATLASNN_X64", "").strip() not in ("", "0", "false", "False"):
    jax.config.update("jax_enable_x64", True)


def enable_x64(on: bool = True) -> None:
    """Turn JAX's 64-bit mode on (or off) globally."""
    jax.config.update("jax_enable_x64", bool(on))


def x64_enabled() -> bool:
    """True when JAX creates float64 arrays by default."""
    return bool(jax.config.read("jax_enable_x64"))


def default_float():
    """The float dtype JAX uses now (float32 or float64)."""
    import jax.numpy as jnp

    return jnp.float64 if x64_enabled() else jnp.float32

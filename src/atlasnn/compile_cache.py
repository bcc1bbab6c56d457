"""JAX's persistent compilation cache, on by default: a second run of the same config (same
shapes, system and settings) loads its compiled programs from disk instead of compiling again.

The cache lives in ``$ATLASNN_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/atlasnn/jax`` (default
``~/.cache/atlasnn/jax``). ``ATLASNN_CACHE_DIR=off`` (or ``0``, ``none``, empty) turns it off. A
directory that cannot be created or written is skipped silently (a read-only home must not stop a
run); JAX's own errors while reading or writing an entry are not raised (it compiles instead).
Every program is cached, however quick it was to compile (the training chunks compile in 1–3 s,
the estimate's and the reference's in tens of milliseconds).
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

__all__ = ["cache_dir", "enable_compile_cache", "CACHE_ENV"]

CACHE_ENV = "ATLASNN_CACHE_DIR"
_OFF = ("", "0", "off", "none", "false")


def cache_dir() -> Path | None:
    """The directory the cache uses, or None when it is off."""
    given = os.environ.get(CACHE_ENV)
    if given is not None:
        return None if given.strip().lower() in _OFF else Path(given).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "atlasnn" / "jax"


def enable_compile_cache() -> Path | None:
    """Point JAX's persistent cache at :func:`cache_dir` (once, at import); returns the directory
    used, or None (off, or not writable)."""
    folder = cache_dir()
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not os.access(folder, os.W_OK):
            return None
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    jax.config.update("jax_raise_persistent_cache_errors", False)
    return folder

"""Atomic file writes shared by the run store and checkpoints.

(Placeholder moved from the runner; the reliability work replaces it with one writer that also
gives files the user's umask permissions.)
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def write_atomic(path: Path, write) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it onto ``path``;
    on any failure (Ctrl-C included) the temporary file is removed and ``path`` is untouched."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_json(path: Path, data: Any) -> None:
    """Write JSON atomically (temporary file, fsync, then rename)."""
    text = json.dumps(data, indent=1, default=_json_default, allow_nan=True)
    write_atomic(Path(path), lambda f: f.write(text.encode("utf-8")))


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``np.savez`` atomically (temporary file, fsync, then rename)."""
    write_atomic(Path(path), lambda f: np.savez(f, **arrays))

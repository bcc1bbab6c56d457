"""Splitting-method solutions saved as one checkpoint file (``kind = "splitting"``), and loaded back.

The format is :mod:`atlasnn.checkpoint._format`'s (arrays + JSON meta under one content hash,
atomic, no pickle): the kept states, their compensations and their step indices; the scheme, t0,
h and the step count, the solver's settings, the system and a free ``extra`` dict in the meta. The
loaded solution evaluates bit-identically and has its error estimate back (its solver is rebuilt
from the settings).
"""

from __future__ import annotations

import functools
import os
from typing import Any, Mapping

import numpy as np

from atlasnn.checkpoint._format import _describe_exc, _fail, _read, _resolve_system
from atlasnn.checkpoint._piecewise import write_payload
from atlasnn.checkpoint._polynomial import solved_meta
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.solutions import SplittingSolution
from atlasnn.solver import SplittingComposition
from atlasnn.systems import HamiltonianSystem

__all__ = ["KIND_SPLITTING", "save_splitting", "load_splitting"]

KIND_SPLITTING = "splitting"


def save_splitting(path: str | os.PathLike, solution: SplittingSolution, *,
                   extra: Mapping[str, Any] | None = None) -> str:
    """Write ``solution`` to ``path``; returns the content hash."""
    p = os.fspath(path)
    meta = solved_meta(p, KIND_SPLITTING, {"kind": "splitting", "scheme": solution.scheme}, solution, extra)
    meta["splitting"] = {"t0": solution.t0, "h": solution.h, "n_steps": solution.n_steps}
    arrays = {"split_kept": np.asarray(solution.kept, np.int64), "split_z": np.asarray(solution.z, np.float64),
              "split_e": np.asarray(solution.e, np.float64)}
    return write_payload(p, meta, arrays)


def load_splitting(path: str | os.PathLike, system: HamiltonianSystem | None = None) -> SplittingSolution:
    """The splitting solution a file holds (its hash verified first)."""
    p = os.fspath(path)
    arrays, meta = _read(p)
    try:
        kept, z, e = (arrays[k] for k in ("split_kept", "split_z", "split_e"))
        scheme = str(meta["architecture"]["scheme"])
        where = meta["splitting"]
        t0, h, n_steps = float(where["t0"]), float(where["h"]), int(where["n_steps"])
    except (KeyError, TypeError, ValueError) as exc:
        raise _fail(p, f"holds no splitting solution ({_describe_exc(exc)})") from None
    try:
        sys_ = _resolve_system(p, meta, system)
        info = dict(meta.get("info") or {})
        solver = SplittingComposition(**dict(info.get("settings") or {}))
        info.update({"path": p, "content_sha256": meta["content_sha256"], "extra": meta.get("extra") or {}})
        sol = SplittingSolution(sys_, scheme, t0, h, n_steps, kept, z, e, info)
        sol.estimator = functools.partial(solver.companion, sol)
        return sol
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the splitting solution from its meta ({_describe_exc(exc)})") from None

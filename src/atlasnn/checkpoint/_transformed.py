"""Time-transformed Gauss solutions saved as one checkpoint file (``kind = "time_transformed"``), and
loaded back.

What ``GaussCollocation`` returns where it marched in a fictitious time τ with ``time_scale =
"potential"`` (the default's choice for gravitational systems): the extended solution in τ (its
window edges, start states, compensations and stage increments, as a polynomial solution's), the
physical system, the end T and the solver's settings. The extended system is rebuilt from the
physical one (``poincare_system``); the loaded solution evaluates bit-identically and has its error
estimate back. A time scale given as a Python function cannot be rebuilt from a file and is
refused in one line.
"""

from __future__ import annotations

import os
from typing import Any, Mapping

import numpy as np

from atlasnn.checkpoint._format import _describe_exc, _fail, _read, _resolve_system
from atlasnn.checkpoint._piecewise import write_payload
from atlasnn.checkpoint._polynomial import solved_meta
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.solutions import PolynomialSolution, TimeTransformedSolution
from atlasnn.solver import GaussCollocation, poincare_system
from atlasnn.systems import HamiltonianSystem

__all__ = ["KIND_TRANSFORMED", "save_transformed", "load_transformed"]

KIND_TRANSFORMED = "time_transformed"
#: the time scales a file can name (a function cannot be rebuilt from one)
_NAMED_SCALES = ("potential",)


def save_transformed(path: str | os.PathLike, solution: TimeTransformedSolution, *,
                     extra: Mapping[str, Any] | None = None) -> str:
    """Write ``solution`` to ``path``; returns the content hash."""
    p = os.fspath(path)
    scale = solution.info.get("time_scale")
    if scale not in _NAMED_SCALES:
        raise _fail(p, f"a solution marched with the time scale {scale!r} (a Python function) cannot be saved: a "
                       "file cannot hold the function; save one marched with time_scale='potential', or evaluate it "
                       "and save the values")
    ext = solution.extended
    meta = solved_meta(p, KIND_TRANSFORMED, {"kind": "gauss-polynomial-in-tau", "stages": int(ext.stages),
                                             "time_scale": scale}, solution, extra)
    meta["time_transformed"] = {"end": float(solution.end), "extended_info": _extended_info(ext)}
    arrays = {"poly_edges": ext.edges, "poly_z": ext.z, "poly_e": ext.e, "poly_offsets": ext.offsets}
    if ext.L is not None:
        arrays["poly_L"] = ext.L
    if ext.check is not None:
        arrays["poly_check"] = ext.check
    return write_payload(p, meta, {k: np.asarray(v, np.float64) for k, v in arrays.items()})


def _extended_info(ext: PolynomialSolution) -> dict[str, Any]:
    """The extended solution's own record, JSON-able (its settings are the solver's)."""
    return {k: v for k, v in ext.info.items() if isinstance(v, (str, int, float, bool, type(None)))}


def load_transformed(path: str | os.PathLike, system: HamiltonianSystem | None = None) -> TimeTransformedSolution:
    """The time-transformed solution a file holds (its hash verified first)."""
    p = os.fspath(path)
    arrays, meta = _read(p)
    try:
        edges, z, e, offsets = (arrays[k] for k in ("poly_edges", "poly_z", "poly_e", "poly_offsets"))
        stages, scale = int(meta["architecture"]["stages"]), str(meta["architecture"]["time_scale"])
        end = float(meta["time_transformed"]["end"])
        ext_info = dict(meta["time_transformed"].get("extended_info") or {})
    except (KeyError, TypeError, ValueError) as exc:
        raise _fail(p, f"holds no time-transformed solution ({_describe_exc(exc)})") from None
    try:
        sys_ = _resolve_system(p, meta, system)
        info = dict(meta.get("info") or {})
        solver = GaussCollocation(**dict(info.get("settings") or {}))
        extended = poincare_system(sys_, scale)
        L = arrays.get("poly_L")
        ext = PolynomialSolution(extended, edges, z, e, L, stages, arrays.get("poly_check"), ext_info,
                                 resolve=None if L is not None else solver.resolver(extended), offsets=offsets)
        ext.estimator = lambda start=None: solver.companion(ext, start)
        info.update({"path": p, "content_sha256": meta["content_sha256"], "extra": meta.get("extra") or {}})
        return TimeTransformedSolution(sys_, ext, end, info)
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the time-transformed solution from its meta ({_describe_exc(exc)})") from None

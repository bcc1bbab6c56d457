"""Gauss collocation solutions saved as one checkpoint file (``kind = "polynomial"``), and loaded back.

The format is :mod:`atlasnn.checkpoint._format`'s (arrays + JSON meta under one content hash,
atomic, no pickle): the window edges (and their offsets, where not all zero), start states and
their compensation, and the stage increments L when the solution kept them (float64); the
solver's settings, the system and a free ``extra`` dict in the meta. The loaded solution evaluates
bit-identically and has its error estimate back (its solver is rebuilt from the settings).
"""

from __future__ import annotations

from typing import Any, Mapping

import jax
import numpy as np

from atlasnn.checkpoint._format import FORMAT, FORMAT_VERSION, _describe_exc, _fail, _resolve_system, _to_json
from atlasnn.checkpoint._identity import expectation_mismatch, record_probes
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.solutions import PolynomialSolution
from atlasnn.solver import GaussCollocation
from atlasnn.systems import HamiltonianSystem
from atlasnn.version import __version__

__all__ = ["KIND_POLYNOMIAL", "polynomial_payload", "polynomial_from", "solved_meta"]

KIND_POLYNOMIAL = "polynomial"


def solved_meta(p: str, kind: str, architecture: dict[str, Any], solution: Any,
                extra: Mapping[str, Any] | None) -> dict[str, Any]:
    """The meta of a solution a solver computed (kind, architecture, z0, t0, the system and its
    probes, the solver's record, ``extra``), or a one-line refusal of what is not JSON-able."""
    system = solution.system
    try:
        return {
            "format": FORMAT, "format_version": FORMAT_VERSION, "kind": kind,
            "atlasnn_version": __version__, "jax_version": jax.__version__,
            "architecture": {"state_dim": int(system.state_dim), **architecture},
            "z0": _to_json(np.asarray(solution.z0, np.float64), "z0"), "t0": float(solution.t0),
            "dtype": "float64", "system": _to_json(system.describe(), "system"),
            "system_probes": _to_json(record_probes(system, np.asarray(solution.z0, np.float64)), "system_probes"),
            "info": _to_json({k: v for k, v in solution.info.items() if k not in ("path", "content_sha256")},
                             "info"),
            "extra": _to_json(dict(extra or {}), "extra"),
        }
    except (TypeError, ValueError) as exc:
        raise _fail(p, f"cannot save: {exc}") from None


def polynomial_payload(p: str, solution: PolynomialSolution,
                       extra: Mapping[str, Any] | None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The meta and arrays a polynomial solution is saved as (before the hash)."""
    meta = solved_meta(p, KIND_POLYNOMIAL, {"kind": "gauss-polynomial", "stages": int(solution.stages)}, solution,
                       extra)
    arrays = {"poly_edges": solution.edges, "poly_z": solution.z, "poly_e": solution.e}
    if solution.L is not None:
        arrays["poly_L"] = solution.L
    if solution.check is not None:
        arrays["poly_check"] = solution.check
    if np.any(solution.offsets != 0):
        arrays["poly_offsets"] = solution.offsets
    return meta, {k: np.asarray(v, np.float64) for k, v in arrays.items()}


def polynomial_from(p: str, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any],
                    system: HamiltonianSystem | None, expect: Mapping[str, Any] | None = None,
                    owner: str = "the expected problem") -> PolynomialSolution:
    """The polynomial solution held by a file's ``arrays`` and ``meta`` (read and verified)."""
    try:
        stages = int(meta["architecture"]["stages"])
        edges, z, e = (arrays[k] for k in ("poly_edges", "poly_z", "poly_e"))
    except (KeyError, TypeError, ValueError) as exc:
        raise _fail(p, f"holds no Gauss collocation windows ({_describe_exc(exc)})") from None
    if edges.dtype != np.float64 or edges.ndim != 1 or edges.size < 2 or not np.all(np.diff(edges) > 0):
        raise _fail(p, "poly_edges must be at least two increasing float64 times")
    why = expectation_mismatch(meta, edges, expect)
    if why:
        raise _fail(p, f"not a model of {owner}: {why}")
    try:
        sys_ = _resolve_system(p, meta, system)
        info = dict(meta.get("info") or {})
        settings = dict(info.get("settings") or {})
        solver = GaussCollocation(**settings)
        info.update({"path": p, "content_sha256": meta["content_sha256"], "extra": meta.get("extra") or {}})
        L = arrays.get("poly_L")
        sol = PolynomialSolution(sys_, edges, z, e, L, stages, arrays.get("poly_check"), info,
                                 resolve=None if L is not None else solver.resolver(sys_),
                                 offsets=arrays.get("poly_offsets"))
        sol.estimator = lambda start=None: solver.companion(sol, start)
        return sol
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the polynomial solution from its meta ({_describe_exc(exc)})") from None

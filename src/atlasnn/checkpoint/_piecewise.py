"""Piecewise (time-marching) solutions saved as one checkpoint file, and loaded back.

:func:`save_piecewise` writes a :class:`~atlasnn.solutions._piecewise.PiecewiseSolution` in the format of
:mod:`atlasnn.checkpoint._format` with ``kind = "piecewise"``: the window models' leaves stacked
along a leading window axis, the window edges, the window records and (optionally) their loss
curves, all under one content hash. :func:`load_piecewise` verifies and rebuilds it. Both are
also importable from :mod:`atlasnn.checkpoint._single`.
"""

from __future__ import annotations

import math
import os
from typing import Any, Mapping

import numpy as np

from atlasnn.checkpoint._format import (
    _FLOAT_DTYPES,
    _build_meta,
    _canonical,
    _content_hash,
    _describe_exc,
    _fail,
    _leaf_arrays,
    model_skeleton,
    _read,
    _resolve_system,
    _restore_leaves,
    _to_json,
    _write_atomic,
    _x64,
)
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.checkpoint._identity import expectation_mismatch
from atlasnn.checkpoint._polynomial import KIND_POLYNOMIAL, polynomial_from, polynomial_payload
from atlasnn.solutions import PiecewiseSolution, PolynomialSolution, WindowRecord, stack_models, unstack_models
from atlasnn.systems import HamiltonianSystem

__all__ = ["KIND_PIECEWISE", "save_piecewise", "load_piecewise", "piecewise_payload", "piecewise_from",
           "write_payload"]

# ------------------------------------------------------- piecewise (time-marching) solutions
KIND_PIECEWISE = "piecewise"
_WINDOW_RECORD_FIELDS = (
    "index", "start", "end", "z_start", "gamma", "epochs", "stop_reason", "final_loss", "best_loss",
    "polish_steps", "polish_stop_reason", "polish_initial_loss", "loss", "wall_time", "compile_time",
)


def save_piecewise(
    path: str | os.PathLike,
    solution: Any,
    *,
    train_config: Any = None,
    extra: Mapping[str, Any] | None = None,
    histories: bool = True,
) -> str:
    """Save a :class:`~atlasnn.solutions._piecewise.PiecewiseSolution` as ONE checkpoint file; return its hash.

    The file has the format of :func:`save_checkpoint` with ``kind = "piecewise"``: the meta
    describes the first window's model (architecture, γ, z0 of the problem), the ``param_###``
    leaves are the window models stacked along a leading window axis, ``piecewise_edges`` holds
    the edges t_0..t_n (float64), ``meta["piecewise"]`` the window records and the scheme's info,
    and with ``histories`` the per-window loss curves (``window_adam_###``, ``window_polish_###``).
    The content hash covers all of it. ``train_config``: a TrainConfig, a MarchConfig's dict, or
    any JSON-able dict.
    """
    p = os.fspath(path)
    meta, arrays = piecewise_payload(p, solution, train_config, extra, histories)
    return write_payload(p, meta, arrays)


def piecewise_payload(p: str, solution: Any, train_config: Any, extra: Mapping[str, Any] | None,
                      histories: bool) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The meta and arrays :func:`save_piecewise` writes (before the hash), for writers that add
    their own (a march's progress)."""
    if isinstance(solution, PolynomialSolution):
        return polynomial_payload(p, solution, extra)
    if not isinstance(solution, PiecewiseSolution):
        raise _fail(p, f"save_piecewise needs a PiecewiseSolution, got {type(solution).__name__}")
    models = list(solution.models)
    meta = _build_meta(p, models[0], solution.system, KIND_PIECEWISE, None, train_config, extra)
    arrays, leaf_info = _leaf_arrays(solution.stacked, "param")
    meta["leaves"] = leaf_info
    meta["history"] = None
    arrays["piecewise_edges"] = np.asarray(solution.edges, dtype=np.float64)
    records = []
    for k, rec in enumerate(solution.windows):
        records.append({f: getattr(rec, f) for f in _WINDOW_RECORD_FIELDS})
        if histories and rec.history is not None:
            arrays[f"window_adam_{k:03d}"] = np.asarray(rec.history, dtype=np.float64)
        if histories and rec.polish_history is not None:
            arrays[f"window_polish_{k:03d}"] = np.asarray(rec.polish_history, dtype=np.float64)
    try:
        meta["piecewise"] = {
            "n_windows": len(models),
            "windows": _to_json(records, "windows"),
            "info": _to_json(dict(solution.info), "info"),
        }
    except (TypeError, ValueError) as exc:
        raise _fail(p, f"cannot save: {exc}") from None
    return meta, arrays


def write_payload(p: str, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> str:
    """Hash ``meta`` and ``arrays`` together, store the meta beside them, write atomically."""
    meta["content_sha256"] = _content_hash(meta, arrays)
    arrays["meta"] = np.frombuffer(_canonical(meta), dtype=np.uint8)
    _write_atomic(p, arrays)
    return meta["content_sha256"]


def _window_records(path: str, records: Any, arrays: Mapping[str, np.ndarray]) -> list:
    out = []
    for k, rec in enumerate(records):
        if not isinstance(rec, dict) or set(rec) != set(_WINDOW_RECORD_FIELDS):
            raise _fail(path, f"piecewise window record {k} is malformed")
        values = {f: (math.nan if rec[f] is None else rec[f]) for f in _WINDOW_RECORD_FIELDS}
        out.append(WindowRecord(**values, history=arrays.get(f"window_adam_{k:03d}"),
                                polish_history=arrays.get(f"window_polish_{k:03d}")))
    return out


def load_piecewise(path: str | os.PathLike, system: HamiltonianSystem | None = None, *,
                   expect: Mapping[str, Any] | None = None, owner: str = "the expected problem"):
    """Load a :class:`~atlasnn.solutions._piecewise.PiecewiseSolution` written by :func:`save_piecewise`.

    The hash is verified, the stacked leaves are checked against a skeleton of the stored
    architecture (number, shapes, dtypes) and split into the window models; the system is
    rebuilt from its spec unless given (as for :func:`load_checkpoint`). The loaded solution
    predicts bit-identically to the saved one. ``meta`` and the path are in its ``info``.
    ``expect`` (keys ``"system"`` and ``"interval"``, as for :func:`load_checkpoint`) refuses a
    solution of another problem with one line naming ``owner``.
    """
    p = os.fspath(path)
    arrays, meta = _read(p)
    if meta.get("kind") == KIND_POLYNOMIAL:
        return polynomial_from(p, arrays, meta, system, expect, owner)
    if meta.get("kind") != KIND_PIECEWISE or not isinstance(meta.get("piecewise"), dict):
        raise _fail(p, f"holds no piecewise solution (kind {meta.get('kind')!r}); use load_checkpoint")
    return piecewise_from(p, arrays, meta, system, expect, owner)


def piecewise_from(p: str, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any],
                   system: HamiltonianSystem | None, expect: Mapping[str, Any] | None = None,
                   owner: str = "the expected problem") -> PiecewiseSolution:
    """The piecewise solution held by a file's ``arrays`` and ``meta`` (read and verified)."""
    if not isinstance(meta.get("piecewise"), dict):
        raise _fail(p, "holds no piecewise windows")
    pw = meta["piecewise"]
    n = pw.get("n_windows")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise _fail(p, f"bad piecewise n_windows {n!r}")
    edges = arrays.get("piecewise_edges")
    if edges is None or edges.dtype != np.float64 or edges.shape != (n + 1,) or not np.all(np.diff(edges) > 0):
        raise _fail(p, f"piecewise_edges must be {n + 1} increasing float64 times")
    why = expectation_mismatch(meta, edges, expect)
    if why:
        raise _fail(p, f"not a model of {owner}: {why}")
    try:
        arch, dtype = meta["architecture"], meta["dtype"]
        if dtype not in _FLOAT_DTYPES:
            raise _fail(p, f"unsupported dtype {dtype!r}")
        with _x64(dtype):
            skeleton = model_skeleton(arch, stack=lambda m: stack_models([m] * n))
            stacked = _restore_leaves(p, arrays, "param", skeleton, "stacked model")
        sys_ = _resolve_system(p, meta, system)
        records = _window_records(p, pw.get("windows") or [], arrays)
        info = dict(pw.get("info") or {})
        info.update({"path": p, "content_sha256": meta["content_sha256"], "extra": meta.get("extra") or {}})
        with _x64(dtype):
            return PiecewiseSolution(unstack_models(stacked, n), sys_, edges, records, info)
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the piecewise solution from its meta ({_describe_exc(exc)})") from None

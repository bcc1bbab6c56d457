"""Bundle solutions saved as one checkpoint file (``kind = "bundle"``), and loaded back.

The format is :mod:`atlasnn.checkpoint._format`'s (arrays + JSON meta under one content hash,
atomic, no pickle): each window's leaves as ``w###_#####`` arrays, the window edges, and in the
meta the architecture (with the input normalisation), the box, the system's description (a
built-in or expression system is rebuilt from it) and a free ``extra`` dict.
"""

from __future__ import annotations

import os
from typing import Any, Mapping

import jax
import numpy as np

from atlasnn.checkpoint._format import (
    _FLOAT_DTYPES,
    FORMAT,
    FORMAT_VERSION,
    _describe_exc,
    _fail,
    _leaf_arrays,
    _read,
    _resolve_system,
    _restore_leaves,
    _to_json,
    _x64,
)
from atlasnn.checkpoint._piecewise import write_payload
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.nn import BundleTrial, make_bundle_model
from atlasnn.solutions import BundleSolution
from atlasnn.systems import BundleBox, HamiltonianSystem
from atlasnn.version import __version__

__all__ = ["KIND_BUNDLE", "save_bundle", "load_bundle"]

KIND_BUNDLE = "bundle"


def save_bundle(path: str | os.PathLike, solution: BundleSolution, *, extra: Mapping[str, Any] | None = None) -> str:
    """Save a :class:`~atlasnn.solutions.BundleSolution` as one checkpoint file; return its hash."""
    p = os.fspath(path)
    if not isinstance(solution, BundleSolution):
        raise _fail(p, f"save_bundle needs a BundleSolution, got {type(solution).__name__}")
    first = solution.windows[0]
    dtype = str(np.dtype(first.weights[0].dtype))
    arrays: dict[str, np.ndarray] = {"bundle_edges": np.asarray(solution.edges, np.float64)}
    leaves = []
    for k, w in enumerate(solution.windows):
        a, info = _leaf_arrays(w, f"w{k:03d}")
        arrays.update(a)
        leaves.append(info)
    try:
        meta = {
            "format": FORMAT, "format_version": FORMAT_VERSION, "kind": KIND_BUNDLE,
            "atlasnn_version": __version__, "jax_version": jax.__version__, "dtype": dtype,
            "architecture": _to_json(first.architecture(), "architecture"),
            "box": _to_json(solution.box.describe(), "box"), "n_windows": len(solution.windows),
            "leaves": leaves, "history": None,
            "system": None if solution.system is None else _to_json(solution.system.describe(), "system"),
            "extra": _to_json(dict(extra or {}), "extra"),
        }
    except (TypeError, ValueError) as exc:
        raise _fail(p, f"cannot save: {exc}") from None
    return write_payload(p, meta, arrays)


def _skeleton(arch: Mapping[str, Any], t0: float) -> BundleTrial:
    centre = [float(c) for c in arch["centre"]]
    model = make_bundle_model(centre, [1.0] * len(centre), int(arch["state_dim"]), scaling=arch["scaling"],
                              width=int(arch["width"]), depth=int(arch["depth"]), t0=t0, activation=arch["activation"])
    return BundleTrial(model.weights, model.biases, model.scaling, float(t0), tuple(centre),
                       tuple(float(v) for v in arch["inv_half"]), arch["activation"])


def load_bundle(path: str | os.PathLike, system: HamiltonianSystem | None = None) -> BundleSolution:
    """Load a bundle written by :func:`save_bundle` (hash verified, leaves checked against the
    stored architecture); it predicts bit-identically to the saved one. The system is rebuilt from
    its description unless given."""
    p = os.fspath(path)
    arrays, meta = _read(p)
    if meta.get("kind") != KIND_BUNDLE:
        raise _fail(p, f"holds no bundle (kind {meta.get('kind')!r})")
    try:
        n = int(meta["n_windows"])
        edges = arrays.get("bundle_edges")
        if edges is None or edges.shape != (n + 1,) or not np.all(np.diff(edges) > 0):
            raise _fail(p, f"bundle_edges must be {n + 1} increasing times")
        dtype = meta["dtype"]
        if dtype not in _FLOAT_DTYPES:
            raise _fail(p, f"unsupported dtype {dtype!r}")
        with _x64(dtype):
            windows = tuple(_restore_leaves(p, arrays, f"w{k:03d}", _skeleton(meta["architecture"], edges[k]),
                                            f"window {k}") for k in range(n))
        system_ = _resolve_system(p, meta, system) if (system is not None or meta.get("system")) else None
        return BundleSolution(windows, edges, BundleBox.from_dict(meta["box"]), system_)
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the bundle from its meta ({_describe_exc(exc)})") from None

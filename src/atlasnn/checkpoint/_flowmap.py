"""Flow-map bundles saved as one checkpoint file (``kind = "flowmap"``), and loaded back.

The format is :mod:`atlasnn.checkpoint._format`'s (arrays + JSON meta under one content hash,
atomic, no pickle): the output layer ``W`` as one float64 array; the basis (degrees, region, h),
the box, the window count and a free ``extra`` dict in the meta.
"""

from __future__ import annotations

import os
from typing import Any, Mapping

import jax
import numpy as np

from atlasnn.checkpoint._format import FORMAT, FORMAT_VERSION, _describe_exc, _fail, _read, _to_json
from atlasnn.checkpoint._piecewise import write_payload
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.solutions import ChebyshevBasis, FlowMapBundle
from atlasnn.systems import BundleBox
from atlasnn.version import __version__

__all__ = ["KIND_FLOWMAP", "save_flowmap", "load_flowmap"]

KIND_FLOWMAP = "flowmap"
_BASIS_FIELDS = ("time_degree", "state_degree", "param_degree", "state_dim", "low", "high", "h")


def save_flowmap(path: str | os.PathLike, bundle: FlowMapBundle, *, extra: Mapping[str, Any] | None = None) -> str:
    """Save a :class:`~atlasnn.solutions.FlowMapBundle` as one checkpoint file; return its hash."""
    p = os.fspath(path)
    if not isinstance(bundle, FlowMapBundle):
        raise _fail(p, f"save_flowmap needs a FlowMapBundle, got {type(bundle).__name__}")
    try:
        meta = {
            "format": FORMAT, "format_version": FORMAT_VERSION, "kind": KIND_FLOWMAP,
            "atlasnn_version": __version__, "jax_version": jax.__version__,
            "basis": _to_json({f: getattr(bundle.basis, f) for f in _BASIS_FIELDS}, "basis"),
            "box": _to_json(bundle.box.describe(), "box"), "windows": int(bundle.windows),
            "info": _to_json(bundle.info, "info"), "extra": _to_json(dict(extra or {}), "extra"),
        }
    except (TypeError, ValueError) as exc:
        raise _fail(p, f"cannot save: {exc}") from None
    return write_payload(p, meta, {"flowmap_W": np.asarray(bundle.W, np.float64)})


def load_flowmap(path: str | os.PathLike) -> FlowMapBundle:
    """Load a flow-map bundle written by :func:`save_flowmap` (hash verified); it predicts
    bit-identically to the saved one."""
    p = os.fspath(path)
    arrays, meta = _read(p)
    if meta.get("kind") != KIND_FLOWMAP:
        raise _fail(p, f"holds no flow-map bundle (kind {meta.get('kind')!r})")
    try:
        b = meta["basis"]
        basis = ChebyshevBasis(int(b["time_degree"]), int(b["state_degree"]), int(b["param_degree"]),
                               int(b["state_dim"]), tuple(map(float, b["low"])), tuple(map(float, b["high"])),
                               float(b["h"]))
        W = arrays["flowmap_W"]
        if W.shape != (basis.state_dim, basis.time_degree + 1, basis.n_space):
            raise _fail(p, f"flowmap_W has shape {W.shape}, the basis needs "
                           f"{(basis.state_dim, basis.time_degree + 1, basis.n_space)}")
        return FlowMapBundle(basis, W, BundleBox.from_dict(meta["box"]), int(meta["windows"]), dict(meta["info"]))
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the flow map from its meta ({_describe_exc(exc)})") from None

"""A time-marching run's progress saved as one checkpoint file, so that an interrupted march
resumes at the window where it stopped.

:func:`save_march_progress` writes a :class:`~atlasnn.training.MarchProgress` in the piecewise
format (:mod:`atlasnn.checkpoint._piecewise`: the finished windows' models, edges and records)
with ``kind = "march_progress"``, plus the carried Adam state (``opt_###`` leaves, their structure
rebuilt on loading from the last window's model and TrainConfig, as :func:`load_state` does), the
adaptive controller's state (next trial length, the solution's running extent ``march_lo`` /
``march_hi``, every attempt), all under one content hash.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from atlasnn.checkpoint._format import _describe_exc, _fail, _leaf_arrays, _read, _restore_leaves, _to_json, _x64
from atlasnn.checkpoint._piecewise import piecewise_from, piecewise_payload, write_payload
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.solutions import PiecewiseSolution
from atlasnn.systems import HamiltonianSystem
from atlasnn.training import MarchProgress, TrainConfig, state_template

__all__ = ["KIND_MARCH_PROGRESS", "save_march_progress", "load_march_progress"]

KIND_MARCH_PROGRESS = "march_progress"


def save_march_progress(path: str | os.PathLike, progress: MarchProgress, system: HamiltonianSystem) -> str:
    """Save a march's progress as one file (atomic; ``progress.info`` as the file's extra); return
    its content hash."""
    p = os.fspath(path)
    if not isinstance(progress, MarchProgress):
        raise _fail(p, f"save_march_progress needs a MarchProgress, got {type(progress).__name__}")
    solution = PiecewiseSolution(list(progress.trained), system, np.asarray(progress.edges, np.float64),
                                 list(progress.records), {})
    meta, arrays = piecewise_payload(p, solution, progress.opt_config, progress.info, histories=True)
    meta["kind"] = KIND_MARCH_PROGRESS
    state: dict[str, Any] = {"next_length": float(progress.next_length), "opt_leaves": None,
                             "extent": progress.lo is not None}
    if progress.opt_state is not None:
        if not isinstance(progress.opt_config, TrainConfig):
            raise _fail(p, "a carried Adam state needs the TrainConfig it was trained with (opt_config)")
        opt_arrays, state["opt_leaves"] = _leaf_arrays(progress.opt_state, "opt")
        arrays.update(opt_arrays)
    if progress.lo is not None:
        arrays["march_lo"] = np.asarray(progress.lo, np.float64)
        arrays["march_hi"] = np.asarray(progress.hi, np.float64)
    try:
        state["attempts"] = _to_json(list(progress.attempts), "attempts")
    except (TypeError, ValueError) as exc:
        raise _fail(p, f"cannot save: {exc}") from None
    meta["march_progress"] = state
    return write_payload(p, meta, arrays)


def load_march_progress(path: str | os.PathLike, system: HamiltonianSystem | None = None) -> MarchProgress:
    """Load what :func:`save_march_progress` wrote (hash verified, shapes checked, no pickle)."""
    p = os.fspath(path)
    arrays, meta = _read(p)
    state = meta.get("march_progress")
    if meta.get("kind") != KIND_MARCH_PROGRESS or not isinstance(state, dict):
        raise _fail(p, f"holds no march progress (kind {meta.get('kind')!r})")
    solution = piecewise_from(p, arrays, meta, system)
    try:
        config = None if meta.get("train_config") is None else TrainConfig(**meta["train_config"])
        opt_state = None
        if state.get("opt_leaves") is not None:
            with _x64(meta["dtype"]):
                template = state_template(solution.models[-1], config).opt_state
                opt_state = _restore_leaves(p, arrays, "opt", template, "optimizer state")
        lo = hi = None
        if state.get("extent"):
            lo, hi = np.asarray(arrays["march_lo"], np.float64), np.asarray(arrays["march_hi"], np.float64)
        return MarchProgress(list(solution.edges), list(solution.models), list(solution.windows), opt_state, config,
                             next_length=float(state["next_length"]), lo=lo, hi=hi,
                             attempts=list(state.get("attempts") or []), info=dict(meta.get("extra") or {}))
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the march's progress from its meta ({_describe_exc(exc)})") from None

"""Checkpoints: every solution saved and loaded by one pair, :func:`save` and :func:`load`; trained
models, training states and time-marching solutions saved as one ``.npz`` file each (arrays + JSON meta, a content hash, atomic writes, never pickle), loaded back with
every problem reported as one line naming the file; a time-marching run's progress, window by
window, to resume it; bundle solutions."""

from atlasnn.checkpoint._bundle import KIND_BUNDLE, load_bundle, save_bundle
from atlasnn.checkpoint._door import load, save
from atlasnn.checkpoint._flowmap import KIND_FLOWMAP, load_flowmap, save_flowmap
from atlasnn.checkpoint._format import FORMAT, FORMAT_VERSION
from atlasnn.checkpoint._march import KIND_MARCH_PROGRESS, load_march_progress, save_march_progress
from atlasnn.checkpoint._piecewise import KIND_PIECEWISE, load_piecewise, save_piecewise
from atlasnn.checkpoint._single import (
    KIND_MODEL,
    KIND_STATE,
    Checkpoint,
    load_checkpoint,
    load_state,
    save_checkpoint,
    save_state,
)

__all__ = [
    "save",
    "load",
    "save_checkpoint",
    "load_checkpoint",
    "Checkpoint",
    "save_state",
    "load_state",
    "save_piecewise",
    "load_piecewise",
    "save_bundle",
    "load_bundle",
    "save_flowmap",
    "load_flowmap",
    "KIND_FLOWMAP",
    "KIND_BUNDLE",
    "save_march_progress",
    "load_march_progress",
    "KIND_MARCH_PROGRESS",
    "FORMAT",
    "FORMAT_VERSION",
    "KIND_MODEL",
    "KIND_STATE",
    "KIND_PIECEWISE",
]

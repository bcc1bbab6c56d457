"""Saving and loading trained models (and interrupted training runs) without running code.

:func:`save_checkpoint` and :func:`load_checkpoint` store and restore a trained model (with its
history, training config and a free ``extra`` dict) as one ``.npz`` file, :func:`save_state` and
:func:`load_state` a :class:`~atlasnn.training.TrainState` so that an interrupted training continues
exactly; :class:`Checkpoint` is what :func:`load_checkpoint` returns. The file format (no pickle,
a content hash, atomic writes) is described and implemented in :mod:`atlasnn.checkpoint._format`;
piecewise (time-marching) solutions are saved by :mod:`atlasnn.checkpoint._piecewise`.

The model's skeleton is its architecture through :func:`~atlasnn.nn._trial.make_model` under
``equinox.filter_eval_shape`` (shapes and dtypes of the stored float type, no initial weights
drawn or compiled) and the stored leaves are put into that skeleton, after checking their
number, shapes and dtypes. A system defined by a Python function cannot be stored as data; it
has to be passed again when loading. Built-in and expression systems are rebuilt from their
``spec``.

Every problem with a file is raised as a one-line :class:`~atlasnn.errors.CheckpointError` that
names the file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
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
    _write_atomic,
    _x64,
)
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.checkpoint._identity import interval_mismatch, system_mismatch
from atlasnn.checkpoint._piecewise import KIND_PIECEWISE
from atlasnn.training import History, TrainConfig, TrainState, state_template
from atlasnn.nn import TrialSolution
from atlasnn.solutions import Solution
from atlasnn.systems import HamiltonianSystem

KIND_MODEL = "model"
KIND_STATE = "train_state"

_HISTORY_FIELDS = ("loss", "residual", "energy", "gamma")

__all__ = ["Checkpoint", "save_checkpoint", "load_checkpoint", "save_state", "load_state"]


# ------------------------------------------------------------------------ history
def _history_arrays(history: Any) -> tuple[dict[str, np.ndarray], dict[str, Any] | None]:
    if history is None:
        return {}, None
    arrays = {f"history_{f}": np.asarray(getattr(history, f)) for f in _HISTORY_FIELDS}
    info = {"epochs": int(arrays["history_loss"].shape[0]), "gamma_names": list(history.gamma_names)}
    return arrays, info


def _history_from(path: str, meta: Mapping[str, Any], arrays: Mapping[str, np.ndarray]):
    info = meta.get("history")
    if info is None:
        return None
    names = [f"history_{f}" for f in _HISTORY_FIELDS]
    missing = [n for n in names if n not in arrays]
    if missing:
        raise _fail(path, f"history arrays missing: {missing}")
    loss, res, en, gam = (arrays[n] for n in names)
    gamma_names = tuple(str(g) for g in info.get("gamma_names", []))
    n = loss.shape[0] if loss.ndim == 1 else -1
    if (
        n < 0 or res.shape != (n,) or en.shape != (n,)
        or gam.shape != (n, len(gamma_names))
    ):
        raise _fail(path, "history arrays have inconsistent shapes")
    return History(loss, res, en, gam, gamma_names)


def _save(path, model, system, kind, history, train_config, extra, more_arrays, more_meta) -> str:
    path = os.fspath(path)
    meta = _build_meta(path, model, system, kind, history, train_config, extra)
    arrays, leaf_info = _leaf_arrays(model, "param")
    meta["leaves"] = leaf_info
    h_arrays, h_info = _history_arrays(history)
    arrays.update(h_arrays)
    meta["history"] = h_info
    arrays.update(more_arrays)
    meta.update(more_meta)
    digest = _content_hash(meta, arrays)
    meta["content_sha256"] = digest
    arrays["meta"] = np.frombuffer(_canonical(meta), dtype=np.uint8)
    _write_atomic(path, arrays)
    return digest


def save_checkpoint(
    path: str | os.PathLike,
    model: TrialSolution,
    system: HamiltonianSystem | None,
    *,
    history: Any = None,
    train_config: Any = None,
    extra: Mapping[str, Any] | None = None,
) -> str:
    """Save a trained model (and optionally its history and config) to ``path``; return its hash.

    Args:
        path: the file to write (used as given; no suffix is added). Written atomically.
        model: the trained :class:`~atlasnn.nn._trial.TrialSolution` (non-finite values are kept).
        system: its Hamiltonian system (its ``describe()`` is stored; a built-in or expression
            system is rebuilt from it on load, a Python-function system must be passed again).
        history: a :class:`~atlasnn.training._records.History` to keep, or ``None``.
        train_config: a :class:`~atlasnn.training.TrainConfig` (or a JSON-able dict), or ``None``.
        extra: a free JSON-able dict (model name, seed, ``interval``, stop reason, ...).
            An ``"interval": [t0, T]`` entry is used by :meth:`Checkpoint.solution`.
            Non-finite floats in the meta are written as ``null``.

    Returns:
        The ``content_sha256`` recorded in the file.
    """
    return _save(path, model, system, KIND_MODEL, history, train_config, extra, {}, {})


def save_state(
    path: str | os.PathLike,
    state: Any,
    system: HamiltonianSystem | None,
    train_config: Any,
    *,
    extra: Mapping[str, Any] | None = None,
) -> str:
    """Save a :class:`~atlasnn.training.TrainState` (model, Adam state, bookkeeping, epoch, history)
    so that ``train(..., resume=load_state(path))`` continues the run exactly; return the hash.

    ``train_config`` must be the run's :class:`~atlasnn.training.TrainConfig`: loading needs it to
    rebuild the structure of the optimizer state.
    """
    p = os.fspath(path)
    if not isinstance(train_config, TrainConfig):
        raise _fail(p, f"save_state needs the run's TrainConfig, got {type(train_config).__name__}")
    epoch = int(state.epoch)
    opt_arrays, opt_info = _leaf_arrays(state.opt_state, "opt")
    track_arrays, track_info = _leaf_arrays(state.track, "track")
    more_meta = {"state": {"epoch": epoch, "opt_leaves": opt_info, "track_leaves": track_info}}
    return _save(
        p, state.model, system, KIND_STATE, state.history, train_config, extra,
        {**opt_arrays, **track_arrays}, more_meta,
    )


def _rebuild_model(path: str, meta: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> TrialSolution:
    try:
        dtype = meta["dtype"]
        if dtype not in _FLOAT_DTYPES:
            raise _fail(path, f"unsupported dtype {dtype!r}")
        arch = meta["architecture"]
        state_dim = int(arch["state_dim"])
        z0 = meta.get("z0")
        # the z0 leaf is overwritten below; the skeleton just needs a valid one of the right size
        if not (isinstance(z0, list) and len(z0) == state_dim and all(isinstance(x, (int, float)) for x in z0)):
            z0 = [0.0] * state_dim
        with _x64(dtype):
            return _restore_leaves(path, arrays, "param", model_skeleton(arch, z0), "model")
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(path, f"cannot rebuild the model from its meta ({_describe_exc(exc)})") from None


@dataclass
class Checkpoint:
    """A loaded checkpoint.

    Attributes:
        model: the restored :class:`~atlasnn.nn._trial.TrialSolution` (bit-identical to the saved one).
        system: the system passed to :func:`load_checkpoint`, or the one rebuilt from its spec.
        history: the stored :class:`~atlasnn.training._records.History`, or ``None``.
        meta: the file's meta dict (architecture, gamma, system, train_config, extra, hash, ...).
        path: the file it came from.
    """

    model: TrialSolution
    system: HamiltonianSystem
    history: Any
    meta: dict[str, Any]
    path: str = ""

    @property
    def extra(self) -> dict[str, Any]:
        return dict(self.meta.get("extra") or {})

    @property
    def content_sha256(self) -> str:
        return str(self.meta.get("content_sha256", ""))

    @property
    def interval(self) -> tuple[float, float] | None:
        iv = self.extra.get("interval")
        if isinstance(iv, (list, tuple)) and len(iv) == 2 and all(isinstance(x, (int, float)) for x in iv):
            return float(iv[0]), float(iv[1])
        return None

    def train_config(self):
        """The stored :class:`~atlasnn.training.TrainConfig`, or ``None`` if none was stored."""
        cfg = self.meta.get("train_config")
        if cfg is None:
            return None
        try:
            return TrainConfig(**cfg)
        except (TypeError, AtlasError) as exc:
            raise _fail(self.path, f"stored train_config is not usable ({_describe_exc(exc)})") from None

    def require(self, expect: Mapping[str, Any], owner: str = "the expected problem") -> None:
        """Refuse (one-line CheckpointError) a model that is not of ``expect``'s problem: keys
        ``"system"`` (a HamiltonianSystem or a ``describe()`` dict), ``"interval"`` ((t0, T)) and
        ``"z0"`` (the model's initial state); ``owner`` names the problem in the message."""
        unknown = sorted(set(expect) - {"system", "interval", "z0"})
        if unknown:
            raise TypeError(f"expect has unknown keys {unknown} (known: interval, system, z0)")
        stored = self.meta.get("system") if isinstance(self.meta.get("system"), dict) else self.system.describe()
        why = None
        if expect.get("system") is not None:
            why = system_mismatch(stored, expect["system"], self.meta.get("system_probes"))
        if why is None and expect.get("z0") is not None:
            # the model holds z0 in its own float type: compare with the expected z0 rounded to it
            z0, want = self.meta.get("z0"), [float(x) for x in expect["z0"]]
            rounded = np.asarray(want, dtype=self.meta.get("dtype", "float64")).astype(np.float64)
            if not (isinstance(z0, list) and len(z0) == len(want) and np.allclose(z0, rounded, rtol=1e-12, atol=0.0)):
                why = f"its model starts at z0 = {[float(f'{x:.8g}') for x in z0]}, not at {want}"
        if why is None and "interval" in expect:
            why = interval_mismatch(self.interval, expect["interval"])
        if why:
            raise _fail(self.path, f"not a model of {owner}: {why}")

    def solution(self, outside: str = "warn") -> Solution:
        """The model as a :class:`~atlasnn.solutions._solution.Solution` with the stored training interval
        (evaluating beyond it warns, raises or is allowed per ``outside``) and extra as its info."""
        return Solution(self.model, self.system, interval=self.interval, info=self.extra, outside=outside)


def load_checkpoint(
    path: str | os.PathLike,
    system: HamiltonianSystem | None = None,
    *,
    expect: Mapping[str, Any] | None = None,
) -> Checkpoint:
    """Load a checkpoint written by :func:`save_checkpoint` (or :func:`save_state`).

    Args:
        path: the file.
        system: the Hamiltonian system; required when it was a Python function (no spec), else
            rebuilt from the stored spec. A given system must be the stored one: same d, state
            names, spec (built-in name and parameters, or expression and parameters), z0, and H
            at the recorded probe states (see :mod:`atlasnn.checkpoint._identity`, which also says what
            cannot be compared for Python-function systems).
        expect: what the caller knows the model must be, any of ``"system"`` (a
            HamiltonianSystem or its ``describe()`` dict, e.g. a run's ``results["system"]``),
            ``"interval"`` ((t0, T) of the training) and ``"z0"`` (the model's initial state).

    A float64 checkpoint is restored as float64 arrays; evaluate it with JAX's x64 mode on
    (``jax.enable_x64(True)`` or ``atlasnn.enable_x64()``).

    Raises:
        CheckpointError: one line naming the file and the problem (missing, foreign, truncated,
            altered, newer format, incompatible leaves, system needed, another system or
            interval than the given or expected one).
    """
    p = os.fspath(path)
    arrays, meta = _read(p)
    if meta.get("kind") == KIND_PIECEWISE:  # hook: one file, many window models
        raise _fail(p, "holds a piecewise (time-marching) solution; load it with load_piecewise")
    model = _rebuild_model(p, meta, arrays)
    try:
        sys_ = _resolve_system(p, meta, system)
    except (KeyError, TypeError, ValueError) as exc:
        raise _fail(p, f"malformed meta ({_describe_exc(exc)})") from None
    history = _history_from(p, meta, arrays)
    ck = Checkpoint(model=model, system=sys_, history=history, meta=meta, path=p)
    if expect:
        ck.require(expect)
    return ck


def load_state(path: str | os.PathLike, system: HamiltonianSystem | None = None):
    """Load a :class:`~atlasnn.training.TrainState` written by :func:`save_state`, to pass as
    ``train(model, system, T, config, resume=...)`` with the same config.

    The optimizer state and bookkeeping are rebuilt without pickle: a template is built from the
    restored model and the stored TrainConfig (:func:`atlasnn.training.state_template`) and the stored leaves are put into its structure, shapes checked.
    ``system``, when given, must be the stored one (as for :func:`load_checkpoint`).
    """
    p = os.fspath(path)
    arrays, meta = _read(p)
    if meta.get("kind") != KIND_STATE or not isinstance(meta.get("state"), dict):
        raise _fail(p, "holds no training state (written by save_checkpoint, not save_state)")
    model = _rebuild_model(p, meta, arrays)
    if system is not None:
        _resolve_system(p, meta, system)
    try:
        cfg = TrainConfig(**meta["train_config"])
        epoch = meta["state"]["epoch"]
        if isinstance(epoch, bool) or not isinstance(epoch, int) or epoch < 0:
            raise ValueError(f"bad epoch {epoch!r}")
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the training state from its meta ({_describe_exc(exc)})") from None
    dtype = meta["dtype"]
    with _x64(dtype):
        template = state_template(model, cfg)
        opt_state = _restore_leaves(p, arrays, "opt", template.opt_state, "optimizer state")
        track = _restore_leaves(p, arrays, "track", template.track, "trainer bookkeeping")
    history = _history_from(p, meta, arrays)
    if history is None:
        history = template.history
    return TrainState(model=model, opt_state=opt_state, track=track, epoch=epoch, history=history)

"""Saving and loading trained models (and interrupted training runs) without running code.

A checkpoint is one ``.npz`` archive (NumPy's zip of ``.npy`` arrays, written by ``np.savez``,
read with ``allow_pickle=False``), so opening one can never execute anything. It holds:

- ``param_000``, ``param_001``, …: the model's array leaves in ``jax.tree_util.tree_flatten``
  order;
- ``history_loss``, ``history_residual``, ``history_energy``, ``history_gamma`` (optional): the
  per-epoch training records;
- for a training state (:func:`save_state`) also ``opt_000``… (Adam's state leaves) and
  ``track_000``… (the trainer's bookkeeping leaves);
- ``meta``: UTF-8 JSON stored as a uint8 array, with the format marker and version, the package
  versions, the model architecture, γ, z0, t0, dtype, the system's description, the training
  config, a free ``extra`` dict, the leaf shapes and dtypes, and ``content_sha256``.

``content_sha256`` is the SHA-256 of the canonical JSON of ``meta`` without that field (sorted
keys, compact separators) followed by every other array's name, dtype, shape and raw bytes in
sorted name order; loading recomputes it, so an altered or damaged file is refused.

The model is rebuilt from its architecture with :func:`~atlasnn.model.make_model` (under the
stored float type) and the stored leaves are put into that skeleton, after checking their
number, shapes and dtypes. A system defined by a Python function cannot be stored as data; it
has to be passed again when loading. Built-in and expression systems are rebuilt from their
``spec``.

Files are written atomically by :func:`atlasnn.fileio.write_atomic`: to a temporary file in the
same directory, flushed and fsynced, then renamed onto the real name, so a crash never leaves a
half-written file under that name; the file gets the permissions an ordinary ``open()`` gives
(0644 under the usual umask 022).

Every problem with a file is raised as a one-line :class:`~atlasnn.errors.CheckpointError` that
names the file.
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import json
import math
import os
import re
from dataclasses import dataclass
from typing import Any, Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn._version import __version__
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.fileio import write_atomic
from atlasnn.identity import interval_mismatch, record_probes, system_mismatch
from atlasnn.model import TrialSolution, make_model
from atlasnn.solution import Solution
from atlasnn.systems import HamiltonianSystem, system_from_spec

FORMAT = "atlasnn-checkpoint"
FORMAT_VERSION = 1

KIND_MODEL = "model"
KIND_STATE = "train_state"

_HISTORY_FIELDS = ("loss", "residual", "energy", "gamma")
_FLOAT_DTYPES = ("float32", "float64")

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "Checkpoint",
    "save_checkpoint",
    "load_checkpoint",
    "save_state",
    "load_state",
    "save_piecewise",
    "load_piecewise",
]


# ------------------------------------------------------------------------- errors
def _one_line(text: Any) -> str:
    return " ".join(str(text).split())


def _fail(path: str, problem: str) -> CheckpointError:
    return CheckpointError(f"checkpoint {path}: {_one_line(problem)}")


def _describe_exc(exc: BaseException) -> str:
    msg = _one_line(exc)
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


# --------------------------------------------------------------------------- JSON
def _to_json(obj: Any, where: str) -> Any:
    """A plain-JSON copy of obj: tuples become lists, NumPy scalars and arrays Python values,
    non-finite floats ``None`` (the meta is strict JSON; the arrays keep the exact values)."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, np.integer)) and not isinstance(obj, np.bool_):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if isinstance(obj, Mapping):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"{where} has a non-string key {k!r}")
            out[k] = _to_json(v, f"{where}.{k}")
        return out
    if isinstance(obj, (list, tuple)):
        return [_to_json(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (np.ndarray, jax.Array)):
        return _to_json(np.asarray(obj).tolist(), where)
    raise TypeError(f"{where} holds a {type(obj).__name__}, which is not JSON-able")


def _canonical(meta: Mapping[str, Any]) -> bytes:
    return json.dumps(meta, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode("utf-8")


def _content_hash(meta_without_hash: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 over the canonical meta JSON and each array's name, dtype, shape and bytes."""
    h = hashlib.sha256()
    h.update(_canonical(meta_without_hash))
    for name in sorted(arrays):
        a = arrays[name]
        header = json.dumps([name, a.dtype.str, list(a.shape)], separators=(",", ":")).encode("utf-8")
        data = a.tobytes(order="C")
        h.update(len(header).to_bytes(8, "little"))
        h.update(header)
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return h.hexdigest()


# ------------------------------------------------------------------------- leaves
def _leaf_arrays(tree: Any, prefix: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The array leaves of a pytree as named NumPy arrays, plus their description for meta."""
    leaves = jax.tree_util.tree_leaves(tree)
    arrays = {f"{prefix}_{i:03d}": np.asarray(x) for i, x in enumerate(leaves)}
    info = {
        "count": len(leaves),
        "shapes": [list(a.shape) for a in arrays.values()],
        "dtypes": [str(a.dtype) for a in arrays.values()],
    }
    return arrays, info


def _restore_leaves(path: str, arrays: Mapping[str, np.ndarray], prefix: str, template: Any, what: str) -> Any:
    """Put the stored ``prefix_###`` arrays into the structure of ``template``, after checking
    their number, shapes and dtypes. Call under the x64 setting of the stored dtype."""
    t_leaves, treedef = jax.tree_util.tree_flatten(template)
    pattern = re.compile(rf"{re.escape(prefix)}_\d+")
    stored = sorted(k for k in arrays if pattern.fullmatch(k))
    expected = [f"{prefix}_{i:03d}" for i in range(len(t_leaves))]
    if sorted(expected) != stored:
        raise _fail(path, f"leaf mismatch: the file holds {len(stored)} {what} leaves, expected {len(t_leaves)}")
    new = []
    for i, (name, t) in enumerate(zip(expected, t_leaves)):
        a = arrays[name]
        t_shape, t_dtype = tuple(np.shape(t)), np.dtype(jnp.asarray(t).dtype)
        if tuple(a.shape) != t_shape:
            raise _fail(path, f"leaf mismatch: {what} leaf {i} has shape {tuple(a.shape)}, expected {t_shape}")
        if a.dtype != t_dtype:
            raise _fail(path, f"leaf mismatch: {what} leaf {i} has dtype {a.dtype}, expected {t_dtype}")
        new.append(jnp.asarray(a))
    return jax.tree_util.tree_unflatten(treedef, new)


# ------------------------------------------------------------------------ history
def _history_arrays(history: Any) -> tuple[dict[str, np.ndarray], dict[str, Any] | None]:
    if history is None:
        return {}, None
    arrays = {f"history_{f}": np.asarray(getattr(history, f)) for f in _HISTORY_FIELDS}
    info = {"epochs": int(arrays["history_loss"].shape[0]), "gamma_names": list(history.gamma_names)}
    return arrays, info


def _history_from(path: str, meta: Mapping[str, Any], arrays: Mapping[str, np.ndarray]):
    from atlasnn.train import History

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


# -------------------------------------------------------------------------- write
def _config_dict(train_config: Any) -> Any:
    if train_config is None:
        return None
    if dataclasses.is_dataclass(train_config) and not isinstance(train_config, type):
        return dataclasses.asdict(train_config)
    if isinstance(train_config, Mapping):
        return dict(train_config)
    raise TypeError(f"train_config must be a TrainConfig, a dict or None, got {type(train_config).__name__}")


def _build_meta(
    path: str,
    model: TrialSolution,
    system: HamiltonianSystem | None,
    kind: str,
    history: Any,
    train_config: Any,
    extra: Mapping[str, Any] | None,
) -> dict[str, Any]:
    if not isinstance(model, TrialSolution):
        raise _fail(path, f"cannot save a {type(model).__name__}; expected a TrialSolution")
    if system is not None and system.state_dim != model.state_dim:
        raise _fail(
            path,
            f"model state dimension {model.state_dim} does not match system {system.name!r} "
            f"(2d = {system.state_dim})",
        )
    dtype = str(np.dtype(model.z0.dtype))
    if dtype not in _FLOAT_DTYPES:
        raise _fail(path, f"model dtype {dtype} is not one of {list(_FLOAT_DTYPES)}")
    try:
        meta = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "kind": kind,
            "atlasnn_version": __version__,
            "jax_version": jax.__version__,
            "architecture": _to_json(model.architecture(), "architecture"),
            "gamma": _to_json({k: float(v) for k, v in model.scaling.gamma().items()}, "gamma"),
            "z0": _to_json(np.asarray(model.z0, dtype=np.float64), "z0"),
            "t0": float(model.t0),
            "dtype": dtype,
            "system": None if system is None else _to_json(system.describe(), "system"),
            "train_config": _to_json(_config_dict(train_config), "train_config"),
            "extra": _to_json(dict(extra or {}), "extra"),
            # H at four fixed states near z0: lets a loader tell Hamiltonians apart even when
            # they are Python functions (atlasnn.identity)
            "system_probes": None if system is None else _to_json(
                record_probes(system, np.asarray(model.z0, dtype=np.float64)), "system_probes"),
        }
    except (TypeError, ValueError) as exc:
        raise _fail(path, f"cannot save: {exc}") from None
    return meta


def _write_atomic(path: str, arrays: Mapping[str, np.ndarray]) -> None:
    """np.savez through :func:`atlasnn.fileio.write_atomic` (temporary file beside ``path``,
    fsync, rename; the permissions of an ordinary file)."""
    try:
        write_atomic(path, lambda f: np.savez(f, allow_pickle=False, **arrays))
    except OSError as exc:
        raise _fail(path, f"cannot write: {exc.strerror or exc}") from None


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
        model: the trained :class:`~atlasnn.model.TrialSolution` (non-finite values are kept).
        system: its Hamiltonian system (its ``describe()`` is stored; a built-in or expression
            system is rebuilt from it on load, a Python-function system must be passed again).
        history: a :class:`~atlasnn.train.History` to keep, or ``None``.
        train_config: a :class:`~atlasnn.train.TrainConfig` (or a JSON-able dict), or ``None``.
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
    """Save a :class:`~atlasnn.train.TrainState` (model, Adam state, bookkeeping, epoch, history)
    so that ``train(..., resume=load_state(path))`` continues the run exactly; return the hash.

    ``train_config`` must be the run's :class:`~atlasnn.train.TrainConfig`: loading needs it to
    rebuild the structure of the optimizer state.
    """
    from atlasnn.train import TrainConfig

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


# --------------------------------------------------------------------------- read
def _read(path: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """All arrays of the archive (without ``meta``) and the verified meta dict."""
    import zipfile

    try:
        f = open(path, "rb")
    except FileNotFoundError:
        raise _fail(path, "no such file") from None
    except OSError as exc:
        raise _fail(path, f"cannot read: {exc.strerror or exc}") from None
    with f:
        head = f.read(4)
        if not head:
            raise _fail(path, "empty file (not an atlasnn checkpoint)")
        if head[:2] != b"PK":
            raise _fail(path, "not an atlasnn checkpoint (not an .npz archive)")
        f.seek(0)
        arrays: dict[str, np.ndarray] = {}
        try:
            with np.load(f, allow_pickle=False) as npz:
                for name in npz.files:
                    value = npz[name]
                    if not isinstance(value, np.ndarray):
                        raise _fail(path, f"archive member {name!r} is not a NumPy array (foreign file)")
                    if value.dtype.hasobject:
                        raise _fail(path, f"archive member {name!r} is an object array; refused")
                    arrays[name] = value
        except CheckpointError:
            raise
        except zipfile.BadZipFile as exc:
            if "crc" in str(exc).lower():
                raise _fail(path, "content hash mismatch: file altered or corrupt (zip CRC-32 check failed)") from None
            raise _fail(path, f"truncated or corrupt archive ({_describe_exc(exc)})") from None
        except ValueError as exc:
            if "pickle" in str(exc).lower() or "object arrays" in str(exc).lower():
                raise _fail(path, "the archive holds an object array, which would need unpickling; refused") from None
            raise _fail(path, f"truncated or corrupt archive ({_describe_exc(exc)})") from None
        except Exception as exc:  # EOFError, OSError, zlib.error, ...: never a raw traceback
            raise _fail(path, f"truncated or corrupt archive ({_describe_exc(exc)})") from None

    raw = arrays.pop("meta", None)
    if raw is None:
        raise _fail(path, "no meta entry (not an atlasnn checkpoint)")
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise _fail(path, f"meta entry has dtype {raw.dtype} and shape {raw.shape}, expected 1-D uint8")
    try:
        meta = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise _fail(path, f"meta is not valid UTF-8 JSON ({_describe_exc(exc)})") from None
    if not isinstance(meta, dict):
        raise _fail(path, "meta is not a JSON object")
    if meta.get("format") != FORMAT:
        raise _fail(path, f"not an atlasnn checkpoint (format marker {meta.get('format')!r})")
    version = meta.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise _fail(path, f"bad format_version {version!r}")
    if version > FORMAT_VERSION:
        raise _fail(
            path,
            f"written by a newer atlasnn (format version {version}; this atlasnn {__version__} reads "
            f"up to {FORMAT_VERSION}); upgrade atlasnn to load it",
        )
    stored = meta.pop("content_sha256", None)
    if not isinstance(stored, str):
        raise _fail(path, "meta has no content_sha256")
    try:
        actual = _content_hash(meta, arrays)
    except (TypeError, ValueError) as exc:
        raise _fail(path, f"meta cannot be hashed ({_describe_exc(exc)})") from None
    if not hmac.compare_digest(stored.encode("utf-8"), actual.encode("utf-8")):
        raise _fail(path, "content hash mismatch: file altered or corrupt")
    meta["content_sha256"] = stored
    return arrays, meta


def _x64(dtype: str):
    return jax.enable_x64(dtype == "float64")


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
            skeleton = make_model(
                z0,
                scaling=arch["scaling"],
                width=int(arch["width"]),
                depth=int(arch["depth"]),
                t0=float(arch["t0"]),
                activation=arch["activation"],
            )
            return _restore_leaves(path, arrays, "param", skeleton, "model")
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(path, f"cannot rebuild the model from its meta ({_describe_exc(exc)})") from None


def _resolve_system(path: str, meta: Mapping[str, Any], system: HamiltonianSystem | None) -> HamiltonianSystem:
    state_dim = int(meta["architecture"]["state_dim"])
    stored = meta.get("system") if isinstance(meta.get("system"), dict) else None
    if system is not None:
        if not isinstance(system, HamiltonianSystem):
            raise _fail(path, f"system must be a HamiltonianSystem, got {type(system).__name__}")
        if system.state_dim != state_dim:
            raise _fail(
                path,
                f"the given system {system.name!r} has state dimension {system.state_dim}, "
                f"the stored model has {state_dim}",
            )
        if stored is not None:
            why = system_mismatch(stored, system, meta.get("system_probes"))
            if why:
                raise _fail(path, f"not a model of the given system: {why}")
        return system
    spec = stored.get("spec") if stored else None
    if not spec:
        name = stored.get("name") if stored else None
        raise _fail(
            path,
            f"the system{'' if name is None else f' {name!r}'} was defined by a Python function and "
            "cannot be rebuilt from the file; pass system=... when loading",
        )
    try:
        rebuilt = system_from_spec(spec)
    except (AtlasError, KeyError, TypeError, ValueError) as exc:
        raise _fail(path, f"cannot rebuild the stored system ({_describe_exc(exc)}); pass system=...") from None
    if rebuilt.state_dim != state_dim:
        raise _fail(path, f"the stored system has state dimension {rebuilt.state_dim}, the model {state_dim}")
    return rebuilt


@dataclass
class Checkpoint:
    """A loaded checkpoint.

    Attributes:
        model: the restored :class:`~atlasnn.model.TrialSolution` (bit-identical to the saved one).
        system: the system passed to :func:`load_checkpoint`, or the one rebuilt from its spec.
        history: the stored :class:`~atlasnn.train.History`, or ``None``.
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
        """The stored :class:`~atlasnn.train.TrainConfig`, or ``None`` if none was stored."""
        from atlasnn.train import TrainConfig

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
        """The model as a :class:`~atlasnn.solution.Solution` with the stored training interval
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
            at the recorded probe states (see :mod:`atlasnn.identity`, which also says what
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
    """Load a :class:`~atlasnn.train.TrainState` written by :func:`save_state`, to pass as
    ``train(model, system, T, config, resume=...)`` with the same config.

    The optimizer state and bookkeeping are rebuilt without pickle: a template is built from the
    restored model and the stored TrainConfig (``init_opt_state`` and ``_initial_track`` on the
    trainable partition) and the stored leaves are put into its structure, shapes checked.
    ``system``, when given, must be the stored one (as for :func:`load_checkpoint`).
    """
    from atlasnn import train as tr

    p = os.fspath(path)
    arrays, meta = _read(p)
    if meta.get("kind") != KIND_STATE or not isinstance(meta.get("state"), dict):
        raise _fail(p, "holds no training state (written by save_checkpoint, not save_state)")
    model = _rebuild_model(p, meta, arrays)
    if system is not None:
        _resolve_system(p, meta, system)
    try:
        cfg = tr.TrainConfig(**meta["train_config"])
        epoch = meta["state"]["epoch"]
        if isinstance(epoch, bool) or not isinstance(epoch, int) or epoch < 0:
            raise ValueError(f"bad epoch {epoch!r}")
    except (KeyError, TypeError, ValueError, AtlasError) as exc:
        raise _fail(p, f"cannot rebuild the training state from its meta ({_describe_exc(exc)})") from None
    dtype = meta["dtype"]
    with _x64(dtype):
        params, _ = eqx.partition(model, tr.trainable_filter(model, cfg.freeze_gamma))
        opt_template = tr.init_opt_state(params, cfg, model.z0.dtype)
        track_template = tr._initial_track(params, model.z0.dtype)
        opt_state = _restore_leaves(p, arrays, "opt", opt_template, "optimizer state")
        track = _restore_leaves(p, arrays, "track", track_template, "trainer bookkeeping")
    history = _history_from(p, meta, arrays)
    if history is None:
        history = tr.History.empty(tuple(model.scaling.gamma_names))
    return tr.TrainState(model=model, opt_state=opt_state, track=track, epoch=epoch, history=history)


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
    """Save a :class:`~atlasnn.piecewise.PiecewiseSolution` as ONE checkpoint file; return its hash.

    The file has the format of :func:`save_checkpoint` with ``kind = "piecewise"``: the meta
    describes the first window's model (architecture, γ, z0 of the problem), the ``param_###``
    leaves are the window models stacked along a leading window axis, ``piecewise_edges`` holds
    the edges t_0..t_n (float64), ``meta["piecewise"]`` the window records and the scheme's info,
    and with ``histories`` the per-window loss curves (``window_adam_###``, ``window_polish_###``).
    The content hash covers all of it. ``train_config``: a TrainConfig, a MarchConfig's dict, or
    any JSON-able dict.
    """
    from atlasnn.piecewise import PiecewiseSolution, stack_models

    p = os.fspath(path)
    if not isinstance(solution, PiecewiseSolution):
        raise _fail(p, f"save_piecewise needs a PiecewiseSolution, got {type(solution).__name__}")
    models = list(solution.models)
    meta = _build_meta(p, models[0], solution.system, KIND_PIECEWISE, None, train_config, extra)
    arrays, leaf_info = _leaf_arrays(stack_models(models), "param")
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
    meta["content_sha256"] = _content_hash(meta, arrays)
    arrays["meta"] = np.frombuffer(_canonical(meta), dtype=np.uint8)
    _write_atomic(p, arrays)
    return meta["content_sha256"]


def _window_records(path: str, records: Any, arrays: Mapping[str, np.ndarray]) -> list:
    from atlasnn.piecewise import WindowRecord

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
    """Load a :class:`~atlasnn.piecewise.PiecewiseSolution` written by :func:`save_piecewise`.

    The hash is verified, the stacked leaves are checked against a skeleton of the stored
    architecture (number, shapes, dtypes) and split into the window models; the system is
    rebuilt from its spec unless given (as for :func:`load_checkpoint`). The loaded solution
    predicts bit-identically to the saved one. ``meta`` and the path are in its ``info``.
    ``expect`` (keys ``"system"`` and ``"interval"``, as for :func:`load_checkpoint`) refuses a
    solution of another problem with one line naming ``owner``.
    """
    from atlasnn.piecewise import PiecewiseSolution, stack_models, unstack_models

    p = os.fspath(path)
    arrays, meta = _read(p)
    if meta.get("kind") != KIND_PIECEWISE or not isinstance(meta.get("piecewise"), dict):
        raise _fail(p, f"holds no piecewise solution (kind {meta.get('kind')!r}); use load_checkpoint")
    pw = meta["piecewise"]
    n = pw.get("n_windows")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise _fail(p, f"bad piecewise n_windows {n!r}")
    edges = arrays.get("piecewise_edges")
    if edges is None or edges.dtype != np.float64 or edges.shape != (n + 1,) or not np.all(np.diff(edges) > 0):
        raise _fail(p, f"piecewise_edges must be {n + 1} increasing float64 times")
    for key in sorted(set(expect or {}) - {"system", "interval"}):
        raise TypeError(f"expect has unknown key {key!r} (known: interval, system)")
    why = None
    if (expect or {}).get("system") is not None and isinstance(meta.get("system"), dict):
        why = system_mismatch(meta["system"], expect["system"], meta.get("system_probes"))
    if why is None and "interval" in (expect or {}):
        why = interval_mismatch((float(edges[0]), float(edges[-1])), expect["interval"])
    if why:
        raise _fail(p, f"not a model of {owner}: {why}")
    try:
        arch, dtype = meta["architecture"], meta["dtype"]
        if dtype not in _FLOAT_DTYPES:
            raise _fail(p, f"unsupported dtype {dtype!r}")
        with _x64(dtype):
            skeleton = make_model([0.0] * int(arch["state_dim"]), scaling=arch["scaling"], width=int(arch["width"]),
                                  depth=int(arch["depth"]), t0=float(arch["t0"]), activation=arch["activation"])
            stacked = _restore_leaves(p, arrays, "param", stack_models([skeleton] * n), "stacked model")
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

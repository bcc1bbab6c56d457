"""The checkpoint file format: writing and the validated reading of one ``.npz`` archive.

A checkpoint is one ``.npz`` archive (NumPy's zip of ``.npy`` arrays, written by ``np.savez``,
read with ``allow_pickle=False``), so opening one can never execute anything. It holds:

- ``param_000``, ``param_001``, …: the model's array leaves in ``jax.tree_util.tree_flatten``
  order;
- ``history_loss``, ``history_residual``, ``history_energy``, ``history_gamma`` (optional): the
  per-epoch training records;
- for a training state (:func:`~atlasnn.checkpoint._single.save_state`) also ``opt_000``… (Adam's state
  leaves) and ``track_000``… (the trainer's bookkeeping leaves);
- ``meta``: UTF-8 JSON stored as a uint8 array, with the format marker and version, the package
  versions, the model architecture, γ, z0, t0, dtype, the system's description, the training
  config, a free ``extra`` dict, the leaf shapes and dtypes, and ``content_sha256``.

``content_sha256`` is the SHA-256 of the canonical JSON of ``meta`` without that field (sorted
keys, compact separators) followed by every other array's name, dtype, shape and raw bytes in
sorted name order; loading recomputes it, so an altered or damaged file is refused.

Files are written atomically by :func:`atlasnn.fileio.write_atomic`: to a temporary file in the
same directory, flushed and fsynced, then renamed onto the real name, so a crash never leaves a
half-written file under that name; the file gets the permissions an ordinary ``open()`` gives
(0644 under the usual umask 022).

This module holds the pieces every kind of checkpoint shares: the format constants, the strict
JSON of the meta and its content hash, packing array leaves into named arrays and back (checked
against a skeleton), the meta's common fields, the atomic write, the verified read, and the
rebuilding of the stored system. :mod:`atlasnn.checkpoint._single` (models and training states) and
:mod:`atlasnn.checkpoint._piecewise` (time-marching solutions) build on it; it imports neither.

Every problem with a file is raised as a one-line :class:`~atlasnn.errors.CheckpointError` that
names the file.
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import json
import math
import re
from typing import Any, Callable, Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.version import __version__
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.fileio import write_atomic
from atlasnn.checkpoint._identity import record_probes, system_mismatch
from atlasnn.nn import TrialSolution, make_model
from atlasnn.systems import HamiltonianSystem, system_from_spec

FORMAT = "atlasnn-checkpoint"
FORMAT_VERSION = 1

_FLOAT_DTYPES = ("float32", "float64")


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


def model_skeleton(arch: Mapping[str, Any], z0: Any = None, stack: Callable[[list], Any] | None = None) -> Any:
    """The structure, shapes and dtypes of the model ``arch`` describes (``stack`` of n copies
    for a stacked one), without drawing or computing its initial weights: the leaves are
    ``jax.ShapeDtypeStruct``s for :func:`_restore_leaves` to fill. Call under the x64 setting
    of the stored dtype."""
    z0 = [0.0] * int(arch["state_dim"]) if z0 is None else z0

    def build():
        m = make_model(z0, scaling=arch["scaling"], width=int(arch["width"]), depth=int(arch["depth"]),
                       t0=float(arch["t0"]), activation=arch["activation"])
        return m if stack is None else stack(m)

    return eqx.filter_eval_shape(build)


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
        if not hasattr(t, "dtype"):  # a Python number among the leaves
            t = jnp.asarray(t)
        t_shape, t_dtype = tuple(t.shape), np.dtype(t.dtype)
        if tuple(a.shape) != t_shape:
            raise _fail(path, f"leaf mismatch: {what} leaf {i} has shape {tuple(a.shape)}, expected {t_shape}")
        if a.dtype != t_dtype:
            raise _fail(path, f"leaf mismatch: {what} leaf {i} has dtype {a.dtype}, expected {t_dtype}")
        new.append(jax.device_put(a))  # a plain copy: jnp.asarray compiles a program per leaf shape
    return jax.tree_util.tree_unflatten(treedef, new)


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
            # they are Python functions (atlasnn.checkpoint._identity)
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


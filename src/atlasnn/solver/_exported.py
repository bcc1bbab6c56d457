"""The march program kept on disk as an exported program, so that a new process neither traces
nor lowers it again.

JAX's persistent cache (:mod:`atlasnn.compile_cache`) spares a second run the XLA compilation,
but not the tracing and lowering of the Python function, which for the march program is most of
a warm start (measured: 0.38 s of a 0.6 s first solve; ``benchmarks/solver_first_run.py``). Here
the program is exported once (``jax.export``: its StableHLO, for this backend) into
``<cache>/exported/``; a later process deserializes it (milliseconds) and calls it, the compiled
code then coming from the persistent cache.

A stored program is only right for the exact computation it was made from, so its file name is a
hash of everything that computation depends on: the system's definition (only systems defined by
data — a built-in by name and parameters, or an expression — qualify; a Python-function system
is traced as before), the program's settings, the shapes of its arguments, JAX's trace settings,
the versions of atlasnn, JAX and jaxlib, the backend, and the source text of every module of
:mod:`atlasnn.solver` and :mod:`atlasnn.systems`. A file that cannot be read back is replaced.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from pathlib import Path
from typing import Any, Callable

import jax

from atlasnn.compile_cache import cache_dir, code_digest, program_cache
from atlasnn.version import __version__

__all__ = ["exported_program", "EXPORTABLE_SPECS"]

#: system definitions that fix the computation (a Python file's content could change under its name)
EXPORTABLE_SPECS = ("builtin", "expression")


@functools.lru_cache(maxsize=1)
def _source_digest() -> str:
    """A hash of the source of the packages the program is built from, and of the versions."""
    import jaxlib

    return code_digest(("solver", "systems"), f"{__version__} {jax.__version__} {jaxlib.__version__}")


def _flat(jitted: Callable, treedef) -> Callable:
    """``jitted`` as a function of its flattened arguments returning its flattened result (an
    exported program's signature holds arrays only)."""
    return jax.jit(lambda *leaves: jax.tree_util.tree_leaves(jitted(*jax.tree_util.tree_unflatten(treedef, leaves))))


class _Exported:
    """A jitted program served from its exported form on disk, one per argument shapes."""

    def __init__(self, jitted: Callable, key: dict, out_tree, folder: Path):
        self.jitted, self.key, self.out_tree, self.folder = jitted, key, out_tree, folder
        self.loaded: dict[Any, Callable] = {}

    def _path(self, leaves, treedef) -> Path:
        shapes = [[list(x.shape), str(x.dtype)] for x in leaves]
        text = json.dumps({**self.key, "args": shapes, "tree": str(treedef), "source": _source_digest(),
                           "backend": jax.default_backend()}, sort_keys=True, default=str)
        return self.folder / f"march-{hashlib.sha256(text.encode()).hexdigest()[:32]}.bin"

    def _load(self, leaves, treedef) -> Callable:
        path = self._path(leaves, treedef)
        try:
            exp = jax.export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # noqa: BLE001 - none yet, or a damaged or foreign file: made (again) below
            exp = None
        if exp is None:
            exp = jax.export.export(_flat(self.jitted, treedef))(*leaves)
            try:
                blob = exp.serialize()
                self.folder.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".{os.getpid()}.tmp")
                tmp.write_bytes(blob)
                os.replace(tmp, path)  # whole or not at all, for a process reading beside this one
            except (OSError, ImportError):
                pass  # a read-only cache (or no flatbuffers): the program runs, next time traced again
        return jax.jit(exp.call)

    def __call__(self, *args):
        leaves, treedef = jax.tree_util.tree_flatten(args)
        sig = (treedef, tuple((x.shape, str(x.dtype)) for x in leaves))
        fn = self.loaded.get(sig)
        if fn is None:
            fn = self.loaded[sig] = self._load(leaves, treedef)
        return jax.tree_util.tree_unflatten(self.out_tree, fn(*leaves))


@program_cache
@functools.lru_cache(maxsize=32)
def _exported(jitted: Callable, key_text: str, out_tree, folder: str) -> _Exported:
    return _Exported(jitted, json.loads(key_text), out_tree, Path(folder))


def exported_program(jitted: Callable, system: Any, settings: dict, out_tree) -> Callable:
    """``jitted`` served from an exported program on disk where the system qualifies and the
    cache is on (module docstring); else ``jitted`` itself. ``out_tree``: its result's tree."""
    spec = getattr(system, "spec", None)
    folder = cache_dir()
    if folder is None or not isinstance(spec, dict) or spec.get("kind") not in EXPORTABLE_SPECS:
        return jitted
    key = json.dumps({"system": system.describe(), "settings": settings}, sort_keys=True, default=str)
    return _exported(jitted, key, out_tree, str(folder / "exported"))

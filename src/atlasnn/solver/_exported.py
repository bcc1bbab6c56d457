"""The march program kept on disk as an exported program (:func:`atlasnn.compile_cache.compiled_from_disk`),
so that a new process neither traces nor lowers it again.

JAX's persistent cache spares a second run the XLA compilation, but not the tracing and lowering
of the Python function, which for the march program is most of a warm start (measured: 0.38 s of a
0.6 s first solve; ``benchmarks/solver_first_run.py``). The file's name is a hash of everything the
program depends on: the system's definition (only systems defined by data qualify: a Python-function
system is traced as before), the program's settings, its arguments' shapes, JAX's trace settings, the
versions, the backend, and the source of :mod:`atlasnn.solver` and :mod:`atlasnn.systems`.
"""

from __future__ import annotations

import functools
import json
from typing import Any, Callable

import jax

from atlasnn.compile_cache import compile_lowered, compiled_from_disk, packed_program, program_cache
from atlasnn.systems import defined_by_data

__all__ = ["exported_program"]


class _Exported:
    """A jitted program compiled once per argument shapes with XLA's ``options``, served from its
    exported form on disk where ``disk`` (the system qualifies), else traced here."""

    def __init__(self, jitted: Callable, key: dict, out_tree, host: bool, options: dict | None, disk: bool):
        self.jitted, self.key, self.out_tree, self.host = jitted, key, out_tree, host
        self.options, self.disk = options, disk
        self.loaded: dict[Any, Callable] = {}

    def __call__(self, *args):
        leaves, treedef = jax.tree_util.tree_flatten(args)
        sig = (treedef, tuple((x.shape, x.dtype) for x in leaves))
        fn = self.loaded.get(sig)
        if fn is None:
            fn = None if not self.disk else compiled_from_disk(
                self.jitted, args, key=self.key, packages=("solver", "systems"), out_tree=self.out_tree,
                prefix="march", options=self.options, host=self.host)
            if fn is None and self.host:
                fn = self._packed(treedef, leaves)
            if fn is None:
                fn = compile_lowered(self.jitted.lower(*args), self.options) if self.options else self.jitted
            self.loaded[sig] = fn
        return fn(*args)

    def _packed(self, treedef, leaves) -> Callable:
        """The program traced here and compiled as a :func:`packed_program` (its results on the host)."""
        tree = jax.tree_util
        run = packed_program(lambda *xs: tree.tree_leaves(self.jitted(*tree.tree_unflatten(treedef, xs))), leaves,
                             self.options)
        return lambda *xs: tree.tree_unflatten(self.out_tree, run(*tree.tree_leaves(xs)))


@program_cache
@functools.lru_cache(maxsize=32)
def _exported(jitted: Callable, key_text: str, out_tree, host: bool, options_text: str, disk: bool) -> _Exported:
    return _Exported(jitted, json.loads(key_text), out_tree, host, json.loads(options_text), disk)


def exported_program(jitted: Callable, system: Any, settings: dict, out_tree, host: bool = False,
                     options: dict | None = None) -> Callable:
    """``jitted`` compiled with XLA's ``options`` (None: its defaults) and served from an exported
    program on disk where the system qualifies and the cache is on (module docstring); without
    options and off the disk, ``jitted`` itself. ``out_tree``: its result's tree; ``host``: the
    kept program returns NumPy arrays (for a caller that copies them to the host)."""
    disk, described = _system_key(system)
    if not disk and not options:
        return jitted
    key = json.dumps({"system": described, "settings": settings}, sort_keys=True, default=str)
    return _exported(jitted, key, out_tree, host, json.dumps(options), disk)


@functools.lru_cache(maxsize=64)
def _system_key(system: Any) -> tuple[bool, Any]:
    """(whether the system is defined by data, what keys its programs): judged once per system
    object (it rebuilds the system from its spec, which a solve of one window would otherwise pay
    for on every call)."""
    disk = defined_by_data(system)
    return disk, system.describe() if disk else system.name

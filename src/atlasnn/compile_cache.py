"""JAX's persistent compilation cache, on by default: a second run of the same config (same
shapes, system and settings) loads its compiled programs from disk instead of compiling again.

The cache lives in ``$ATLASNN_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/atlasnn/jax`` (default
``~/.cache/atlasnn/jax``). ``ATLASNN_CACHE_DIR=off`` (or ``0``, ``none``, empty) turns it off. A
directory that cannot be created or written is skipped silently (a read-only home must not stop a
run); JAX's own errors while reading or writing an entry are not raised (it compiles instead).
Every program is cached, however quick it was to compile (the training chunks compile in 1–3 s,
the estimate's and the reference's in tens of milliseconds).

Two processes sharing the cache (``--jobs 2``, a benchmark beside a run) must not read an entry
while the other is writing it: without a size limit JAX writes entries without a lock, and reading
a half-written executable crashed the reader (a segmentation fault, seen here twice). A size limit
(:data:`CACHE_MAX_BYTES`) makes JAX take a file lock (the ``filelock`` package) around every read
and write, and evicts the least recently used entries past it.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import math
import os
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["cache_dir", "code_digest", "enable_compile_cache", "CACHE_ENV", "CACHE_MAX_BYTES", "program_cache",
           "clear_programs", "to_host", "jax_time", "JaxTime", "compiled_from_disk", "compile_lowered",
           "packed_program", "EXPORTED_MAX_BYTES"]

CACHE_ENV = "ATLASNN_CACHE_DIR"
#: the cache's size limit (least recently used entries go past it); with it, JAX locks the cache
CACHE_MAX_BYTES = 4 << 30
_OFF = ("", "0", "off", "none", "false")


def code_digest(packages: tuple[str, ...], versions: str) -> str:
    """A hash of ``versions`` (a text naming the library versions that matter) and of the source
    of atlasnn's ``packages`` (e.g. ``("solver", "systems")``): the key part that makes anything
    kept on disk from atlasnn's own code (an exported program, a drawn figure) stale when that
    code changes."""
    h = hashlib.sha256(versions.encode())
    root = Path(__file__).resolve().parent  # the atlasnn package
    for package in packages:
        for path in sorted((root / package).glob("*.py")):
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def cache_dir() -> Path | None:
    """The directory the cache uses, or None when it is off."""
    given = os.environ.get(CACHE_ENV)
    if given is not None:
        return None if given.strip().lower() in _OFF else Path(given).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "atlasnn" / "jax"


def enable_compile_cache() -> Path | None:
    """Point JAX's persistent cache at :func:`cache_dir` (once, at import); returns the directory
    used, or None (off, or not writable)."""
    folder = cache_dir()
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not os.access(folder, os.W_OK):
            return None
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    jax.config.update("jax_raise_persistent_cache_errors", False)
    try:
        import filelock  # noqa: F401  (JAX needs it for the lock that a size limit brings)
    except ImportError:  # pragma: no cover - a dependency; without it the cache stays unlocked
        return folder
    jax.config.update("jax_compilation_cache_max_size", CACHE_MAX_BYTES)
    return folder


# ---------------------------------------------------------------- compiled programs in memory
#: every in-memory cache of compiled programs atlasnn keeps (dicts, or functions wrapped by
#: functools.lru_cache): what :func:`clear_programs` empties
_PROGRAM_CACHES: list = []


def program_cache(cache):
    """Register an in-memory cache of compiled programs (a dict, or a function wrapped by
    ``functools.lru_cache``) so that :func:`clear_programs` can empty it; returns it unchanged."""
    _PROGRAM_CACHES.append(cache)
    return cache


def clear_programs() -> None:
    """Drop every compiled program this process holds (atlasnn's caches and JAX's own): each
    program keeps its machine code mapped in memory, and a process that compiles thousands of them
    (a long session, a test suite) can run out of memory maps (Linux's vm.max_map_count, 65 530
    by default) and crash inside XLA. The persistent cache on disk is kept, so what is needed again
    loads from there."""
    for cache in _PROGRAM_CACHES:
        if isinstance(cache, dict):
            cache.clear()
        else:
            cache.cache_clear()
    jax.clear_caches()


# ----------------------------------------------------------------- JAX's own time
_TRACE = "/jax/core/compile/jaxpr_trace_duration"
_LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
_BACKEND = "/jax/core/compile/backend_compile_duration"
_HITS = "/jax/compilation_cache/cache_hits"
_ACTIVE: list["JaxTime"] = []  # the collectors open now (the listeners feed each)
_LISTENING = False


class JaxTime:
    """Seconds JAX spent in this process while it was open (:func:`jax_time`): tracing, lowering,
    and compiling or loading from the persistent cache, with the count of programs and of cache hits."""

    def __init__(self) -> None:
        self.trace = self.lower = self.compile = 0.0
        self.programs = self.cache_hits = 0

    def _duration(self, event: str, seconds: float) -> None:
        if event == _TRACE:
            self.trace += seconds
        elif event == _LOWER:
            self.lower += seconds
        elif event == _BACKEND:
            self.compile += seconds
            self.programs += 1

    def summary(self) -> dict:
        return {"trace_seconds": self.trace, "lower_seconds": self.lower, "compile_or_load_seconds": self.compile,
                "programs": self.programs, "cache_hits": self.cache_hits}

    def line(self) -> str:
        return (f"JAX in this process: tracing {self.trace:.1f} s, lowering {self.lower:.1f} s, compiling or loading "
                f"{self.compile:.1f} s ({self.programs} programs, {self.cache_hits} from the cache)")


def _on_duration(event: str, seconds: float, **_kw) -> None:
    for collector in _ACTIVE:
        collector._duration(event, seconds)


def _on_event(event: str, **_kw) -> None:
    if event == _HITS:
        for collector in _ACTIVE:
            collector.cache_hits += 1


@contextlib.contextmanager
def jax_time():
    """``with jax_time() as t:`` — ``t`` (a :class:`JaxTime`) sums JAX's monitoring events inside
    (JAX reports them per process: work in other processes is not counted)."""
    global _LISTENING
    if not _LISTENING:  # JAX keeps listeners for the life of the process: registered once
        jax.monitoring.register_event_duration_secs_listener(_on_duration)
        jax.monitoring.register_event_listener(_on_event)
        _LISTENING = True
    collector = JaxTime()
    _ACTIVE.append(collector)
    try:
        yield collector
    finally:
        _ACTIVE.remove(collector)


# ------------------------------------------------------------ programs kept on disk (jax.export)
# JAX's persistent cache spares a second run the XLA compilation, not the tracing and lowering of
# the Python function, which is most of a warm start for atlasnn's large programs (the Adam chunk,
# the Levenberg–Marquardt loop, the solver's march). Such a program is exported once (jax.export: its
# StableHLO, for this backend) into <cache>/exported/; a later process deserializes it
# (milliseconds), and the compiled code comes from the persistent cache. A stored program is right
# only for the exact computation it was made from, so its file name is a hash of everything the
# trace depends on: the system's definition (only systems defined by data qualify: the caller
# decides, atlasnn.systems.defined_by_data), the program's own settings (the caller's ``key``), the structure, shapes and
# dtypes of its arguments, JAX's settings that change a trace, the versions of JAX, jaxlib, Equinox
# and Optax, the backend, and the source text of atlasnn's top-level modules (its version among them)
# and of every module of the packages the program is built from. A file that cannot be read back is
# made again, as is one that reads back but does not compile for these arguments; a program that
# cannot be exported is traced as usual. The folder is kept under EXPORTED_MAX_BYTES.

_TRACE_FLAGS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_threefry_partitionable",
                "jax_default_prng_impl", "jax_numpy_dtype_promotion", "jax_numpy_rank_promotion")


@functools.lru_cache(maxsize=8)
def _source_digest(packages: tuple[str, ...]) -> str:
    import equinox
    import jaxlib
    import optax

    root = Path(__file__).resolve().parent  # atlasnn's version and its top-level modules (precision, ...)
    top = b"".join(path.read_bytes() for path in sorted(root.glob("*.py")))
    return code_digest(packages, f"{hashlib.sha256(top).hexdigest()} jax {jax.__version__} "
                                 f"jaxlib {jaxlib.__version__} equinox {equinox.__version__} optax {optax.__version__}")


def _trace_flags() -> dict[str, str]:
    """JAX's settings that change a trace, as they are now (``jax.config.read`` refuses the ones
    that have a context manager, so they are read as attributes; one this JAX lacks reads "absent")."""
    return {name: str(getattr(jax.config, name, "absent")) for name in _TRACE_FLAGS}


def _kept_path(prefix: str, key: dict, packages: tuple[str, ...], leaves, treedef) -> Path:
    text = json.dumps({**key, "args": [[list(x.shape), str(x.dtype)] for x in leaves], "tree": str(treedef),
                       "source": _source_digest(packages), "flags": _trace_flags(), "backend": jax.default_backend()},
                      sort_keys=True, default=str)
    return cache_dir() / "exported" / f"{prefix}-{hashlib.sha256(text.encode()).hexdigest()[:32]}.bin"


def _export(fn: Callable, leaves, treedef, out_tree, path: Path):
    """``fn`` exported as a function of the flat arguments returning its flat result, and kept at
    ``path``; None when it cannot be exported or its result's structure is not ``out_tree``."""
    seen = []

    def flat(*xs):
        out = jax.tree_util.tree_flatten(fn(*jax.tree_util.tree_unflatten(treedef, xs)))
        seen.append(out[1])
        return out[0]

    try:
        exp = jax.export.export(jax.jit(flat))(*leaves)
    except Exception:  # noqa: BLE001 - an operation export does not take: the caller traces as usual
        return None
    if seen[-1] != out_tree:  # the caller's out_tree would put the results in the wrong places
        return None
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(exp.serialize())
        os.replace(tmp, path)  # whole or not at all, for a process reading beside this one
    except (OSError, ImportError):  # a read-only or full cache (or no flatbuffers): the program
        with contextlib.suppress(OSError):  # runs, and is traced again next time
            tmp.unlink(missing_ok=True)
        return exp
    _prune_kept(path.parent)
    return exp


#: the size limit of ``<cache>/exported/``: past it, the files read least recently go (a program
#: file is 20–200 kB; a test suite's run leaves a few hundred)
EXPORTED_MAX_BYTES = 256 << 20


def _prune_kept(folder: Path) -> None:
    """Delete the kept programs read least recently (their access time, which a read sets) until
    ``folder`` holds at most :data:`EXPORTED_MAX_BYTES`."""
    try:
        files = [(st.st_atime_ns, st.st_size, f) for f in folder.glob("*.bin") for st in [f.stat()]]
    except OSError:  # a file removed by another process while listing: next time
        return
    total = sum(size for _, size, _ in files)
    for _, size, f in sorted(files, key=lambda row: row[0]):
        if total <= EXPORTED_MAX_BYTES:
            break
        with contextlib.suppress(OSError):
            f.unlink()
        total -= size


def _mark_read(path: Path) -> None:
    """Set ``path``'s access time to now, its modification time unchanged (the order in which
    :func:`_prune_kept` deletes; a file system mounted noatime does not set it on a read)."""
    with contextlib.suppress(OSError):
        os.utime(path, ns=(time.time_ns(), path.stat().st_mtime_ns))


def compiled_from_disk(fn: Callable, args: tuple, *, key: dict, packages: tuple[str, ...], out_tree,
                       prefix: str, options: dict | None = None, host: bool = False) -> Callable | None:
    """``fn`` compiled for ``args`` (their structure, shapes and dtypes) from its exported form on
    disk: read back, or exported now and kept; a function of the same arguments returning ``fn``'s
    result (whose tree the caller gives: ``out_tree``). None when the cache is off or the program
    cannot be exported: the caller traces ``fn`` as usual. ``key``: what else the trace depends on
    (the system's definition, the program's settings); ``packages``: atlasnn's packages its code
    comes from (``("training", "nn", "systems")``); ``options``: XLA's options for compiling it
    (:func:`compile_lowered`); ``host``: the results as NumPy arrays (for a caller that copies them
    to the host anyway: no device copies of its own)."""
    if cache_dir() is None:
        return None
    leaves, treedef = jax.tree_util.tree_flatten(args)
    path = _kept_path(prefix, key, packages, leaves, treedef)

    def build(exp):
        if host:
            return packed_program(exp.call, leaves, options, exp.out_avals)
        return compile_lowered(jax.jit(exp.call).lower(*leaves), options)

    program = None
    try:
        exp = jax.export.deserialize(bytearray(path.read_bytes()))
        program = build(exp)
        _mark_read(path)
    except Exception:  # noqa: BLE001 - none yet, or a damaged or foreign file, or one that does
        exp = _export(fn, leaves, treedef, out_tree, path)  # not fit these arguments: made again
    if exp is None:
        return None
    if program is None:
        try:
            program = build(exp)
        except Exception:  # noqa: BLE001 - exported, but not compilable: traced as usual
            return None

    def run(*call_args):
        out = program(*jax.tree_util.tree_leaves(call_args))
        return jax.tree_util.tree_unflatten(out_tree, out if host else [_uncommitted(x) for x in out])

    return run


#: an array of more entries than this crosses a packed call as itself, not copied into a pack
PACK_MAX_SIZE = 1024


class _Packing:
    """Where each array of a list sits in a few flat arrays: the small ones packed into one per
    dtype, each large one flat on its own. A compiled call's fixed cost grows with its count of
    arguments and results (on a CPU, measured: 18 small arguments and 21 small results 250 µs a
    call, 3 and 3 35 µs), and the Gauss march's chunk has 18 and 21; a large array (the chunk's
    stage increments) would cost a copy in a pack and saves nothing there."""

    def __init__(self, avals):
        self.shapes = [tuple(a.shape) for a in avals]
        dtypes = [np.dtype(a.dtype) for a in avals]
        sizes = [math.prod(shape) for shape in self.shapes]
        self.kinds = sorted({d for d, n in zip(dtypes, sizes) if n <= PACK_MAX_SIZE}, key=str)  # each flat's dtype
        ends = [0] * len(self.kinds)
        self.where = []  # (flat, start, stop) of each array
        for dtype, size in zip(dtypes, sizes):
            if size <= PACK_MAX_SIZE:
                k = self.kinds.index(dtype)
                self.where.append((k, ends[k], ends[k] + size))
                ends[k] += size
            else:
                self.kinds.append(dtype)
                self.where.append((len(self.kinds) - 1, 0, size))

    def pack(self, arrays, xp=np) -> list:
        parts = [[] for _ in self.kinds]
        for x, (kind, _, _) in zip(arrays, self.where):
            parts[kind].append(xp.ravel(xp.asarray(x, self.kinds[kind])))
        return [p[0] if len(p) == 1 else xp.concatenate(p) for p in parts]

    def unpack(self, flats) -> list:
        return [flats[kind][a:b].reshape(shape) for (kind, a, b), shape in zip(self.where, self.shapes)]


def packed_program(call: Callable, leaves: list, options: dict | None = None, out_avals=None) -> Callable:
    """``call`` (flat arrays in, a flat list of arrays out) compiled for ``leaves`` so that its
    small arguments and results cross the call as one flat array per dtype (:class:`_Packing`); returns
    ``run(*leaves) -> list`` of NumPy arrays (views of the packed results). ``out_avals``: the
    results' shapes and dtypes where known (an exported program's), else read while tracing."""
    ins, outs = _Packing(leaves), [] if out_avals is None else [_Packing(out_avals)]

    def inner(*flats):
        out = list(call(*ins.unpack(flats)))
        if not outs:
            outs.append(_Packing(out))
        return tuple(outs[0].pack(out, jnp))

    program = compile_lowered(jax.jit(inner).lower(*ins.pack(leaves)), options)

    def run(*arrays):
        return outs[0].unpack([np.asarray(x) for x in program(*ins.pack(arrays))])

    return run


def to_host(tree):
    """Every array of ``tree`` as a NumPy array (read-only where it is a view of a device buffer).
    ``np.asarray`` per leaf rather than ``jax.device_get``: on a CPU the same arrays, about 40 µs
    less per array (a march's chunk has 21: measured 0.95 → 0.28 ms)."""
    return jax.tree_util.tree_map(np.asarray, tree)


def cpu_loop_options() -> dict | None:
    """XLA's options for atlasnn's large looping programs (the training programs, the Gauss march):
    on a CPU its loop emitters instead of its newer fusion emitters, which compile these programs in
    50–80 % of the time and run them about as fast (the Gauss march: 1.68 → 0.85 s to compile, 0.87
    → 0.95 ms a solve of Hénon–Heiles [0, 24π] on one core); results differ in their last bits, as
    they do between machines. Elsewhere (a GPU): None, XLA's defaults."""
    return {"xla_cpu_use_fusion_emitters": False} if jax.default_backend() == "cpu" else None


def compile_lowered(lowered, options: dict | None = None):
    """``lowered.compile()`` with XLA's ``options`` (debug options such as
    ``{"xla_cpu_use_fusion_emitters": False}``; they are part of the persistent cache's key); an
    option this XLA does not know is dropped rather than failing the run."""
    if options:
        try:
            return lowered.compile(compiler_options=options)
        except Exception:  # noqa: BLE001 - an option this jaxlib lacks (or refuses): its defaults
            pass
    return lowered.compile()


def _uncommitted(x: jax.Array) -> jax.Array:
    """``x`` as a jitted program would have returned it: an exported program's results are committed
    to its device, and a committed argument makes every jitted function it reaches compile a program
    of its own for it (measured: the march's end-state program compiled twice). Copied through the
    host (its values exactly) where it is not weakly typed (a copy would drop that)."""
    import numpy as np

    return x if x.weak_type or not x.committed else jax.device_put(np.asarray(x))


"""Writing files atomically, with the permissions an ordinary ``open()`` would give them.

:func:`write_atomic` is the one writer every result file goes through: the content is written
to a temporary file beside the target (same directory, so the same file system), flushed and
fsynced, then renamed onto the target with ``os.replace`` (atomic on POSIX: a reader sees the old
file or the new one, never half of one), and the directory is fsynced (best effort) so that the
rename survives a crash. On any failure (an ``OSError`` such as a full disk, an exception of the
caller's ``write``, Ctrl-C) the temporary file is removed and the target is untouched.

Permissions. ``tempfile.mkstemp`` creates files as 0600 whatever the umask, which made results
owner-only while the tables beside them were 0644. Here the temporary file is created with
``os.open(..., O_CREAT | O_EXCL, 0o666)``, so the kernel applies the umask (and a directory's
default ACL) exactly as for ``open(path, "w")``: 0644 under umask 022, 0600 under 077. When the
target already exists its permission bits are kept, as ``open()`` keeps them when it truncates.
No umask is read or changed (``os.umask`` can only be read by setting it, which races with
other threads); :func:`current_umask` reads it from ``/proc/self/status`` for callers that want
to know it.

A failure is raised as an ``OSError`` (the matching subclass, e.g. ``PermissionError``) whose
``filename`` is the target path, so that ``f"{exc.filename}: {exc.strerror}"`` is a complete
one-line message.

:func:`write_json` and :func:`write_npz` are the run directory's writers (``indent=1``, NumPy
scalars and arrays converted, NaN and infinities written as the non-standard ``NaN`` and
``Infinity`` that Python's ``json`` reads back).

:func:`parse_toml` is the one reader of TOML text: a syntax error, or nesting deeper than
``MAX_TOML_DEPTH`` (``tomllib`` recurses and would otherwise end in a ``RecursionError``
traceback), is one ``ConfigError`` line naming the file.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path
from typing import IO, Any, Callable, Mapping

import numpy as np

from atlasnn.errors import ConfigError

__all__ = ["parse_toml", "MAX_TOML_DEPTH", "write_atomic", "write_bytes", "write_text", "write_json", "write_npz", "json_default",
           "current_umask"]

_NEW_FILE_MODE = 0o666  # what open(path, "w") asks for; the umask takes its bits away


def current_umask() -> int | None:
    """The process umask from ``/proc/self/status`` (Linux ≥ 4.7), without changing it; None
    where that is not available."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return None


def _with_path(exc: OSError, path: Path) -> OSError:
    """The same error (same errno, hence the same subclass) naming the target path."""
    if exc.errno is None:
        return exc
    return OSError(exc.errno, exc.strerror or os.strerror(exc.errno), str(path))


def _create_temp(directory: Path, name: str) -> tuple[int, Path]:
    for _ in range(100):
        tmp = directory / f".{name}.{secrets.token_hex(6)}.tmp"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), _NEW_FILE_MODE)
        except FileExistsError:
            continue
        return fd, tmp
    raise FileExistsError(17, "cannot find a free temporary file name", str(directory))


def _fsync_directory(directory: Path) -> None:
    # makes the rename durable; not possible on every platform or file system, hence best effort
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_atomic(path: str | os.PathLike, write: Callable[[IO[bytes]], Any]) -> None:
    """Call ``write(f)`` on a new binary file and put it at ``path`` atomically.

    The rule (see the module docstring): temporary file beside ``path`` with the permissions
    ``open()`` would give, ``write``, flush, fsync, ``os.replace`` onto ``path``, fsync of the
    directory; on any failure the temporary file is removed and ``path`` is left as it was.

    Raises:
        OSError: naming ``path`` (``exc.filename``) and the cause (``exc.strerror``).
    """
    path = Path(os.fspath(path))
    directory = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = _create_temp(directory, path.name)
    except OSError as exc:
        raise _with_path(exc, path) from None
    try:
        with os.fdopen(fd, "wb") as f:
            try:
                mode = os.stat(path).st_mode & 0o7777  # an existing file keeps its permissions
            except OSError:
                mode = None
            if mode is not None:
                os.fchmod(f.fileno(), mode)
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise _with_path(exc, path) from None
        raise
    _fsync_directory(directory)


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`write_atomic`)."""
    write_atomic(path, lambda f: f.write(data))


def write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (see :func:`write_atomic`)."""
    write_bytes(path, text.encode(encoding))


def json_default(obj: Any) -> Any:
    """JSON for NumPy values: scalars as Python numbers/bools, arrays as (nested) lists."""
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def write_json(path: str | os.PathLike, data: Any) -> None:
    """``data`` as JSON (indent 1; NumPy values converted; NaN/inf allowed), atomically."""
    text = json.dumps(data, indent=1, default=json_default, allow_nan=True)
    write_bytes(path, text.encode("utf-8"))


def write_npz(path: str | os.PathLike, arrays: Mapping[str, np.ndarray]) -> None:
    """``np.savez`` of ``arrays`` (no object arrays: they would need pickle), atomically."""
    write_atomic(path, lambda f: np.savez(f, allow_pickle=False, **arrays))


MAX_TOML_DEPTH = 32  # tables and arrays inside one another; the deepest config atlasnn reads has 4


def _depth(value: Any) -> int:
    if isinstance(value, dict):
        return 1 + max((_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_depth(v) for v in value), default=0)
    return 0


def _bracket_depth(text: str) -> int:
    """The deepest nesting of [ and { outside strings and comments: a cheap check made before
    parsing, so that a hostile file never reaches tomllib's recursion."""
    deepest = depth = 0
    quote = None
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if quote:
            if c == "\\" and quote == '"':
                i += 1
            elif c == quote:
                quote = None
        elif c in "\"'":
            quote = c
        elif c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth = max(depth - 1, 0)
        i += 1
    return deepest


def parse_toml(text: str, source: str = "config") -> dict[str, Any]:
    """``tomllib.loads`` with one-line errors naming ``source``, and a nesting limit."""
    import tomllib

    if _bracket_depth(text) > MAX_TOML_DEPTH:
        raise ConfigError(f"{source}: nested more than {MAX_TOML_DEPTH} levels deep (arrays and inline "
                          f"tables inside one another); flatten it")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{source}: nested more than {MAX_TOML_DEPTH} levels deep; flatten it") from None
    if _depth(data) > MAX_TOML_DEPTH:
        raise ConfigError(f"{source}: nested more than {MAX_TOML_DEPTH} levels deep; flatten it")
    return data

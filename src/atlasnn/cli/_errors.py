"""How ``atlasnn`` guards a command and reports its failure (used by :func:`atlasnn.cli._main.main`).

Before the command: :func:`_check_out` refuses an ``--out`` that cannot be created or written.
During it: :func:`_raise_interrupt` turns SIGTERM into the KeyboardInterrupt that saves the
training state. After a failure: :class:`_RunWatch` tells whether the run had started (exit
status 1: its finished work is on disk) or not (2), :func:`_os_error_line` words a file-system
error as one line naming the path(s), and :func:`_resume_command` is the command printed after
an interrupt.
"""

from __future__ import annotations

import shlex
import time
from pathlib import Path

from atlasnn.errors import AtlasError


def _resume_command(args, run_dir) -> str:
    parts = ["atlasnn", args.command]
    positional = getattr(args, "name", None) or getattr(args, "config", None)
    if positional:
        parts.append(positional)
    parts += ["--resume", str(run_dir)]
    if getattr(args, "jobs", 1) != 1:
        parts += ["--jobs", str(args.jobs)]
    if getattr(args, "scheduler", None):
        parts += ["--scheduler", args.scheduler]
    if getattr(args, "no_progress", False):
        parts.append("--no-progress")
    return " ".join(shlex.quote(p) for p in parts)


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def _os_error_line(exc: OSError, run_dir) -> str:
    """One line naming the path(s) and the cause (strerror) of a file-system error."""
    cause = exc.strerror or " ".join(str(exc).split()) or type(exc).__name__
    if exc.filename is not None and exc.filename2 is not None:
        return f"cannot move {exc.filename} to {exc.filename2}: {cause}"
    if exc.filename is not None:
        return f"{exc.filename}: {cause}"
    return f"{cause} (writing in {run_dir})" if run_dir is not None else cause


def _check_out(args) -> None:
    """Refuse an ``--out`` that cannot be created or written, before anything is computed: the first
    existing ancestor must be a directory we may write into (root is not checked for permissions
    by the kernel, but a read-only file system still says so through access(2))."""
    import os

    out = getattr(args, "out", None)
    if out is None or getattr(args, "resume", None) is not None:
        return
    path = Path(out).absolute()
    existing = path
    while not os.path.exists(existing) and existing != existing.parent:  # False also when not searchable
        if os.path.islink(existing):  # a dangling link: let the runner report it
            return
        existing = existing.parent
    target = existing if existing == path else f"{existing} (where --out {out} would be created)"
    if not existing.is_dir():
        raise AtlasError(f"--out {out}: {existing} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        import errno

        try:
            read_only = bool(os.statvfs(existing).f_flag & os.ST_RDONLY)
        except OSError:
            read_only = False
        cause = os.strerror(errno.EROFS) if read_only else os.strerror(errno.EACCES)
        raise AtlasError(f"--out {out}: cannot write in {target}: {cause}")


def _meta_stamp(run_dir) -> tuple | None:
    """(inode, mtime) of ``run_dir/meta.json``, or None."""
    if run_dir is None:
        return None
    try:
        st = (Path(run_dir) / "meta.json").stat()
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns


class _RunWatch:
    """Tells, after a failure, whether the command's run had started: its run directory's
    ``meta.json`` (written by the runner just before training) was written during this command.
    The stamps of ``--out``/``--resume`` are taken up front; a default ``runs/NAME`` is judged by
    the file's mtime against the command's start."""

    def __init__(self, args):
        self.args = args
        self.start_ns = time.time_ns()
        self.before = {str(Path(v)): _meta_stamp(v) for v in (getattr(args, "out", None),
                                                               getattr(args, "resume", None)) if v is not None}

    def status(self) -> int:
        """1 when the run failed mid-run (its finished work is on disk), else 2."""
        run_dir = getattr(self.args, "run_dir", None)
        now = _meta_stamp(run_dir)
        if now is None:
            return 2
        key = str(Path(run_dir))
        started = now != self.before[key] if key in self.before else now[1] >= self.start_ns
        return 1 if started else 2



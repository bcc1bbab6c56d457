"""Signals while a run is active: SIGINT and SIGTERM stop it at a safe point.

While a run is active (:class:`SignalGuard`), SIGINT and SIGTERM raise KeyboardInterrupt,
except that while a task trains in this process the first signal only marks the run as to be
stopped; it is acted on at the next safe point (the end of a chunk of epochs, or of a task), where
the training state is consistent (:func:`check_interrupt`). A second signal stops at once. Worker
processes ignore SIGINT (the parent decides) and are stopped by the parent; a Dask task polls its
coordinator's stop event at the same safe points.
"""

from __future__ import annotations

import signal
import sys
import threading
from typing import Any

__all__ = ["SignalGuard", "NoGuard", "check_interrupt", "deferring_signals", "set_remote_stop"]


class SignalGuard:
    """See the module docstring. Handlers are only touched in the main thread, a signal that is
    ignored (SIG_IGN) stays ignored, and the old handlers come back on exit."""

    def __init__(self) -> None:
        self.pending: str | None = None
        self.deferring = False
        self._old: dict[int, Any] = {}
        self._prev: SignalGuard | None = None

    def __enter__(self) -> "SignalGuard":
        global _GUARD
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old = signal.getsignal(sig)
                if old is signal.SIG_IGN or old is None:
                    continue
                self._old[sig] = old
                signal.signal(sig, self._handle)
        self._prev, _GUARD = _GUARD, self
        return self

    def __exit__(self, *exc) -> bool:
        global _GUARD
        for sig, old in self._old.items():
            signal.signal(sig, old)
        _GUARD = self._prev
        return False

    def _handle(self, signum, frame) -> None:
        name = signal.Signals(signum).name
        if self.deferring and self.pending is None:
            self.pending = name
            print(f"atlasnn: {name} received; stopping at the end of the current chunk of epochs and saving "
                  "the training state (send it again to stop at once)", file=sys.stderr, flush=True)
            return
        self.pending = self.pending or name
        raise KeyboardInterrupt


class NoGuard:
    """A stand-in for :class:`SignalGuard` when signals are left alone."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


_GUARD: SignalGuard | None = None


#: per thread: a function that says whether the coordinator of a Dask run asked its tasks to stop
_REMOTE = threading.local()


def check_interrupt() -> None:
    """Act on a deferred SIGINT/SIGTERM, or on a Dask coordinator's stop (call at a safe point)."""
    if _GUARD is not None and _GUARD.pending is not None:
        raise KeyboardInterrupt
    stop = getattr(_REMOTE, "stop", None)
    if stop is not None and stop():
        raise KeyboardInterrupt


def deferring_signals(flag: bool) -> None:
    """While true, a first signal only marks the run as to be stopped at the next safe point."""
    if _GUARD is not None:
        _GUARD.deferring = flag


def set_remote_stop(stop: Any) -> None:
    """This thread's task polls ``stop()`` (a Dask coordinator's stop event) at its safe points;
    None ends that."""
    _REMOTE.stop = stop

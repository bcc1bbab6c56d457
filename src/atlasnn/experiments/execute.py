"""Executing the tasks of a run: in this process, in local worker processes, or on Dask.

An executor takes the tasks still to do and a picklable function ``work(task) → output`` (the
training of one task, :func:`atlasnn.experiments.training.run_training` with the run's arguments
bound) and calls ``on_done(task, output)`` in the calling process as each task finishes. Finished
work is on disk before ``on_done`` is called, so whatever stops a run loses at most the unfinished
tasks' progress since their last saved state.

Signals. While a run is active (:class:`SignalGuard`), SIGINT and SIGTERM raise KeyboardInterrupt,
except that while a task trains in this process the first signal only marks the run as to be
stopped; it is acted on at the next safe point (the end of a chunk of epochs, or of a task), where
the training state is consistent. A second signal stops at once. Worker processes ignore SIGINT
(the parent decides) and are stopped by the parent.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
import sys
import threading
from typing import Any, Callable, Sequence

from atlasnn.experiments.plan import Task

Work = Callable[[Task], Any]
OnDone = Callable[[Task, Any], None]


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


def check_interrupt() -> None:
    """Act on a deferred SIGINT/SIGTERM (call at a safe point)."""
    if _GUARD is not None and _GUARD.pending is not None:
        raise KeyboardInterrupt


def _set_deferring(flag: bool) -> None:
    if _GUARD is not None:
        _GUARD.deferring = flag


# ------------------------------------------------------------------------ executors
def run_here(tasks: Sequence[Task], work: Work, on_done: OnDone) -> None:
    """One task after the other in this process (signals deferred while a task trains)."""
    for task in tasks:
        _set_deferring(True)
        try:
            output = work(task)
        finally:
            _set_deferring(False)
        on_done(task, output)
        check_interrupt()


def _worker_init() -> None:
    # Ctrl-C in a terminal reaches the whole process group: the parent process decides (it
    # stops the workers); a worker must not die with a traceback of its own
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")


def _stop_workers(pool: cf.ProcessPoolExecutor) -> None:
    """Terminate the worker processes of ``pool`` now (finished tasks are already on disk)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    for p in procs:
        try:
            p.terminate()
        except Exception:  # already gone
            pass
    for p in procs:
        try:
            p.join(timeout=10)
        except Exception:
            pass


def run_processes(tasks: Sequence[Task], work: Work, on_done: OnDone, jobs: int) -> None:
    """Tasks in ``jobs`` local worker processes (spawned: a fresh JAX in each)."""
    ctx = multiprocessing.get_context("spawn")
    pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init)
    futures: dict[Any, Task] = {}
    try:
        for task in tasks:
            futures[pool.submit(work, task)] = task
        for fut in cf.as_completed(futures):
            on_done(futures[fut], fut.result())
    except BaseException:
        for fut in futures:
            fut.cancel()
        _stop_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def run_local(tasks: Sequence[Task], work: Work, on_done: OnDone, jobs: int = 1) -> None:
    """In this process when ``jobs`` is 1 or one task is left, else in worker processes."""
    if jobs == 1 or len(tasks) <= 1:
        run_here(tasks, work, on_done)
    else:
        run_processes(tasks, work, on_done, jobs)

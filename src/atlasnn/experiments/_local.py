"""The local executor: this process (one job, or one task left), else ``jobs`` spawned worker
processes, each with a fresh JAX. Signals are deferred while a task trains in this process."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
from typing import Any, Sequence, final

from atlasnn.errors import ConfigError
from atlasnn.experiments._executor import Executor, OnDone, Work
from atlasnn.experiments._signals import check_interrupt, deferring_signals
from atlasnn.experiments._tasks import Task

__all__ = ["LocalExecutor"]


def _run_here(tasks: Sequence[Task], work: Work, on_done: OnDone) -> None:
    """One task after the other in this process (signals deferred while a task trains)."""
    for task in tasks:
        deferring_signals(True)
        try:
            output = work(task)
        finally:
            deferring_signals(False)
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


#: XLA flags of a worker process: one core each (XLA's own thread pool, set to every core, fights
#: the other workers for them: measured, a float64 Cholesky of 300 rows took 0.6 ms alone and
#: 0.3–0.5 s while another process kept a core busy; see docs/PERFORMANCE.md)
WORKER_XLA_FLAGS = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def _run_processes(tasks: Sequence[Task], work: Work, on_done: OnDone, jobs: int) -> None:
    """Tasks in ``jobs`` local worker processes (spawned: a fresh JAX in each, one thread each)."""
    ctx = multiprocessing.get_context("spawn")
    before = os.environ.get("XLA_FLAGS")
    os.environ["XLA_FLAGS"] = f"{before or ''} {WORKER_XLA_FLAGS}".strip()  # the workers inherit it
    try:
        pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init)
        for _ in range(jobs):  # start them now, while the environment says so
            pool.submit(int)
    finally:
        if before is None:
            os.environ.pop("XLA_FLAGS", None)
        else:
            os.environ["XLA_FLAGS"] = before
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


def _run_local(tasks: Sequence[Task], work: Work, on_done: OnDone, jobs: int = 1) -> None:
    """In this process when ``jobs`` is 1 or one task is left, else in worker processes."""
    if jobs == 1 or len(tasks) <= 1:
        _run_here(tasks, work, on_done)
    else:
        _run_processes(tasks, work, on_done, jobs)


@final
class LocalExecutor(Executor):
    """This process when ``jobs`` is 1 or one task is left, else ``jobs`` worker processes."""

    name = "local"

    def __init__(self, jobs: int = 1):
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise ConfigError(f"jobs must be an integer >= 1, got {jobs!r}")
        self.jobs = jobs
        self.shows_progress = jobs == 1

    def slots(self) -> int:
        return self.jobs

    def run(self, tasks, work, on_done, *, shared_dir=None) -> None:
        _run_local(tasks, work, on_done, self.jobs)

    def describe(self) -> str:
        return f"jobs={self.jobs}"

    def record(self) -> dict[str, Any]:
        return {"jobs": self.jobs, "scheduler": None, "xla_flags": os.environ.get("XLA_FLAGS") or None,
                "worker_xla_flags": WORKER_XLA_FLAGS if self.jobs > 1 else None}

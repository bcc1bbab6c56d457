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


#: XLA flags of a worker process: Eigen's thread pool off (set to every core, it fights the other
#: workers for them: measured, a float64 Cholesky of 300 rows took 0.6 ms alone and 0.3–0.5 s
#: while another process kept a core busy; see docs/PERFORMANCE.md). Only flags that start with
#: "--": XLA stops reading XLA_FLAGS at the first word that does not (docs/REPRODUCTION.md,
#: "What a rerun reproduces").
WORKER_XLA_FLAGS = "--xla_cpu_multi_thread_eigen=false"

#: BLAS/LAPACK threads of a worker process (jaxlib's CPU Cholesky and other LAPACK kernels call
#: SciPy's OpenBLAS, whose threads spin-wait): one. Unset, each worker's OpenBLAS spun on every
#: core while the other worker computed: a time-marching seed of oscillator-long took 141–245 s in
#: one of two workers against 5–8 s with this (docs/PERFORMANCE.md, "Worker processes"). A value
#: the user set is kept.
WORKER_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _run_processes(tasks: Sequence[Task], work: Work, on_done: OnDone, jobs: int) -> None:
    """Tasks in ``jobs`` local worker processes (spawned: a fresh JAX in each, one thread each)."""
    ctx = multiprocessing.get_context("spawn")
    before = {k: os.environ.get(k) for k in ("XLA_FLAGS", *WORKER_THREAD_ENV)}
    os.environ["XLA_FLAGS"] = f"{before['XLA_FLAGS'] or ''} {WORKER_XLA_FLAGS}".strip()  # the workers inherit it
    for key, value in WORKER_THREAD_ENV.items():
        os.environ.setdefault(key, value)
    try:
        pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init)
        for _ in range(jobs):  # start them now, while the environment says so
            pool.submit(int)
    finally:
        for key, value in before.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
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
                "worker_xla_flags": WORKER_XLA_FLAGS if self.jobs > 1 else None,
                "worker_threads": {k: os.environ.get(k, v) for k, v in WORKER_THREAD_ENV.items()} if self.jobs > 1 else None}

"""Executing the tasks of a run: in this process, in local worker processes, or on a Dask cluster.

An executor takes the tasks still to do and a picklable function ``work(task) → output`` (the
training of one task, :func:`atlasnn.experiments._task.run_training` with the run's arguments
bound) and calls ``on_done(task, output)`` in the calling process as each task finishes. Finished
work is on disk before ``on_done`` is called, so whatever stops a run loses at most the unfinished
tasks' progress since their last saved state.

Signals. While a run is active (:class:`SignalGuard`), SIGINT and SIGTERM raise KeyboardInterrupt,
except that while a task trains in this process the first signal only marks the run as to be
stopped; it is acted on at the next safe point (the end of a chunk of epochs, or of a task), where
the training state is consistent. A second signal stops at once. Worker processes ignore SIGINT
(the parent decides) and are stopped by the parent.

Dask (:func:`run_dask`). The tasks go to the workers of a ``distributed`` scheduler, which must
see the run directory at the same path (a shared file system): each task writes its checkpoints,
records and states there itself, as a local worker process would. A worker cannot be stopped
from outside, so a signal in the coordinating process sets a Dask :class:`~distributed.Event`
that every running task polls at its safe points (:func:`check_interrupt`): the tasks save their
training states and return, and the coordinator raises once they have (or after
:data:`DASK_STOP_WAIT` seconds, or at a second signal).
"""

from __future__ import annotations

import asyncio
import concurrent.futures as cf
import functools
import multiprocessing
import os
import signal
import sys
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.experiments._plan import Task
from atlasnn.experiments._store import one_line

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


#: per thread: a function that says whether the coordinator of a Dask run asked its tasks to stop
_REMOTE = threading.local()


def check_interrupt() -> None:
    """Act on a deferred SIGINT/SIGTERM, or on a Dask coordinator's stop (call at a safe point)."""
    if _GUARD is not None and _GUARD.pending is not None:
        raise KeyboardInterrupt
    stop = getattr(_REMOTE, "stop", None)
    if stop is not None and stop():
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


# ------------------------------------------------------------------------ Dask
SCHEDULER_ENV = "ATLASNN_SCHEDULER"
#: after a signal, how long the coordinator waits for the running Dask tasks to save their states
DASK_STOP_WAIT = 60.0
#: a running Dask task asks the scheduler whether to stop at most this often (seconds)
_POLL_SECONDS = 0.25


def scheduler_address(scheduler: str | None = None, configured: str | None = None) -> str | None:
    """The Dask scheduler of a run: ``scheduler`` (the command line) when given, else
    ``$ATLASNN_SCHEDULER``, else ``configured`` (the config's ``execution.scheduler``); None (also
    for an empty text) means the local executors. The machine's setting (the environment) wins
    over the experiment file's, so one file runs anywhere."""
    if scheduler is None:
        scheduler = os.environ.get(SCHEDULER_ENV)
    if scheduler is None:
        scheduler = configured
    text = (scheduler or "").strip()
    return text or None


async def _probe(address: str, timeout: float) -> None:
    from distributed.comm import connect

    comm = await connect(address, timeout=timeout)
    await comm.close()


def _worker_version() -> str:
    from atlasnn import __version__

    return __version__


def connect_dask(address: str):
    """A :class:`distributed.Client` of the scheduler at ``address`` whose workers run this
    version of atlasnn, or a one-line ConfigError naming the address and the cause. The connect
    timeout is Dask's ``distributed.comm.timeouts.connect`` (default 30 s)."""
    try:
        import dask
        from distributed import Client
    except ImportError:
        raise ConfigError(f"scheduler {address}: the Dask executor needs the distributed package "
                          "(pip install 'atlasnn[dask]')") from None
    timeout = dask.utils.parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"))
    try:
        # a plain connection first, in its own thread and event loop: a Client that fails to
        # start prints tracebacks of its own when it is collected
        with cf.ThreadPoolExecutor(1) as ex:
            ex.submit(asyncio.run, _probe(address, timeout)).result()
        client = Client(address, timeout=timeout, set_as_default=False)
    except Exception as exc:
        raise ConfigError(f"cannot connect to the Dask scheduler at {address}: "
                          f"{one_line(exc) or type(exc).__name__}") from None
    try:
        versions = client.run(_worker_version)
    except Exception as exc:
        client.close()
        raise ConfigError(f"the workers of the Dask scheduler at {address} cannot run atlasnn "
                          f"({one_line(exc) or type(exc).__name__}); install it on every worker") from None
    mine = _worker_version()
    other = {w: v for w, v in versions.items() if v != mine}
    if other:
        client.close()
        worker, version = next(iter(other.items()))
        raise ConfigError(f"Dask worker {worker} of {address} runs atlasnn {version}, this process {mine}; "
                          "install the same version on every worker")
    return client


def close_dask(client) -> None:
    """Close a client; a scheduler that is already gone is not an error here (the run's own
    outcome, or error, is what counts)."""
    try:
        client.close()
    except Exception:
        pass


def dask_threads(client) -> int:
    """The number of worker threads of a Dask cluster now (at least 1)."""
    return max(1, sum(client.nthreads().values()))


def _read_probe(path: str) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        return f"cannot read {path}: {one_line(exc)}"


def check_shared_dir(client, directory: str | Path) -> None:
    """Every Dask worker must see ``directory`` (a shared file system at the same path): a file
    written here must be readable there, else a one-line ConfigError."""
    token = uuid.uuid4().hex
    probe = Path(directory) / f".dask-probe-{token}"
    probe.write_text(token, encoding="utf-8")
    try:
        seen = client.run(_read_probe, str(probe))
    finally:
        probe.unlink(missing_ok=True)
    for worker, text in seen.items():
        if text != token:
            raise ConfigError(f"Dask worker {worker} does not see the run directory {directory} ({text}); "
                              "the workers need it on a shared file system at the same path")


@dataclass(frozen=True)
class Stopped:
    """What a Dask task returns when it stopped because the coordinator asked it to (its training
    states are saved)."""


class _StopPoll:
    """Whether the coordinator set the stop event; asks the scheduler at most every
    :data:`_POLL_SECONDS` (a round trip per chunk of epochs would be wasted)."""

    def __init__(self, name: str):
        from distributed import Event

        self.event, self.last, self.value = Event(name), float("-inf"), False

    def __call__(self) -> bool:
        now = time.monotonic()
        if not self.value and now - self.last >= _POLL_SECONDS:
            self.last = now
            try:
                self.value = bool(self.event.is_set())
            except Exception:  # the scheduler is unreachable: the task goes on, Dask decides
                pass
        return self.value


def _on_worker(work: Work, stop_name: str, task: Task) -> Any:
    """Run one task on a Dask worker, stopping at a safe point when the coordinator asks."""
    stop = _StopPoll(stop_name)
    if stop():
        return Stopped()
    _REMOTE.stop = stop
    try:
        return work(task)
    except KeyboardInterrupt:  # raised at a safe point by check_interrupt; the states are saved
        return Stopped()
    finally:
        _REMOTE.stop = None


def _stop_tasks(client, stop, futures: dict, interrupted: bool) -> None:
    """Ask the running tasks to save their states and return, wait for them (at most
    :data:`DASK_STOP_WAIT` seconds; a second signal stops waiting), then cancel every task."""
    try:
        stop.set()
        running = [f for f in futures if not f.done()]
        if running and interrupted:
            print(f"atlasnn: stopping {len(running)} Dask task(s) at the end of their current chunk of epochs "
                  "(send the signal again to stop at once)", file=sys.stderr, flush=True)
        end = time.monotonic() + DASK_STOP_WAIT
        while running and time.monotonic() < end:
            time.sleep(0.05)
            running = [f for f in running if not f.done()]
    except BaseException:  # a second signal or a lost scheduler: stop waiting
        pass
    try:
        client.cancel(list(futures))
    except Exception:
        pass


def _task_key(task: Task, token: str) -> str:
    return f"atlasnn-{task.column}-seeds{'-'.join(map(str, task.seeds))}-{token}"


def _result(fut, task: Task, address: str) -> Any:
    """A finished future's output; a dead worker or a lost scheduler as a one-line error."""
    from distributed import KilledWorker

    try:
        return fut.result()
    except KilledWorker as exc:
        raise AtlasError(f"Dask gave up on {task.column} seeds {list(task.seeds)}: its workers died while "
                         f"running it ({one_line(exc)}); finished trainings are kept, resume the run") from None
    except (cf.CancelledError, asyncio.CancelledError):
        raise AtlasError(f"the Dask scheduler at {address} dropped {task.column} seeds {list(task.seeds)} "
                         "(connection lost?); finished trainings are kept, resume the run") from None


def run_dask(tasks: Sequence[Task], work: Work, on_done: OnDone, address, *,
             shared_dir: str | Path | None = None) -> None:
    """Tasks on the workers of a Dask cluster: ``address`` is the scheduler's address or a
    connected :class:`distributed.Client`. ``shared_dir``: check first that every worker sees it.

    A task that Dask runs again (its worker died) runs ``work`` again: ``work`` must continue
    from what the earlier attempt saved (the runner passes ``resume=True``). On a signal or an
    error the running tasks are stopped as the module docstring says, then it is raised."""
    from distributed import Event, as_completed

    own = isinstance(address, str)
    client = connect_dask(address) if own else address
    where = address if own else client.scheduler.address
    try:
        if shared_dir is not None:
            check_shared_dir(client, shared_dir)
        token = uuid.uuid4().hex
        stop = Event(f"atlasnn-stop-{token}", client=client)
        remote = functools.partial(_on_worker, work, stop.name)
        futures = {client.submit(remote, task, key=_task_key(task, token), pure=False): task for task in tasks}
        try:
            for fut in as_completed(list(futures), loop=client.loop):
                output = _result(fut, futures[fut], where)
                if isinstance(output, Stopped):  # only after a stop: another coordinator's?
                    raise KeyboardInterrupt
                on_done(futures[fut], output)
                check_interrupt()
        except BaseException as exc:
            _stop_tasks(client, stop, futures, isinstance(exc, KeyboardInterrupt))
            raise
    finally:
        if own:
            close_dask(client)

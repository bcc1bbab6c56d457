"""The Dask executor: the tasks of a run on the workers of a ``distributed`` cluster.

The workers must see the run directory at the same path (a shared file system): each task writes
its checkpoints, records and states there itself, as a local worker process would. A worker
cannot be stopped from outside, so a signal in the coordinating process sets a Dask
:class:`~distributed.Event` that every running task polls at its safe points
(:func:`~atlasnn.experiments._signals.check_interrupt`): the tasks save their training states and
return, and the coordinator raises once they have (or after :data:`DASK_STOP_WAIT` seconds, or at
a second signal). A task that Dask runs again (its worker died) continues from what the earlier
attempt saved.
"""

from __future__ import annotations

import asyncio
import concurrent.futures as cf
import functools
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence, final

from atlasnn.errors import AtlasError, ConfigError
from atlasnn.experiments._executor import Executor, OnDone, Work
from atlasnn.experiments._plan import Task
from atlasnn.experiments._signals import check_interrupt, set_remote_stop
from atlasnn.experiments._store import one_line

__all__ = ["DaskExecutor", "connect_dask", "close_dask", "dask_threads", "run_dask", "check_shared_dir",
           "Stopped", "DASK_STOP_WAIT"]

#: after a signal, how long the coordinator waits for the running Dask tasks to save their states
DASK_STOP_WAIT = 60.0
#: a running Dask task asks the scheduler whether to stop at most this often (seconds)
_POLL_SECONDS = 0.25


async def _probe(address: str, timeout: float) -> None:
    from distributed.comm import connect

    comm = await connect(address, timeout=timeout)
    await comm.close()


def _worker_version() -> str:
    from atlasnn.version import __version__

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
                          "(pip install distributed, or in atlasnn's source folder pip install -e '.[dask]')") from None
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
    set_remote_stop(stop)
    try:
        return work(task)
    except KeyboardInterrupt:  # raised at a safe point by check_interrupt; the states are saved
        return Stopped()
    finally:
        set_remote_stop(None)


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


@final
class DaskExecutor(Executor):
    """The workers of the Dask scheduler at ``address`` (connected, versions checked, at once)."""

    name = "dask"
    reruns_tasks = True
    local_memory = False

    def __init__(self, address: str):
        self.address = address
        self.client = connect_dask(address)

    def slots(self) -> int:
        return dask_threads(self.client)

    def run(self, tasks, work, on_done, *, shared_dir=None) -> None:
        run_dask(tasks, work, on_done, self.client, shared_dir=shared_dir)

    def describe(self) -> str:
        return f"Dask scheduler {self.address} ({dask_threads(self.client)} worker threads)"

    def record(self) -> dict[str, Any]:
        return {"jobs": 1, "scheduler": self.address}

    def close(self) -> None:
        close_dask(self.client)

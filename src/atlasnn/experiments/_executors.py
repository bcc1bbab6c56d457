"""The executors by name, and the one a run asks for (:func:`open_executor`).

- ``local``: :class:`~atlasnn.experiments._local.LocalExecutor`, this process or ``jobs`` worker
  processes;
- ``dask``: :class:`~atlasnn.experiments._dask.DaskExecutor`, the workers of a Dask cluster.
"""

from __future__ import annotations

import os
from typing import Any, Callable

from atlasnn.errors import ConfigError
from atlasnn.experiments._dask import DaskExecutor
from atlasnn.experiments._executor import Executor
from atlasnn.experiments._local import LocalExecutor

__all__ = ["EXECUTORS", "open_executor", "scheduler_address", "SCHEDULER_ENV"]

#: name -> the executor class, built from its one argument (jobs, or a scheduler's address)
EXECUTORS: dict[str, Callable[[Any], Executor]] = {"local": LocalExecutor, "dask": DaskExecutor}

SCHEDULER_ENV = "ATLASNN_SCHEDULER"


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


def open_executor(jobs: int = 1, scheduler: str | None = None, configured: str | None = None) -> Executor:
    """The executor a run asks for: Dask when a scheduler address is given (argument, environment
    or config: :func:`scheduler_address`), else local processes. ``jobs`` > 1 with a scheduler is
    refused (the scheduler's workers run the trainings)."""
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"jobs must be an integer >= 1, got {jobs!r}")
    address = scheduler_address(scheduler, configured)
    if address is None:
        return EXECUTORS["local"](jobs)
    if jobs != 1:
        raise ConfigError(f"jobs = {jobs} and the Dask scheduler {address} cannot be combined: the "
                          "scheduler's workers run the trainings (unset ATLASNN_SCHEDULER for local processes)")
    return EXECUTORS["dask"](address)

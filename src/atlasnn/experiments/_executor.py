"""The executor interface: where the tasks of a run train.

An :class:`Executor` takes the tasks still to do and a picklable function ``work(task) → output``
(the training of one task, :func:`atlasnn.experiments._task.run_training` with the run's arguments
bound) and calls ``on_done(task, output)`` in the calling process as each task finishes. Finished
work is on disk before ``on_done`` is called, so whatever stops a run loses at most the unfinished
tasks' progress since their last saved state. The runner and the sweep use executors only through
this interface; a new one is a subclass and one :data:`~atlasnn.experiments._executors.EXECUTORS`
entry.
"""

from __future__ import annotations

import abc
from pathlib import Path
from typing import Any, Callable, ClassVar, Sequence

from atlasnn.experiments._tasks import Task

__all__ = ["Executor", "Work", "OnDone"]

Work = Callable[[Task], Any]
OnDone = Callable[[Task, Any], None]


class Executor(abc.ABC):
    """Where a run's tasks train (see the module docstring). Use as a context manager, or call
    :meth:`close`."""

    #: the executor's name (``EXECUTORS`` key)
    name: ClassVar[str] = ""
    #: progress bars make sense (trainings run in this process, one at a time)
    shows_progress: bool = False
    #: a task may be run again after a failure: work must continue from saved states
    reruns_tasks: bool = False
    #: trainings run on this machine: their memory is checked here before the run
    local_memory: bool = True

    @abc.abstractmethod
    def slots(self) -> int:
        """How many trainings run at once (what seed batching plans for)."""

    @abc.abstractmethod
    def run(self, tasks: Sequence[Task], work: Work, on_done: OnDone, *, shared_dir: str | Path | None = None) -> None:
        """Run ``tasks``, calling ``on_done`` as each finishes; raises KeyboardInterrupt when stopped."""

    @abc.abstractmethod
    def describe(self) -> str:
        """One phrase for the run's log, e.g. ``jobs=2``."""

    def record(self) -> dict[str, Any]:
        """What meta.json records of the executor: ``jobs`` and ``scheduler`` (None: local)."""
        return {"jobs": self.slots(), "scheduler": None}

    def close(self) -> None:
        """Give back what the executor holds (a connection)."""

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

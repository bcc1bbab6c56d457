"""Experiments: configs → a plan of tasks → executors (local processes, Dask) → a run directory
with results.json, tables and figures; resume, sweeps, and the training schemes' table."""

from atlasnn.experiments._executor import Executor
from atlasnn.experiments._executors import EXECUTORS, open_executor, scheduler_address
from atlasnn.experiments._family_run import load_resumable_family, rewrite_family_summary, run_family
from atlasnn.experiments._family_seeds import check_resumable_family, is_unfinished_family_run
from atlasnn.experiments._local import LocalExecutor
from atlasnn.experiments._plan import columns_of, plan_tasks
from atlasnn.experiments._runner import RunInterrupted, divergence_advice, resume_experiment, run_experiment
from atlasnn.experiments._schemes import SCHEMES, Scheme, baseline_column, column_label, column_labels, table_columns
from atlasnn.experiments._signals import NoGuard, SignalGuard, check_interrupt
from atlasnn.experiments._store import load_run_config
from atlasnn.experiments._suite import SUITE_PROFILES, run_suite, suite_members
from atlasnn.experiments._sweep import SweepInterrupted, resume_sweep, run_sweep
from atlasnn.experiments._tasks import Task

__all__ = [
    "run_experiment",
    "run_family",
    "check_resumable_family",
    "load_resumable_family",
    "is_unfinished_family_run",
    "rewrite_family_summary",
    "resume_experiment",
    "RunInterrupted",
    "divergence_advice",
    "load_run_config",
    "run_sweep",
    "run_suite",
    "suite_members",
    "SUITE_PROFILES",
    "resume_sweep",
    "SweepInterrupted",
    "Executor",
    "LocalExecutor",
    "EXECUTORS",
    "open_executor",
    "scheduler_address",
    "Scheme",
    "SCHEMES",
    "table_columns",
    "baseline_column",
    "column_labels",
    "column_label",
    "Task",
    "plan_tasks",
    "columns_of",
    "SignalGuard",
    "NoGuard",
    "check_interrupt",
]

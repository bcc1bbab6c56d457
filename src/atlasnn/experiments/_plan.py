"""Planning a run: an experiment config → the independent trainings and their batches.

A *training* is one model and one seed in one role: a short run, the baseline HNN trained from
scratch on the target interval, or a transfer chain (source → target, which counts as one
training). A *task* is what an executor runs as one unit: the trainings of one column for a batch
of seeds, trained together as one compiled program (:func:`atlasnn.training._train.train_batch`). Every
training keeps its own records, checkpoints and state files, so how seeds are batched never
changes what a run directory holds.

How many seeds go in one batch (``seed_batch``): an integer, or ``"auto"``. Measured on this 2-core
CPU (``python -m benchmarks.seed_batch``, docs/PERFORMANCE.md): pinned to one core, a batch trains
no faster per seed than one seed alone (0.88–1.06× on the paper's configurations: an epoch already
keeps the core busy); given both cores, a batch of small epochs gains 1.3–1.4× because XLA spreads
its larger operations over them, which a lone small training does not. A batch still saves the
compilation of one program per seed. So ``"auto"`` batches the seeds of a column when one epoch is
below :data:`AUTO_BATCH_WORK` (collocation points × width²) — in the largest batch size whose
tasks, spread over the parallel jobs, are estimated to finish first — and pairs them when it is
larger but the machine has more cores than parallel jobs.

On a GPU the measurements go the other way (``scripts/gpu_check.sh``, docs/PERFORMANCE.md "A
GPU"): one seed alone leaves an H100 nearly idle, and a program of 16, 256 or 1 024 seeds trains
each seed 6–13×, 14–52× and 16–63× faster than one seed alone on it. So there ``"auto"`` puts all
the seeds of a column in one program, up to :data:`AUTO_BATCH_MAX_ACCELERATOR`.
"""

from __future__ import annotations

import os

import jax
import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.experiments._schemes import SCHEMES, active_schemes
from atlasnn.experiments._tasks import Task
from atlasnn.experiments.config import ExperimentConfig, Stage
from atlasnn.limits import check_integration_memory

#: "auto" batches the seeds of a column when K · width² of its largest stage is at most this
#: (oscillator-short, K = 200 and 50×2: 5.0e5, batches; Hénon–Heiles, K ≥ 500 and 80×2: ≥ 3.2e6,
#: does not). Set from the seed-batch benchmark; see the module docstring.
AUTO_BATCH_WORK = 1.0e6
#: at most this many seeds in one program ("auto"), so one batch never holds a whole long run
AUTO_BATCH_MAX = 8
#: the per-seed speed-up of a batch of small-epoch seeds in a process with one core to itself
#: (measured 0.97–1.06×: docs/benchmarks/seed_batch_one_core.json) and with a second core free
#: (measured 1.29–1.39× at the batch sizes auto picks: docs/benchmarks/seed_batch.json)
ONE_CORE_BATCH_GAIN = 1.0
SPARE_CORE_BATCH_GAIN = 1.3
#: "auto" on an accelerator (JAX's default backend is not the CPU): every seed of a column in one
#: program, up to this many (the largest batch measured on the H100: docs/benchmarks/gpu/)
AUTO_BATCH_MAX_ACCELERATOR = 1024



def _makespan(size: int, n_seeds: int, columns: int, jobs: int) -> float:
    """Estimated wall time, in lone-seed trainings, of ``columns`` columns of ``n_seeds`` seeds cut
    into batches of ``size`` and spread over ``jobs`` processes (longest task first)."""
    gain = SPARE_CORE_BATCH_GAIN if (os.cpu_count() or 1) > jobs else ONE_CORE_BATCH_GAIN
    batches = [min(size, n_seeds - i) for i in range(0, n_seeds, size)] * columns
    cost = sorted((b / (gain if b > 1 else 1.0) for b in batches), reverse=True)
    loads = [0.0] * jobs
    for c in cost:
        loads[loads.index(min(loads))] += c
    return max(loads)


def columns_of(cfg: ExperimentConfig) -> list[tuple[str, str]]:
    """(scheme, model) of every trained column, in table order."""
    return [(s.name, m) for s in active_schemes(cfg) for m in s.models(cfg)]


def epoch_work(cfg: ExperimentConfig, role: str) -> float:
    """K · width² of the largest training of a column's scheme: the size of one epoch, roughly."""
    return SCHEMES[role].epoch_work(cfg)


def _explicit(seed_batch: int | str, n_seeds: int) -> int:
    if isinstance(seed_batch, bool) or not isinstance(seed_batch, int) or seed_batch < 1:
        raise ConfigError(f"seed_batch must be an integer >= 1 or \"auto\", got {seed_batch!r}")
    return min(seed_batch, n_seeds)


def batch_size(cfg: ExperimentConfig, role: str, n_seeds: int, jobs: int, seed_batch: int | str,
               backend: str | None = None) -> int:
    """How many seeds of one column to train together (see the module docstring); ``backend``
    is where they train (default: JAX's default backend)."""
    limit = SCHEMES[role].batch_limit(cfg)
    if limit is not None:
        return 1 if seed_batch == "auto" else min(limit, _explicit(seed_batch, n_seeds))
    if seed_batch != "auto":
        return _explicit(seed_batch, n_seeds)
    if (backend or jax.default_backend()) != "cpu":
        return min(n_seeds, AUTO_BATCH_MAX_ACCELERATOR)
    if epoch_work(cfg, role) > AUTO_BATCH_WORK:
        return 2 if (os.cpu_count() or 1) > jobs and n_seeds > 1 else 1
    columns = len(columns_of(cfg))
    sizes = range(1, min(AUTO_BATCH_MAX, n_seeds) + 1)  # the fastest plan; ties: larger batches
    return min(sizes, key=lambda size: (round(_makespan(size, n_seeds, columns, jobs), 9), -size))


def plan_tasks(cfg: ExperimentConfig, seeds: tuple[int, ...], *, jobs: int = 1,
               seed_batch: int | str = 1, backend: str | None = None) -> list[Task]:
    """The tasks of a run: per column, its seeds cut into batches (in seed order)."""
    tasks = []
    for role, model in columns_of(cfg):
        size = batch_size(cfg, role, len(seeds), jobs, seed_batch, backend)
        for i in range(0, len(seeds), size):
            tasks.append(Task(role, model, tuple(seeds[i:i + size])))
    return tasks


def trainings(tasks: list[Task]) -> list[Task]:
    """Every one-seed training of a plan."""
    return [t for task in tasks for t in task.trainings()]


def eval_grid(stage: Stage, points: int | None) -> np.ndarray:
    """The evaluation grid of a stage: ``points`` (default K) equally spaced times."""
    n = points or stage.train.n_points
    return np.linspace(stage.t0, stage.T, n)


def check_memory(cfg: ExperimentConfig, tasks: list[Task], state_dim: int) -> None:
    """Refuse, as one line naming the key, a plan whose trainings or classical integrations will
    not fit in the memory available (:mod:`atlasnn.limits`), before anything is written."""
    for task in tasks:
        SCHEMES[task.role].check_memory(cfg, len(task.seeds), state_dim)
    ev = cfg.evaluation
    steps = (ev.se_steps or cfg.eval_stage.train.n_points - 1) * ev.fine_factor
    if cfg.system.separable or cfg.system.is_builtin:  # built-ins are separable
        check_integration_memory(steps, state_dim, value=ev.fine_factor)

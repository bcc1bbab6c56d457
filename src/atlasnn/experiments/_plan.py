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
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.experiments.config._config import ExperimentConfig, Stage

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


@dataclass(frozen=True)
class Task:
    """The trainings of one column (role and model) for a batch of seeds."""

    role: str  # "short" | "transfer" | "baseline" | "march"
    model: str  # "hnn" | "atlas_tanh" | "atlas_exp"
    seeds: tuple[int, ...]

    @property
    def column(self) -> str:
        """The table column this task's trainings fill."""
        if self.role == "short":
            return self.model
        if self.role == "baseline":
            return "hnn_baseline"
        if self.role == "march":
            return f"{self.model}_march"
        return f"{self.model}_transfer"

    @property
    def seed(self) -> int:
        """The seed of a one-seed task."""
        if len(self.seeds) != 1:
            raise ValueError(f"task {self.column} holds seeds {list(self.seeds)}, not one")
        return self.seeds[0]

    def one(self, seed: int) -> "Task":
        """The one-seed task of ``seed`` (records and state files are kept per seed)."""
        return Task(self.role, self.model, (seed,))

    def trainings(self) -> list["Task"]:
        return [self.one(s) for s in self.seeds]


def columns_of(cfg: ExperimentConfig) -> list[tuple[str, str]]:
    """(role, model) of every trained column, in table order."""
    marched = [("march", m) for m in cfg.march.models] if cfg.march is not None else []
    if cfg.kind == "short":
        return [("short", m) for m in cfg.models] + marched
    return ([("baseline", "hnn")] if cfg.baseline else []) + [("transfer", m) for m in cfg.models] + marched


def _stages(cfg: ExperimentConfig, role: str) -> list[Stage]:
    if role == "short":
        return [cfg.stage]
    if role == "baseline":
        return [cfg.target]
    return [cfg.source, cfg.target]


def epoch_work(cfg: ExperimentConfig, role: str) -> float:
    """K · width² of the largest stage of a column (a window for time-marching): the size of one
    epoch, roughly."""
    if role == "march":
        return cfg.march.scheme.train.n_points * float(cfg.march.width) ** 2
    return max(st.train.n_points for st in _stages(cfg, role)) * float(cfg.width) ** 2


def batch_size(cfg: ExperimentConfig, role: str, n_seeds: int, jobs: int, seed_batch: int | str) -> int:
    """How many seeds of one column to train together (see the module docstring)."""
    if seed_batch != "auto":
        if isinstance(seed_batch, bool) or not isinstance(seed_batch, int) or seed_batch < 1:
            raise ConfigError(f"seed_batch must be an integer >= 1 or \"auto\", got {seed_batch!r}")
        return min(seed_batch, n_seeds)
    if epoch_work(cfg, role) > AUTO_BATCH_WORK:
        return 2 if (os.cpu_count() or 1) > jobs and n_seeds > 1 else 1
    columns = len(columns_of(cfg))
    sizes = range(1, min(AUTO_BATCH_MAX, n_seeds) + 1)  # the fastest plan; ties: larger batches
    return min(sizes, key=lambda size: (round(_makespan(size, n_seeds, columns, jobs), 9), -size))


def plan_tasks(cfg: ExperimentConfig, seeds: tuple[int, ...], *, jobs: int = 1,
               seed_batch: int | str = 1) -> list[Task]:
    """The tasks of a run: per column, its seeds cut into batches (in seed order)."""
    tasks = []
    for role, model in columns_of(cfg):
        size = batch_size(cfg, role, len(seeds), jobs, seed_batch)
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
    from atlasnn.limits import check_integration_memory, check_training_memory

    for task in tasks:
        if task.role == "march":
            m = cfg.march
            check_training_memory(m.scheme.train.n_points, m.width, m.depth, state_dim, len(task.seeds),
                                  key="march.train.n_points")
            continue
        names = {"short": ["interval"], "baseline": ["target"], "transfer": ["source", "target"]}[task.role]
        for name, st in zip(names, _stages(cfg, task.role)):
            key = f"{name}.train.n_points" if "n_points" in ((cfg.raw.get(name) or {}).get("train") or {}) \
                else "train.n_points"
            check_training_memory(st.train.n_points, cfg.width, cfg.depth, state_dim, 1, key=key)
            if len(task.seeds) > 1:  # one seed fits; the batch is what to lower
                check_training_memory(st.train.n_points, cfg.width, cfg.depth, state_dim, len(task.seeds),
                                      key="execution.seed_batch", value=len(task.seeds),
                                      advice="one seed fits: lower execution.seed_batch (or --seed-batch)")
    ev = cfg.evaluation
    steps = (ev.se_steps or cfg.eval_stage.train.n_points - 1) * ev.fine_factor
    if cfg.system.separable or cfg.system.hamiltonian is None:  # built-ins are separable
        check_integration_memory(steps, state_dim, value=ev.fine_factor)

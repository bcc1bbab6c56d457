"""One task of a run: train a batch of seeds of one column, save the checkpoints, measure them.

:func:`run_training` is a plain function of (config, task, run directory, grids): the local
executor calls it in-process or in worker processes, the Dask executor on any worker that sees
the run directory. Its scheme (:data:`~atlasnn.experiments._schemes.SCHEMES`) trains the task's
seeds together through a :class:`TaskRun`, which writes one checkpoint and one record per seed;
it returns the records and trajectories per seed.

Interrupts and resume. Every chunk of epochs the host copy of each seed's
:class:`~atlasnn.training.TrainState` is kept; it is written to ``state/`` every
``ATLASNN_CHECKPOINT_SECONDS`` seconds and when the task is interrupted (KeyboardInterrupt,
re-raised after saving). A transfer chain also keeps each finished source (model, final state with
its Adam moments, record), so an interrupted target can be rebuilt exactly. With ``resume``, the
saved states of this run (same ``run_id``) are continued — bit-identical to an uninterrupted run
of the same batch — and a missing or unusable state means that training starts again (noted).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from atlasnn.checkpoint import (
    load_checkpoint,
    load_march_progress,
    load_state,
    save_checkpoint,
    save_march_progress,
    save_piecewise,
    save_state,
)
from atlasnn.errors import CheckpointError
from atlasnn.evaluation import MarchSummary, TrainingRecord, judge_training, measure_solution
from atlasnn.experiments import _schemes
from atlasnn.experiments._schemes import SCHEMES, column_label, host_state
from atlasnn.experiments._signals import check_interrupt
from atlasnn.experiments._tasks import Task
from atlasnn.experiments.config import ExperimentConfig, Stage
from atlasnn.nn import make_model
from atlasnn.solutions import PolynomialSolution, Solution
from atlasnn.training import LMConfig, MarchProgress, refine
from atlasnn.experiments._store import (
    checkpoint_seconds,
    state_files,
    state_path,
    write_record,
)

_SYSTEMS: dict[str, Any] = {}


def system_of(cfg: ExperimentConfig):
    """The built system of a config, one object per process (so compiled steps are reused)."""
    key = repr(cfg.system)
    sysm = _SYSTEMS.get(key)
    if sysm is None:
        if len(_SYSTEMS) >= 16:
            _SYSTEMS.pop(next(iter(_SYSTEMS)))
        sysm = _SYSTEMS[key] = cfg.system.build()
    return sysm


def lr_key(cfg: ExperimentConfig, role: str) -> str:
    """The config table that sets a training's lr: a stage's own ``train`` table, else ``train``."""
    if role == "march":
        return "march.train"
    stage = {"short": "interval", "source": "source", "target": "target"}.get(role, "interval")
    per_stage = (cfg.raw.get(stage) or {}).get("train") if isinstance(cfg.raw.get(stage), dict) else None
    return f"{stage}.train" if isinstance(per_stage, dict) and "lr" in per_stage else "train"


def verdict(cfg: ExperimentConfig, role: str, result, energy: np.ndarray, e0: float, stage: Stage,
            estimate: dict | None = None) -> dict:
    """The quality verdict of a finished training (:func:`atlasnn.evaluation.judge_training`, its
    error estimate first), as JSON."""
    returned = float(result.history.loss[result.best_epoch]) if result.best_epoch >= 0 else result.final_loss
    return judge_training(
        result.history.loss, stop_reason=result.stop_reason, tolerance=result.config.tolerance, energy=energy,
        energy0=e0, gamma={k: float(v) for k, v in result.model.scaling.gamma().items()}, returned_loss=returned,
        interval=(stage.t0, stage.T), lr=result.config.lr, epochs_budget=result.config.epochs,
        key=lr_key(cfg, role), estimate=estimate, thresholds=cfg.quality,
    ).as_dict()


def record(training: Task, role: str, column: str, result, metrics_: dict, ckpt: str, stage: Stage) -> TrainingRecord:
    """The record of one finished training (or transfer source)."""
    returned = float(result.history.loss[result.best_epoch]) if result.best_epoch >= 0 else result.final_loss
    return TrainingRecord(
        column=column, label=column_label(training.model, "short" if role == "source" else training.role),
        model=training.model, seed=training.seed, role=role, interval=(stage.t0, stage.T), metrics=metrics_,
        gamma={k: float(v) for k, v in result.model.scaling.gamma().items()}, epochs=result.epochs_run,
        stop_reason=result.stop_reason, returned_loss=returned, checkpoint=ckpt,
        tolerance_met=result.tolerance_met, best_epoch=result.best_epoch, diverged_epoch=result.diverged_epoch,
        wall_time=result.wall_time + float(result.info.get("wall_time_before", 0.0)),
        compile_time=result.compile_time, batch_size=result.info.get("batch_size", 1),
        final_loss=result.final_loss, best_loss=result.best_loss, lr=result.config.lr,
        epochs_budget=result.config.epochs, resumed_from_epoch=result.info.get("resumed_from_epoch"),
        polish=result.info.get("polish"),
    )


def march_record(training: Task, sol, scheme, metrics_: dict, ckpt: str, stage: Stage) -> TrainingRecord:
    """The record of a time-marching training: the worst window's loss is its loss; with adaptive
    windows every attempt (accepted, cut, rejected, forced) is listed in ``windows``."""
    windows = sol.windows
    losses = [float(r.loss) for r in windows]
    reasons = {r.stop_reason for r in windows}
    stop = "diverged" if "diverged" in reasons else ("tolerance" if reasons == {"tolerance"} else "budget")
    attempts = list(sol.info.get("attempts") or [])
    first = scheme.first or scheme.train
    budget = (sum(a["epochs"] for a in attempts) if attempts
              else first.epochs + scheme.train.epochs * (len(windows) - 1))
    lengths = np.diff(sol.edges)
    return TrainingRecord(
        column=training.column, label=column_label(training.model, training.role), model=training.model,
        seed=training.seed, role="march", interval=(stage.t0, stage.T), metrics=metrics_, gamma=sol.gamma,
        epochs=int(sum(a["epochs"] for a in attempts) if attempts else sum(r.epochs for r in windows)),
        stop_reason=stop, returned_loss=max(losses), checkpoint=ckpt,
        tolerance_met=stop == "tolerance", wall_time=float(sum(a["wall_time"] for a in attempts) if attempts
                                                           else sum(r.wall_time for r in windows)),
        compile_time=float(sum(r.compile_time for r in windows)), batch_size=int(sol.info.get("batch_size", 1)),
        final_loss=losses[-1], best_loss=min(losses), lr=scheme.train.lr, epochs_budget=int(budget),
        march=MarchSummary(n_windows=len(windows), window=float(lengths.max()), window_losses=losses,
                           window_epochs=[int(r.epochs) for r in windows], windows=attempts,
                           edges=[float(e) for e in sol.edges]),
    )


def march_verdict(cfg: ExperimentConfig, sol, rec: TrainingRecord, energy: np.ndarray, e0: float,
                  stage: Stage, window_epochs: int) -> dict:
    """The quality verdict of a time-marching training: its error estimate first; its windows' loss
    histories one after the other, the worst window's loss as the returned one. The advice names
    ``window_epochs``, the budget of one window (march.train.epochs), not the sum over windows."""
    history = np.concatenate([np.asarray(r.history, np.float64) for r in sol.windows if r.history is not None])
    return judge_training(history, stop_reason=rec.stop_reason, tolerance=None, energy=energy, energy0=e0,
                          gamma=rec.gamma, returned_loss=rec.returned_loss, interval=(stage.t0, stage.T),
                          lr=rec.lr, epochs_budget=window_epochs, key="march.train", estimate=rec.estimate,
                          thresholds=cfg.quality, estimate_advice="lower march.rtol (adaptive windows) or shorten "
                          "march.window, or raise march.train.epochs").as_dict()


def solve_record(training: Task, sol, metrics_: dict, ckpt: str, stage: Stage) -> TrainingRecord:
    """The record of a solve: no epochs; its "loss" is the worst window's error check over the
    tolerance (≤ 1 for every window kept), its wall time its share of the program that marched the
    task's seeds (the first call's compilation or cache load included; a deterministic solver's
    one solve is charged to every seed)."""
    info = sol.info
    ratios = [float(r) for r in sol.check] if isinstance(sol, PolynomialSolution) else [float(r.loss) for r in sol.windows]
    lengths = np.diff(sol.edges)
    work = {k: info[k] for k in ("rejected", "iterations", "newton_iterations", "newton_windows") if k in info}
    return TrainingRecord(
        column=training.column, label=column_label(training.model, training.role), model=training.model,
        seed=training.seed, role="solve", interval=(stage.t0, stage.T), metrics=metrics_, gamma={}, epochs=0,
        stop_reason="tolerance", returned_loss=max(ratios), checkpoint=ckpt, tolerance_met=max(ratios) <= 1.0,
        # one program marches the task's seeds: each is charged its share; the first call's compilation is in it
        wall_time=float(info["solve_time"]) / int(info.get("batch", 1)), compile_time=None,
        batch_size=int(info.get("batch", 1)), final_loss=ratios[-1], best_loss=min(ratios), lr=None, epochs_budget=0,
        march=MarchSummary(n_windows=len(ratios), window=float(lengths.max()), window_losses=ratios,
                           window_epochs=[0] * len(ratios), edges=[float(e) for e in sol.edges]),
        extra={"solver": info["settings"], "rtol": info["settings"]["rtol"], "atol": info["settings"]["atol"],
               **work, "first_call_time": info["first_call_time"], "batch_time": info["solve_time"]},
    )


def solve_verdict(cfg: ExperimentConfig, rec: TrainingRecord, energy: np.ndarray, e0: float, stage: Stage) -> dict:
    """The quality verdict of a collocation solve: its error estimate and energy (no loss curve:
    the worst window's error over its tolerance stands for one)."""
    return judge_training([rec.returned_loss], stop_reason="tolerance", energy=energy, energy0=e0, gamma={},
                          returned_loss=rec.returned_loss, interval=(stage.t0, stage.T), key="solve",
                          estimate=rec.estimate, thresholds=cfg.quality,
                          estimate_advice="lower solve.rtol and solve.atol").as_dict()


class TaskRun:
    """The trainings of one task while they run: system, grids, unsaved states, outputs."""

    def __init__(self, cfg, task, run_dir, grids, progress, run_id, resume):
        self.cfg, self.task, self.run_dir, self.grids = cfg, task, Path(run_dir), grids
        self.progress, self.run_id, self.resume = progress, run_id, resume
        self.system = system_of(cfg)
        self.z0 = self.system.initial_state(cfg.system.z0)
        self.e0 = float(self.system.energy64(self.z0))
        self.names = list(self.system.state_names)
        self.out = {s: {"records": [], "arrays": {}, "notes": []} for s in task.seeds}
        self.unsaved: dict[Path, Callable[[], Any]] = {}  # state file -> what writes it
        self.every = checkpoint_seconds()
        (self.run_dir / "state").mkdir(exist_ok=True)

    # ---------------------------------------------------------------- states
    def note(self, seed: int, text: str) -> None:
        self.out[seed]["notes"].append(text)

    def write_state(self, path: Path) -> None:
        self.unsaved.pop(path)()

    def write_all(self) -> None:
        for path in list(self.unsaved):
            self.write_state(path)

    def keep(self, path: Path, state, tc, column: str, seed: int, wall: float) -> None:
        extra = {"run_id": self.run_id, "experiment": self.cfg.name, "column": column, "seed": seed,
                 "wall_time_before": wall}
        self.unsaved[path] = lambda: save_state(path, state, self.system, tc, extra=extra)

    def march_saver(self, paths: list[Path], seeds: list[int]) -> Callable[[list[MarchProgress]], None]:
        """The ``on_progress`` of a march of ``seeds``: keeps every finished window's progress, writes
        it at most every ``checkpoint_seconds()`` (and on an interrupt), and stops at a signal."""
        last = [time.monotonic()]

        def keep(progress: list[MarchProgress]) -> None:
            for path, seed, prog in zip(paths, seeds, progress):
                prog.info = {"run_id": self.run_id, "experiment": self.cfg.name, "column": self.task.column,
                             "seed": seed}
                self.unsaved[path] = functools.partial(save_march_progress, path, prog, self.system)
            if time.monotonic() - last[0] >= self.every:
                for path in paths:
                    self.write_state(path)
                last[0] = time.monotonic()
            for seed, prog in zip(seeds, progress):  # every seed is kept before a hook can interrupt
                _schemes._hook("window", self.task.one(seed), self.task.column, prog)
            check_interrupt()

        return keep

    def load_march(self, paths: list[Path], seeds: list[int]) -> list[MarchProgress] | None:
        """The saved progress of every seed of a march of this run, or None (a fresh start) when a
        seed has none, it is another run's, or the seeds stopped after different windows."""
        if not self.resume or not all(p.is_file() for p in paths):
            return None
        saved = []
        for path, seed in zip(paths, seeds):
            try:
                prog = load_march_progress(path, self.system)
            except CheckpointError as exc:
                self.note(seed, f"{exc}; marching {self.task.column} seed {seed} from its first window")
                return None
            if prog.info.get("run_id") != self.run_id:
                return None
            saved.append(prog)
        if len({p.windows for p in saved}) != 1:
            for seed in seeds:
                self.note(seed, f"the saved windows of {self.task.column} differ between seeds of one batch; "
                                "marching the batch from its first window")
            return None
        for seed, prog in zip(seeds, saved):
            self.note(seed, f"{self.task.column} seed {seed} resumed after window {prog.windows} "
                            f"(t = {prog.t:.6g})")
        return saved

    def load_resume(self, path: Path, seed: int):
        """(saved TrainState of this run or None, wall time it had already taken)."""
        if not self.resume or not path.is_file():
            return None, 0.0
        try:
            extra = load_checkpoint(path, self.system).extra
            if extra.get("run_id") != self.run_id:
                return None, 0.0
            return load_state(path, self.system), float(extra.get("wall_time_before") or 0.0)
        except CheckpointError as exc:
            self.note(seed, f"{exc}; training {self.task.column} seed {seed} from scratch")
            return None, 0.0

    # ---------------------------------------------------------------- training
    def stage(self, column: str, seeds: list[int], tcs: list, start: Callable) -> list:
        """Train ``seeds`` of ``column`` as one batch: ``start(resume_states, on_chunk)`` trains."""
        paths = [state_path(self.run_dir, column, s) for s in seeds]
        loaded = [self.load_resume(p, s) for p, s in zip(paths, seeds)]
        states0 = [state for state, _ in loaded]
        if any(s is None for s in states0) and not all(s is None for s in states0):
            for s, state in zip(seeds, states0):  # a batch continues together or not at all
                if state is not None:
                    self.note(s, f"the saved state of {column} seed {s} is not used: other seeds of its "
                                 "batch have none; training the batch from scratch")
            loaded = [(None, 0.0)] * len(seeds)
            states0 = [None] * len(seeds)
        walls0 = [w for _, w in loaded]
        last_save, t_start = time.monotonic(), time.perf_counter()

        def on_chunk(states) -> None:
            nonlocal last_save
            snaps = [host_state(state) for state in states]
            for s, path, tc, wall0, snap in zip(seeds, paths, tcs, walls0, snaps):
                self.keep(path, snap, tc, column, s, wall0 + time.perf_counter() - t_start)
            for s, snap in zip(seeds, snaps):  # every seed is kept before a hook can interrupt
                _schemes._hook("chunk", self.task.one(s), column, snap)
            if time.monotonic() - last_save >= self.every:
                for path in paths:
                    self.write_state(path)
                last_save = time.monotonic()
            check_interrupt()

        results = start(None if all(s is None for s in states0) else states0, on_chunk)
        if any(r.stop_reason == "interrupted" for r in results):
            raise KeyboardInterrupt
        for res, state0, wall0 in zip(results, states0, walls0):
            res.info["resumed_from_epoch"] = None if state0 is None else int(state0.epoch)
            res.info["wall_time_before"] = wall0
        return results

    def new_models(self, model_name: str, stage: Stage, seeds: list[int]) -> list:
        cfg = self.cfg
        return [make_model(self.z0, scaling=model_name, width=cfg.width, depth=cfg.depth,
                           t0=stage.t0, gamma=cfg.gamma_init.get(model_name), activation=cfg.activation,
                           first_layer_scale=cfg.first_layer_scale, seed=s) for s in seeds]

    def configs(self, stage: Stage, seeds: list[int], freeze_gamma: bool = False) -> list:
        return [stage.train.to_train_config(stage.T, s, self.progress, freeze_gamma=freeze_gamma) for s in seeds]

    def label(self, column: str, seeds: list[int]) -> str:
        if column == self.task.column:
            who = column_label(self.task.model, self.task.role)
        else:
            who = column_label(column, "short") if column == self.task.model else column
        return f"{who} seed {seeds[0]}" if len(seeds) == 1 else f"{who} seeds {seeds[0]}-{seeds[-1]}"

    # ---------------------------------------------------------------- results
    def save(self, result, column: str, role: str, stage: Stage, seed: int) -> str:
        rel = f"models/{column}{'_source' if role == 'source' else ''}_seed{seed}.npz"
        save_checkpoint(
            self.run_dir / rel, result.model, self.system, history=result.history,
            train_config=dataclasses.asdict(result.config),
            extra={"experiment": self.cfg.name, "column": column, "model": self.task.model, "role": role,
                   "seed": seed, "interval": [stage.t0, stage.T], "stop_reason": result.stop_reason,
                   "epochs": result.epochs_run, "best_epoch": result.best_epoch},
        )
        return rel

    def polished(self, result, stage: Stage) -> None:
        """The second phase after Adam ([polish]: Levenberg–Marquardt or L-BFGS): the result's model
        is replaced by the refined one (never worse) and the phase is recorded in
        ``result.info["polish"]``."""
        pol = refine(result.model, self.system, stage.T, self.cfg.polish.replace(lam_reg=result.config.lam_reg),
                     energy0=self.e0)
        result.info["polish"] = {"method": "lm" if isinstance(self.cfg.polish, LMConfig) else "lbfgs",
                                 "steps": pol.steps, "stop_reason": pol.stop_reason,
                                 "initial_loss": pol.initial_loss, "final_loss": pol.final_loss}
        result.model = pol.model

    def finish_march(self, sol, scheme, stage: Stage, seed: int) -> None:
        column = self.task.column
        rel = f"models/{column}_seed{seed}.npz"
        save_piecewise(self.run_dir / rel, sol, train_config=dataclasses.asdict(scheme),
                       extra={"experiment": self.cfg.name, "column": column, "model": self.task.model,
                              "role": "march", "seed": seed, "interval": [stage.t0, stage.T]})
        self._measured(sol, column, seed, lambda per, energy, est: march_record(self.task.one(seed), sol, scheme, per,
                                                                               rel, stage),
                       lambda rec, energy: march_verdict(self.cfg, sol, rec, energy, self.e0, stage, scheme.train.epochs))

    def finish_solve(self, sol, stage: Stage, seed: int) -> None:
        column = self.task.column
        rel = f"models/{column}_seed{seed}.npz"
        save_piecewise(self.run_dir / rel, sol, extra={"experiment": self.cfg.name, "column": column,
                                                       "model": self.task.model, "role": "solve", "seed": seed,
                                                       "interval": [stage.t0, stage.T]})
        self._measured(sol, column, seed, lambda per, energy, est: solve_record(self.task.one(seed), sol, per, rel, stage),
                       lambda rec, energy: solve_verdict(self.cfg, rec, energy, self.e0, stage))

    def _say(self, line: str) -> None:
        """A phase's line beside the progress bars (when they are on)."""
        if self.progress:
            from tqdm.auto import tqdm

            tqdm.write(line, file=sys.stderr)

    def _measured(self, sol, column: str, seed: int, make_record, judge) -> None:
        """Measure a piecewise solution on the evaluation grid, estimate its error, keep its record."""
        per, z, energy = measure_solution(sol, self.grids["eval"], self.grids["eval_ref"], self.names, self.e0)
        clock = time.perf_counter()
        self._say(f"{column} seed {seed}: error estimate over the {len(sol.edges) - 1} windows…")
        est = sol.estimate(z0=self.z0)
        self._say(f"{column} seed {seed}: estimated max error {est.relative_max:.2e} of the state's range "
                  f"({time.perf_counter() - clock:.1f} s)")
        per["estimate_relative"] = est.relative_max
        rec = make_record(per, energy, est)
        rec.estimate = est.summary()
        rec.quality = judge(rec, energy)
        self.out[seed]["records"].append(rec.as_dict())
        self.out[seed]["arrays"][f"pred_{column}_seed{seed}"] = z
        self.out[seed]["arrays"][f"energy_{column}_seed{seed}"] = energy
        self.out[seed]["arrays"][f"estimate_{column}_seed{seed}"] = est.at(self.grids["eval"])

    def finish(self, result, column: str, role: str, stage: Stage, t_key: str, seed: int) -> dict:
        if self.cfg.polish is not None and role != "source":
            self.polished(result, stage)

        sol = Solution(result.model, self.system, (stage.t0, stage.T))
        per, z, energy = measure_solution(sol, self.grids[t_key], self.grids[t_key + "_ref"], self.names, self.e0)
        est = sol.estimate(z0=self.z0)
        per["estimate_relative"] = est.relative_max
        rec = record(self.task.one(seed), role, column, result, per, self.save(result, column, role, stage, seed), stage)
        rec.estimate = est.summary()
        rec.quality = verdict(self.cfg, role, result, energy, self.e0, stage, rec.estimate)
        self.out[seed]["records"].append(rec.as_dict())
        if role != "source":
            self.out[seed]["arrays"][f"pred_{column}_seed{seed}"] = z
            self.out[seed]["arrays"][f"energy_{column}_seed{seed}"] = energy
            self.out[seed]["arrays"][f"estimate_{column}_seed{seed}"] = est.at(self.grids[t_key])
        return rec


def run_training(cfg: ExperimentConfig, task: Task, run_dir: str, grids: dict[str, np.ndarray],
                 progress: bool, *, run_id: str | None = None, resume: bool = False) -> dict[int, dict]:
    """Train one task (a batch of seeds of one column), save and measure every seed; returns
    ``{seed: {"records", "arrays", "notes"}}`` and writes each seed's record to ``tasks/``.
    On KeyboardInterrupt the current training states are saved to ``state/`` and it is raised
    again."""
    run = TaskRun(cfg, task, run_dir, grids, progress, run_id, resume)
    try:
        SCHEMES[task.role].train(run)
        for seed in task.seeds:
            write_record(run.run_dir, task.one(seed), run_id, run.out[seed])
    except KeyboardInterrupt:
        run.write_all()
        raise
    for seed in task.seeds:
        for path in state_files(run.run_dir, task.one(seed)):
            path.unlink(missing_ok=True)
    return run.out

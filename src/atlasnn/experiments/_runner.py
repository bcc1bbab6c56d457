"""Run an experiment config: plan the trainings, execute them, collect results.json, report.

The parts, data flowing one way:

- :mod:`~atlasnn.experiments._plan`: config → tasks (the trainings of one column for a batch of
  seeds);
- :mod:`~atlasnn.experiments._measure`: reference solution, classical integrators, metrics;
- :mod:`~atlasnn.experiments._task`: one task as a plain function (train, save, measure);
- :mod:`~atlasnn.experiments._executors`: the executors (this process, local processes, Dask) and the
  signal handling;
- :mod:`~atlasnn.experiments._store`: the run directory (atomic writes, records, states, lock).

This module ties them together: :func:`run_experiment` and :func:`resume_experiment`.

Interrupting and resuming: with SIGINT (Ctrl-C) or SIGTERM a run stops at the end of the
current chunk of epochs, saves the training states of its unfinished trainings and raises
:class:`RunInterrupted`; every finished training is already on disk. :func:`resume_experiment`
(``atlasnn run|reproduce --resume DIR``) skips the finished trainings, continues the others from
their states (bit-identical to an uninterrupted run on the CPU) and writes the results as usual.
The run's plan (how seeds were batched) is recorded in ``meta.json`` and reused on resume.

Executors: ``jobs`` local processes, or the workers of a Dask cluster (``scheduler``, or
``$ATLASNN_SCHEDULER``; :func:`atlasnn.experiments._executors.run_dask`). This process holds the
directory lock either way; Dask workers write into the directory over a shared file system.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
import time
import uuid
from pathlib import Path
from typing import Any, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from atlasnn.compile_cache import jax_time
from atlasnn.errors import ConfigError
from atlasnn.evaluation import REFERENCE_DESCRIPTION, TrainingRecord, energy_drift
from atlasnn.experiments._executor import Executor
from atlasnn.experiments._executors import open_executor
from atlasnn.experiments._measure import integrator_rows, integrator_runs, reference_grids, work_precision
from atlasnn.experiments._plan import check_memory, plan_tasks, trainings
from atlasnn.experiments._schemes import baseline_column, column_labels, table_columns
from atlasnn.experiments._signals import NoGuard, SignalGuard
from atlasnn.experiments._tasks import Task
from atlasnn.experiments.config import ExperimentConfig
from atlasnn.fileio import json_default
from atlasnn.report import check_figures, write_report
from atlasnn.experiments._store import (
    RunLock,
    check_run_dir,
    checkpoint_seconds,
    clear_states,
    forget_trainings,
    load_record,
    load_run_config,
    one_line,
    open_run_dir,
    read_run_meta,
    versions,
    write_json,
    write_npz,
)
from atlasnn.fileio import write_text
from atlasnn.experiments._task import lr_key, run_training, system_of

__all__ = ["RunInterrupted", "run_experiment", "resume_experiment", "divergence_advice", "load_run_config"]


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by SIGINT (Ctrl-C) or SIGTERM; its directory can be resumed.

    A subclass of :class:`KeyboardInterrupt`, so code that does not know about it still sees an
    interrupt. ``finished`` of ``total`` trainings have their records in ``run_dir/tasks``.
    """

    def __init__(self, run_dir: Path, finished: int, total: int):
        self.run_dir, self.finished, self.total = Path(run_dir), finished, total
        super().__init__(
            f"interrupted: {finished} of {total} trainings finished; resume the run in {run_dir} "
            f"with resume_experiment({str(run_dir)!r}) or `atlasnn run --resume {run_dir}`"
        )


def _json_round_trip(obj: Any) -> Any:
    """A JSON round trip (tuples become lists), to compare a config with a recorded one."""
    return json.loads(json.dumps(obj, default=json_default, allow_nan=True))


STATE_SCALE_LIMIT = 1e4  # beyond this the state's size, not the learning rate, is the cause


def state_scale(cfg: ExperimentConfig) -> float:
    """The largest of max |z0| and max |J∇H(z0)|·(T − t0): how far the trial solution must move
    from z0 (the network's outputs start of order 1)."""
    try:
        system = cfg.system.build()
        z0 = np.asarray(system.initial_state(cfg.system.z0), np.float64)
        with jax.enable_x64(True):
            rate = np.asarray(system.vector_field(jnp.asarray(z0)), np.float64)
    except Exception:  # noqa: BLE001 - advice only; the run already validated its system
        return 0.0
    stage = cfg.eval_stage
    span = stage.T - stage.t0
    values = np.concatenate([np.abs(z0), np.abs(rate) * span])
    values = values[np.isfinite(values)]
    return float(values.max()) if values.size else math.inf


def divergence_advice(cfg: ExperimentConfig, record: Mapping | TrainingRecord) -> str | None:
    """One line saying that a training diverged, what was kept, and what to change; None otherwise."""
    r = _as_record(record)
    if r.stop_reason != "diverged":
        return None
    key = lr_key(cfg, r.role)
    if r.best_epoch >= 0:
        kept = f"kept the parameters of epoch {r.best_epoch} (loss {r.returned_loss:.3e})"
    else:
        kept = "no finite loss was reached; kept the initial parameters"
    lr_txt = f"now {r.lr:g}, e.g. {r.lr / 10:g}" if isinstance(r.lr, (int, float)) else "now ?"
    budget = cfg.march.scheme.train.epochs if (r.role == "march" and cfg.march) else r.epochs_budget
    where = f"{r.who()} diverged at epoch {r.diverged_epoch} (non-finite loss); {kept}."
    scale = state_scale(cfg)
    if scale > STATE_SCALE_LIMIT:
        return (f"{where} The state is large (max |z0|, |dz/dt|·(T − t0) ≈ {scale:.3g}) against the network's "
                f"outputs of order 1 in float32: rescale the variables (units in which the state is of order 1); "
                f"a lower learning rate will not cure this.")
    line = (f"{where} Lower {key}.lr ({lr_txt}) and, if it then learns too slowly, raise {key}.epochs "
            f"(now {budget}{' per window' if r.role == 'march' else ''}).")
    if r.role == "source":
        line += " Its target starts from the kept parameters."
    return line


def quality_warning(record: Mapping | TrainingRecord) -> str | None:
    """One line for a training judged suspect or failed (its reasons and advice); None if ok, and
    for a diverged training (:func:`divergence_advice` already says what happened and what to do)."""
    r = _as_record(record)
    q = r.quality or {}
    if r.status in (None, "ok") or r.stop_reason == "diverged":
        return None
    advice = f" {q['advice']}" if q.get("advice") else ""
    return f"{r.who()} is {r.status}: {'; '.join(q.get('reasons') or [])}.{advice}"


#: the advice of a training judged suspect or failed in a quick run: its budget was capped on purpose
QUICK_ADVICE = ("A quick run (--quick) caps every budget, so this verdict judges the smoke test, not the "
                "method or its settings: run without --quick for a verdict at the config's budget.")


def _quick_advice(output: dict) -> dict:
    """A quick run's output with the advice of every suspect or failed training replaced by
    :data:`QUICK_ADVICE` (raising a capped budget, or lowering a learning rate tuned for the full
    one, is not what to do)."""
    for rec in output.get("records", []):
        q = rec.get("quality") or {}
        if q.get("status") not in (None, "ok") and q.get("advice"):
            q["advice"] = QUICK_ADVICE
    return output


def _as_record(record: Mapping | TrainingRecord) -> TrainingRecord:
    return record if isinstance(record, TrainingRecord) else TrainingRecord.from_dict(record)


def _log_done(log, i: int, n: int, output: dict, cfg: ExperimentConfig | None = None) -> None:
    for r in map(TrainingRecord.from_dict, output["records"]):
        if r.role == "solve":
            log(f"  [{i}/{n}] {r.label} seed {r.seed}: {r.march.n_windows} windows ({r.extra.get('rejected', 0)} "
                f"rejected), worst window error {r.returned_loss:.2f} of its tolerance, {r.wall_time:.2f} s "
                f"(compilation or cache load included)" + (f", {r.status}" if r.status else ""))
        elif r.role != "source":
            compiling = "" if not r.compile_time else f" + {r.compile_time:.1f} s compiling"
            log(f"  [{i}/{n}] {r.label} seed {r.seed}: {r.epochs} epochs ({r.stop_reason}), "
                f"loss {r.returned_loss:.3e}, {r.wall_time:.1f} s{compiling}" + (f", {r.status}" if r.status else ""))
        for line in (divergence_advice(cfg, r) if cfg is not None else None, quality_warning(r)):
            if line:
                log(f"  {line}")
    for note in output.get("notes", []):
        log(f"  note: {note}")


# ------------------------------------------------------------------------ the run
def run_experiment(
    cfg: ExperimentConfig,
    out: str | Path,
    *,
    seeds: tuple[int, ...] | None = None,
    jobs: int = 1,
    progress: bool = True,
    overwrite: bool = False,
    config_text: str | None = None,
    quick: bool = False,
    report: bool = True,
    log=print,
    resume: bool = False,
    figures: str = "all",
    config_source: str | None = None,
    handle_signals: bool = True,
    seed_batch: int | str | None = None,
    scheduler: str | None = None,
    executor: Executor | None = None,
) -> dict[str, Any]:
    """Run every training of ``cfg`` and write the run directory ``out``; returns results.

    Nothing is written before the inputs are checked (``out`` must be new or empty unless
    ``overwrite``) and, with a Dask scheduler, before it is connected.

    Args:
        cfg: the experiment, from [`load_config`][atlasnn.experiments.config.load_config].
        out: the run directory: new or empty (unless ``overwrite`` or ``resume``).
        seeds: the seeds to train (default the config's).
        jobs: local processes training at once (an integer ≥ 1).
        progress: show each training's progress.
        overwrite: reuse a non-empty ``out``, replacing this tool's own files of an earlier run.
        config_text: the config's text, kept in ``out`` as ``config.toml``.
        quick: record the run as a quick one (the reduced budget itself comes from
            ``load_config(..., quick=True)``).
        report: write the tables and figures when the trainings are done.
        log: called with each line of news.
        resume: continue an interrupted run in ``out`` (use ``resume_experiment``, which reads the
            config from ``out``).
        figures: what the report draws: ``"all"``, ``"overview"`` or ``"none"`` (tables only;
            ``atlasnn.report.write_report``).
        config_source: where the config came from, for the record.
        handle_signals: while running, SIGINT and SIGTERM stop training at the end of the current
            chunk (main thread only); ``RunInterrupted`` (a KeyboardInterrupt) is raised then.
        seed_batch: seeds of a column trained as one program: an integer, or ``"auto"`` (see
            ``atlasnn.experiments._plan``; on Dask it counts the cluster's worker threads as jobs);
            None takes the config's ``execution.seed_batch``.
        scheduler: the address of a Dask scheduler to run the trainings on (default
            ``$ATLASNN_SCHEDULER``; None or empty: local processes, ``jobs`` of them).
        executor: an open ``Executor`` to use (and leave open) instead of one made from ``jobs``
            and ``scheduler`` (a sweep runs all its points on one).

    Returns the results, as written to ``out/results.json``.
    """
    seeds = tuple(seeds if seeds is not None else cfg.seeds)
    if executor is None and (isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1):
        raise ConfigError(f"jobs must be an integer >= 1, got {jobs!r}")
    checkpoint_seconds()  # a bad ATLASNN_CHECKPOINT_SECONDS fails before anything is written
    check_figures(figures)
    out = Path(out)
    if resume:
        if overwrite:
            raise ConfigError("resume and overwrite cannot be combined: resume continues the run, overwrite starts it again")
        meta = read_run_meta(out)
        if [int(s) for s in seeds] != meta["seeds"] or bool(quick) != bool(meta.get("quick")):
            raise ConfigError(f"--resume {out}: the run was started with seeds {meta['seeds']} and "
                              f"quick={bool(meta.get('quick'))}, not seeds {list(seeds)} and quick={bool(quick)}")
        tasks = _recorded_plan(meta, cfg, seeds, out)
    else:
        meta = None
        check_run_dir(out, overwrite)
    own = executor is None
    if own:
        executor = open_executor(jobs, scheduler, cfg.scheduler)
    lock = None
    try:
        if resume:
            lock = RunLock(out).acquire()
            meta = read_run_meta(out)  # as it is now, under the lock
        else:
            tasks = plan_tasks(cfg, seeds, jobs=executor.slots(),
                               seed_batch=cfg.seed_batch if seed_batch is None else seed_batch)
            if executor.local_memory:  # Dask workers may be other machines: their memory is their own
                check_memory(cfg, tasks, system_of(cfg).state_dim)
            lock = open_run_dir(out, overwrite)
        with SignalGuard() if handle_signals else NoGuard():
            run = _Run(cfg, out, seeds, tasks, executor, progress, log, meta)
            return run.go(overwrite=overwrite, config_text=config_text, quick=quick, report=report,
                          config_source=config_source, figures=figures)
    finally:
        if lock is not None:
            lock.release()
        if own:
            executor.close()


def _recorded_plan(meta: dict, cfg: ExperimentConfig, seeds: tuple[int, ...], out: Path) -> list[Task]:
    """The plan a run was started with (runs without one trained every seed alone)."""
    plan = meta.get("plan")
    if plan is None:
        return plan_tasks(cfg, seeds, seed_batch=1)
    try:
        return [Task(str(t["role"]), str(t["model"]), tuple(int(s) for s in t["seeds"])) for t in plan]
    except (KeyError, TypeError, ValueError):
        raise ConfigError(f"--resume {out}: meta.json has an unreadable plan") from None


def resume_experiment(
    out: str | Path,
    *,
    jobs: int = 1,
    progress: bool = True,
    report: bool = True,
    log=print,
    handle_signals: bool = True,
    scheduler: str | None = None,
    executor: Executor | None = None,
    figures: str = "all",
) -> dict[str, Any]:
    """Continue an interrupted run directory (see the module docstring); returns the results.
    It may run on other executors than the run started on (``jobs``, ``scheduler``, or an open
    ``executor``)."""
    cfg, meta = load_run_config(out)
    return run_experiment(
        cfg, out, seeds=tuple(meta["seeds"]), jobs=jobs, progress=progress, quick=bool(meta.get("quick")),
        report=report, log=log, resume=True, handle_signals=handle_signals, scheduler=scheduler,
        executor=executor, figures=figures,
    )


class _Run:
    """One run of an experiment while it goes: directory, plan, outputs."""

    def __init__(self, cfg, out, seeds, tasks, executor: Executor, progress, log, meta):
        self.cfg, self.out, self.seeds, self.tasks = cfg, Path(out), seeds, tasks
        self.executor, self.progress, self.log, self.meta = executor, progress, log, meta
        self.resume = meta is not None
        self.started = time.time()
        self.previous_wall = float(meta.get("wall_time_total") or 0.0) if meta else 0.0
        self.outputs: dict[Task, dict] = {}  # per one-seed training
        self.quick = False  # set by go()

    def wall_total(self) -> float:
        return self.previous_wall + time.time() - self.started

    def set_status(self, status: str, *, quiet: bool = False, **more) -> None:
        """Record the run's status in meta.json; ``quiet``: a failure to write it (a full disk)
        is ignored, so that the error that stopped the run is the one reported."""
        self.meta.update(status=status, wall_time_total=self.wall_total(), **more)
        try:
            write_json(self.out / "meta.json", self.meta)
        except OSError:
            if not quiet:
                raise

    def go(self, *, overwrite, config_text, quick, report, config_source, figures="all") -> dict[str, Any]:
        cfg = self.cfg
        self.quick = bool(quick)
        system = system_of(cfg)
        z0 = system.initial_state(cfg.system.z0)
        e0 = float(system.energy64(z0))
        runs = integrator_runs(cfg, system, z0, self.log)
        grids, int_refs = reference_grids(cfg, system, z0, [r[3] for r in runs])
        int_rows, arrays = integrator_rows(cfg, system, runs, int_refs, e0, self.log)
        arrays.update({"t_eval": grids["eval"], "z_ref": grids["eval_ref"],
                       "energy_ref": system.energy64(grids["eval_ref"])})
        reference = REFERENCE_DESCRIPTION.replace("1e-12", f"{cfg.evaluation.reference_rtol:g}")
        self.record_start(overwrite, config_text, quick, config_source, reference)
        all_trainings = trainings(self.tasks)
        try:
            with jax_time() as spent:  # JAX's tracing and compiling in this process, in the record
                self.train(grids)
                results = self.collect(system, e0, grids, arrays, int_rows, quick, reference)
                if cfg.evaluation.work_precision:
                    results["work_precision"] = work_precision(cfg, system, z0, grids,
                                                               results["runs"], self.out, self.log)
            results["jax_time"] = {**spent.summary(), "scope": "this process (the trainings' own compile seconds are "
                                   "in each run's record; with --jobs or a scheduler they ran elsewhere)"}
            self.log(f"{cfg.name}: {spent.line()}")
            write_npz(self.out / "arrays.npz", arrays)
            write_json(self.out / "results.json", results)
            self.log(f"{cfg.name}: trainings done in {results['wall_time_total']:.1f} s; results in {self.out}")
            if report:
                write_report(self.out, figures=figures)
                drawn = {"all": "tables and figures", "overview": "tables and the overview figure",
                         "none": "tables (no figures: `atlasnn report DIR` draws them)"}[figures]
                self.log(f"{cfg.name}: {drawn} written to {self.out}")
        except KeyboardInterrupt:
            finished = sum(1 for t in all_trainings if load_record(self.out, t, self.meta["run_id"]) is not None)
            self.set_status("interrupted", quiet=True, finished_tasks=finished)
            raise RunInterrupted(self.out, finished, len(all_trainings)) from None
        except BaseException as exc:
            self.set_status("failed", quiet=True, error=one_line(f"{type(exc).__name__}: {exc}"))
            raise
        self.set_status("complete", finished_tasks=len(all_trainings))
        clear_states(self.out, all_trainings)
        return results

    def record_start(self, overwrite, config_text, quick, config_source, reference) -> None:
        """config.toml, config.json and meta.json (on resume: check the config is unchanged)."""
        cfg_dict = dataclasses.asdict(dataclasses.replace(self.cfg, raw={}))
        plan = [{"role": t.role, "model": t.model, "seeds": list(t.seeds)} for t in self.tasks]
        if self.resume:
            try:
                recorded = json.loads((self.out / "config.json").read_text(encoding="utf-8"))["resolved"]
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise ConfigError(f"--resume {self.out}: config.json is not readable ({one_line(exc)})") from None
            if _json_round_trip(cfg_dict) != recorded:
                raise ConfigError(f"--resume {self.out}: the config now resolves differently from when the run "
                                  "started (config.toml edited or atlasnn changed); start a new run instead")
            self.meta["status"] = "running"
            self.meta.setdefault("plan", plan)
            self.meta.setdefault("resumed", []).append(
                {"at": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(self.started)),
                 "command": " ".join(sys.argv), **self.executor.record()})
        else:
            (self.out / "models").mkdir(parents=True, exist_ok=True)
            if overwrite:  # this tool's own files of an earlier run into the same directory
                forget_trainings(self.out, trainings(self.tasks))
            if config_text is not None:
                write_text(self.out / "config.toml", config_text)
            write_json(self.out / "config.json", {"resolved": cfg_dict, "as_given": self.cfg.raw})
            self.meta = {
                "experiment": self.cfg.name, "profile": self.cfg.profile, "quick": quick,
                "seeds": list(self.seeds), **self.executor.record(),
                "versions": versions(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(self.started)),
                "command": " ".join(sys.argv), "reference": reference, "status": "running",
                "run_id": uuid.uuid4().hex, "config_source": config_source,
                "tasks": len(trainings(self.tasks)), "plan": plan,
            }
        write_json(self.out / "meta.json", self.meta)

    def train(self, grids: dict[str, np.ndarray]) -> None:
        """Every training not finished yet, on the chosen executor."""
        run_id, all_trainings = self.meta["run_id"], trainings(self.tasks)
        if self.resume:
            for t in all_trainings:
                done = load_record(self.out, t, run_id)
                if done is not None:
                    self.outputs[t] = done
            self.log(f"{self.cfg.name}: resuming {self.out}: {len(self.outputs)} of {len(all_trainings)} "
                     "training(s) already finished")
        todo = []
        for task in self.tasks:
            left = tuple(s for s in task.seeds if task.one(s) not in self.outputs)
            if left:
                todo.append(dataclasses.replace(task, seeds=left))
        batches = sorted({len(t.seeds) for t in self.tasks})
        where = self.executor.describe()
        self.log(f"{self.cfg.name}: {len(all_trainings)} training(s) "
                 f"({', '.join(sorted({t.column for t in self.tasks}))}) x seeds {list(self.seeds)}, "
                 f"{where}, seeds per program: {'/'.join(map(str, batches))}")
        # On Dask a task is run again when its worker dies; resume=True makes that attempt continue
        # from the states the earlier one saved. It only ever reads states and sources recorded with
        # this run's run_id, and a new run's directory holds none until its tasks write them.
        ex = self.executor
        work = functools.partial(run_training, self.cfg, run_dir=str(self.out), grids=grids,
                                 progress=self.progress and ex.shows_progress, run_id=run_id,
                                 resume=self.resume or ex.reruns_tasks)

        def on_done(task: Task, output: dict[int, dict]) -> None:
            for seed in task.seeds:
                self.outputs[task.one(seed)] = _quick_advice(output[seed]) if self.quick else output[seed]
                _log_done(self.log, len(self.outputs), len(all_trainings), output[seed], self.cfg)

        ex.run(todo, work, on_done, shared_dir=self.out)

    def collect(self, system, e0, grids, arrays, int_rows, quick, reference) -> dict[str, Any]:
        """results.json's content from the outputs of every training (in plan order)."""
        cfg, st = self.cfg, self.cfg.eval_stage
        ordered = [_quick_advice(self.outputs[t]) if quick else self.outputs[t] for t in trainings(self.tasks)]
        runs = [r for o in ordered for r in o["records"]]
        for o in ordered:
            arrays.update(o["arrays"])
        warnings = [w for w in (divergence_advice(cfg, r) for r in runs) if w]
        warnings += [w for w in (quality_warning(r) for r in runs) if w]
        warnings += [n for o in ordered for n in o.get("notes", [])]
        return {
            "experiment": cfg.name, "paper_experiment": cfg.paper_experiment or None, "profile": cfg.profile,
            "kind": cfg.kind, "description": cfg.description,
            "quick": quick,
            "system": system.describe(), "state_names": list(system.state_names), "energy0": e0,
            "seeds": list(self.seeds), "tolerance": st.train.tolerance, "columns": table_columns(cfg),
            "baseline": baseline_column(cfg), "labels": column_labels(cfg),
            "interval": [st.t0, st.T], "source_interval": [cfg.source.t0, cfg.source.T] if cfg.source else None,
            "eval_points": int(grids["eval"].size), "reference": reference,
            "reference_energy_drift": energy_drift(arrays["energy_ref"], e0),
            "follows": cfg.follows, "runs": runs, "integrators": int_rows,
            "warnings": warnings, "wall_time_total": self.wall_total(),
        }

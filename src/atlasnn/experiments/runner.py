"""Run an experiment config: train every model for every seed, measure, and write a run directory.

A run directory holds

    config.toml      the config file as given          config.json   the resolved config
    meta.json        versions, seeds, timings, status  results.json  per-run metrics and training facts
    arrays.npz       evaluation grid, reference, SE and model trajectories (for figures)
    models/          one checkpoint per trained model (with its loss and γ histories)
    tables.*, figures/   written by :mod:`atlasnn.report`
    tasks/           one record per finished training job (JSON + trajectories as .npz)
    state/           the training state of unfinished jobs (removed as each job finishes)

Data flows one way: config → system + models → trainer → solution → metrics → results.json →
report. Independent trainings (one per model and seed; a transfer chain source → target counts
as one) can run in parallel processes.

Interrupting and resuming. ``meta.json`` has a ``status``: ``running``, ``interrupted``,
``failed`` or ``complete``. Every job writes ``tasks/<role>_<model>_seed<k>.{json,npz}``
(atomically) as soon as it finishes. With one job at a time, SIGINT (Ctrl-C) or SIGTERM stops
training at the end of the current chunk of epochs (a second signal stops at once), saves the
job's :class:`~atlasnn.train.TrainState` to ``state/<column>_seed<k>.npz`` (for a transfer
chain also the finished source's final state, ``state/<model>_source_seed<k>.npz``) and raises
:class:`RunInterrupted`. :func:`resume_experiment` (``atlasnn run|reproduce --resume DIR``)
skips the finished jobs, continues the interrupted one from its state (bit-identical to an
uninterrupted run) and writes the results as usual. Every job also saves its state every
``ATLASNN_CHECKPOINT_SECONDS`` seconds (default 60), so after a crash, a hard kill, or an
interrupt of a parallel run (``jobs > 1``: the worker processes are stopped at once) a resumed
job continues from its last saved state, or from scratch when it has none.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import json
import math
import multiprocessing
import os
import platform
import signal
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.experiments.config import MODEL_LABELS, ExperimentConfig, Stage

RESULT_FILES = ("config.toml", "config.json", "meta.json", "results.json", "arrays.npz")
TASK_DIR = "tasks"
STATE_DIR = "state"
CHECKPOINT_SECONDS = 60.0  # default interval of the periodic state saves (ATLASNN_CHECKPOINT_SECONDS)


@dataclass(frozen=True)
class Task:
    """One independent training job: a short run, a transfer chain, or the baseline HNN."""

    role: str  # "short" | "transfer" | "baseline"
    model: str  # "hnn" | "atlas_tanh" | "atlas_exp"
    seed: int

    @property
    def column(self) -> str:
        if self.role == "short":
            return self.model
        if self.role == "baseline":
            return "hnn_baseline"
        return f"{self.model}_transfer"


def plan_tasks(cfg: ExperimentConfig, seeds: tuple[int, ...]) -> list[Task]:
    """The list of independent training jobs of an experiment."""
    tasks = []
    for seed in seeds:
        if cfg.kind == "short":
            tasks += [Task("short", m, seed) for m in cfg.models]
        else:
            if cfg.baseline:
                tasks.append(Task("baseline", "hnn", seed))
            tasks += [Task("transfer", m, seed) for m in cfg.models]
    return tasks


def eval_grid(stage: Stage, points: int | None) -> np.ndarray:
    """The evaluation grid of a stage: ``points`` (default K) equally spaced times."""
    n = points or stage.train.n_points
    return np.linspace(stage.t0, stage.T, n)


def versions() -> dict[str, str]:
    """Versions of atlasnn and the libraries a result depends on."""
    import equinox
    import jax
    import jaxlib
    import optax
    import scipy

    from atlasnn import __version__

    return {
        "atlasnn": __version__, "jax": jax.__version__, "jaxlib": jaxlib.__version__,
        "equinox": equinox.__version__, "optax": optax.__version__, "numpy": np.__version__,
        "scipy": scipy.__version__, "python": platform.python_version(), "platform": platform.platform(),
        "backend": jax.default_backend(),
    }


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def _write_atomic(path: Path, write) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it onto ``path``;
    on any failure (Ctrl-C included) the temporary file is removed and ``path`` is untouched."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_json(path: Path, data: Any) -> None:
    """Write JSON atomically (temporary file, fsync, then rename)."""
    text = json.dumps(data, indent=1, default=_json_default, allow_nan=True)
    _write_atomic(Path(path), lambda f: f.write(text.encode("utf-8")))


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``np.savez`` atomically (temporary file, fsync, then rename)."""
    _write_atomic(Path(path), lambda f: np.savez(f, **arrays))


# ------------------------------------------------------------------ interrupts and resume
class RunInterrupted(KeyboardInterrupt):
    """A run stopped by SIGINT (Ctrl-C) or SIGTERM; its directory can be resumed.

    A subclass of :class:`KeyboardInterrupt`, so code that does not know about it still sees an
    interrupt. ``finished`` of ``total`` training jobs have their records in ``run_dir/tasks``.
    """

    def __init__(self, run_dir: Path, finished: int, total: int):
        self.run_dir, self.finished, self.total = Path(run_dir), finished, total
        super().__init__(
            f"interrupted: {finished} of {total} trainings finished; resume the run in {run_dir} "
            f"with resume_experiment({str(run_dir)!r}) or `atlasnn run --resume {run_dir}`"
        )


class _SignalGuard:
    """While active, SIGINT and SIGTERM raise KeyboardInterrupt, except that while
    ``deferring`` the first signal only marks the run as to be stopped; it is acted on at the
    next safe point (the end of a chunk of epochs, or of a training job), where the training
    state is consistent. A second signal stops at once. Handlers are only touched in the main
    thread, a signal that is ignored (SIG_IGN) stays ignored, and the old handlers come back."""

    def __init__(self) -> None:
        self.pending: str | None = None
        self.deferring = False
        self._old: dict[int, Any] = {}
        self._prev: _SignalGuard | None = None

    def __enter__(self) -> "_SignalGuard":
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


_GUARD: _SignalGuard | None = None


def _check_interrupt() -> None:
    """Act on a deferred SIGINT/SIGTERM (a safe point)."""
    if _GUARD is not None and _GUARD.pending is not None:
        raise KeyboardInterrupt


def _set_deferring(flag: bool) -> None:
    if _GUARD is not None:
        _GUARD.deferring = flag


def _hook(event: str, task: "Task", column: str, state: Any) -> None:
    """A seam for tests: called after every chunk of epochs (``"chunk"``, with the host copy of
    the current TrainState) and when a transfer source is done (``"source_done"``)."""


def checkpoint_seconds() -> float:
    """Seconds between periodic state saves: ``ATLASNN_CHECKPOINT_SECONDS`` (default 60; 0 saves
    after every chunk of epochs)."""
    text = os.environ.get("ATLASNN_CHECKPOINT_SECONDS")
    if text is None or not text.strip():
        return CHECKPOINT_SECONDS
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not math.isfinite(value) or value < 0:
        raise ConfigError(f"ATLASNN_CHECKPOINT_SECONDS = {text!r}: expected a number of seconds >= 0")
    return value


def task_stem(task: "Task") -> str:
    """The file name (without suffix) of a finished job's record in ``tasks/``."""
    return f"{task.role}_{task.model}_seed{task.seed}"


def state_path(run_dir: Path, column: str, seed: int) -> Path:
    """Where the training state of ``column`` (seed ``seed``) is kept while it is unfinished."""
    return Path(run_dir) / STATE_DIR / f"{column}_seed{seed}.npz"


def _task_state_files(run_dir: Path, task: "Task") -> list[Path]:
    files = [state_path(run_dir, task.column, task.seed)]
    if task.role == "transfer":
        src = state_path(run_dir, f"{task.model}_source", task.seed)
        files += [src, src.with_suffix(".json")]
    return files


def _sha256(path: Path) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _one_line(text: Any) -> str:
    return " ".join(str(text).split())


def _write_task(run_dir: Path, task: "Task", run_id: str | None, output: dict) -> None:
    """Keep a finished job: its trajectories (.npz), then its records (.json, the marker)."""
    tdir = Path(run_dir) / TASK_DIR
    tdir.mkdir(exist_ok=True)
    stem = task_stem(task)
    write_npz(tdir / f"{stem}.npz", output["arrays"])
    write_json(tdir / f"{stem}.json", {
        "run_id": run_id, "task": {"role": task.role, "model": task.model, "seed": task.seed},
        "records": output["records"], "notes": output.get("notes", []),
        "arrays": f"{stem}.npz", "arrays_sha256": _sha256(tdir / f"{stem}.npz"),
    })


def _load_task(run_dir: Path, task: "Task", run_id: str) -> dict | None:
    """The output of a job finished earlier in this run (same run_id, intact files), or None."""
    tdir = Path(run_dir) / TASK_DIR
    path = tdir / f"{task_stem(task)}.json"
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict) or data.get("run_id") != run_id:
            return None
        npz = tdir / data["arrays"]
        if npz.parent != tdir or _sha256(npz) != data["arrays_sha256"]:
            return None
        with np.load(npz, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        records = data["records"]
        if not all((Path(run_dir) / r["checkpoint"]).is_file() for r in records):
            return None
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return {"records": records, "arrays": arrays, "notes": list(data.get("notes") or [])}


# ------------------------------------------------------------------------- one task
_SYSTEMS: dict[str, Any] = {}


def _system(cfg: ExperimentConfig):
    """The built system of a config, one object per process (so compiled steps are reused)."""
    key = repr(cfg.system)
    sysm = _SYSTEMS.get(key)
    if sysm is None:
        if len(_SYSTEMS) >= 16:
            _SYSTEMS.pop(next(iter(_SYSTEMS)))
        sysm = _SYSTEMS[key] = cfg.system.build()
    return sysm


def _measure(solution, t: np.ndarray, z_ref: np.ndarray, names, energy0: float) -> tuple[dict, np.ndarray, np.ndarray]:
    from atlasnn import metrics

    z = solution(t).astype(np.float64)
    energy = solution.energy(t)
    table = metrics.error_table(t, z, z_ref, names)
    per = {m: {n: table["components"][n][m] for n in names} for m in metrics.METRIC_NAMES}
    per["whole"] = table["whole"]
    per["energy_drift"] = metrics.energy_drift(energy, energy0)
    return per, z, energy


def _record(task: Task, role: str, column: str, result, metrics_: dict, ckpt: str, stage: Stage) -> dict:
    gamma = {k: float(v) for k, v in result.model.scaling.gamma().items()}
    return {
        "column": column, "label": MODEL_LABELS.get(column, column), "model": task.model, "seed": task.seed,
        "role": role, "interval": [stage.t0, stage.T], "metrics": metrics_, "gamma": gamma,
        "epochs": result.epochs_run, "tolerance_met": result.tolerance_met, "stop_reason": result.stop_reason,
        "best_epoch": result.best_epoch, "diverged_epoch": result.diverged_epoch,
        "wall_time": result.wall_time + float(result.info.get("wall_time_before", 0.0)),
        "compile_time": result.compile_time,
        "final_loss": result.final_loss, "best_loss": result.best_loss,
        "returned_loss": float(result.history.loss[result.best_epoch]) if result.best_epoch >= 0 else result.final_loss,
        "lr": result.config.lr, "epochs_budget": result.config.epochs,
        "resumed_from_epoch": result.info.get("resumed_from_epoch"),
        "checkpoint": ckpt,
    }


def run_task(
    cfg: ExperimentConfig,
    task: Task,
    run_dir: str,
    grids: dict[str, np.ndarray],
    progress: bool,
    *,
    run_id: str | None = None,
    resume: bool = False,
) -> dict:
    """Train one task, save its checkpoint(s), measure it; returns records and trajectories.

    The finished task is also written to ``tasks/`` (see the module docstring). With ``resume``,
    a saved training state of this run (``run_id``) is continued instead of starting afresh.
    On KeyboardInterrupt the current training state is saved to ``state/`` and the interrupt is
    raised again.
    """
    import jax

    from atlasnn.checkpoint import load_checkpoint, load_state, save_checkpoint, save_state
    from atlasnn.errors import CheckpointError
    from atlasnn.model import MODEL_SCALINGS, make_model
    from atlasnn.solution import Solution
    from atlasnn.train import TrainState, train
    from atlasnn.transfer import transfer_from

    system = _system(cfg)
    z0 = system.initial_state(cfg.system.z0)
    with _x64():
        import jax.numpy as jnp

        energy0 = float(system.energy(jnp.asarray(z0, jnp.float64)))
    names = list(system.state_names)
    run_dir = Path(run_dir)
    (run_dir / STATE_DIR).mkdir(exist_ok=True)
    records, arrays, notes = [], {}, []
    every = checkpoint_seconds()
    unsaved: dict[Path, tuple] = {}  # state file -> (host TrainState, TrainConfig, extra) not yet written

    def host(state) -> TrainState:
        return TrainState(jax.device_get(state.model), jax.device_get(state.opt_state),
                          jax.device_get(state.track), int(state.epoch), state.history)

    def write_state(path: Path) -> None:
        state, tc, extra = unsaved.pop(path)
        save_state(path, state, system, tc, extra=extra)

    def state_extra(column: str, wall: float) -> dict:
        return {"run_id": run_id, "experiment": cfg.name, "column": column, "seed": task.seed,
                "wall_time_before": wall}

    def load_resume(path: Path) -> tuple[TrainState | None, float]:
        if not resume or not path.is_file():
            return None, 0.0
        try:
            extra = load_checkpoint(path, system).extra
            if extra.get("run_id") != run_id:
                return None, 0.0
            return load_state(path, system), float(extra.get("wall_time_before") or 0.0)
        except CheckpointError as exc:
            notes.append(f"{exc}; training {task.column} seed {task.seed} from scratch")
            return None, 0.0

    def run_stage(column: str, tc, start):
        """``start(resume_state, on_chunk)`` trains; the state is kept for interrupts."""
        path = state_path(run_dir, column, task.seed)
        state0, wall0 = load_resume(path)
        last_save = time.monotonic()
        t_start = time.perf_counter()

        def on_chunk(state) -> None:
            nonlocal last_save
            snap = host(state)
            unsaved[path] = (snap, tc, state_extra(column, wall0 + time.perf_counter() - t_start))
            if time.monotonic() - last_save >= every:
                write_state(path)
                last_save = time.monotonic()
            _hook("chunk", task, column, snap)
            _check_interrupt()

        res = start(state0, on_chunk)
        if res.stop_reason == "interrupted":
            raise KeyboardInterrupt
        res.info["resumed_from_epoch"] = None if state0 is None else int(state0.epoch)
        res.info["wall_time_before"] = wall0
        return res

    def new_model(model_name: str, stage: Stage):
        return make_model(
            z0, scaling=MODEL_SCALINGS[model_name], width=cfg.width, depth=cfg.depth, t0=stage.t0,
            gamma=cfg.gamma_init.get(model_name), activation=cfg.activation, seed=task.seed,
        )

    def save(result, column: str, role: str, stage: Stage) -> str:
        rel = f"models/{column}{'_source' if role == 'source' else ''}_seed{task.seed}.npz"
        tc = dataclasses.asdict(result.config)
        save_checkpoint(
            run_dir / rel, result.model, system, history=result.history, train_config=tc,
            extra={"experiment": cfg.name, "column": column, "model": task.model, "role": role,
                   "seed": task.seed, "interval": [stage.t0, stage.T], "stop_reason": result.stop_reason,
                   "epochs": result.epochs_run, "best_epoch": result.best_epoch},
        )
        return rel

    def finish(result, column: str, role: str, stage: Stage, t_key: str) -> None:
        sol = Solution(result.model, system, (stage.t0, stage.T))
        per, z, energy = _measure(sol, grids[t_key], grids[t_key + "_ref"], names, energy0)
        records.append(_record(task, role, column, result, per, save(result, column, role, stage), stage))
        if role != "source":
            arrays[f"pred_{column}_seed{task.seed}"] = z
            arrays[f"energy_{column}_seed{task.seed}"] = energy

    def load_source(src_col: str):
        """A finished source of this run (record, returned model, final Adam state), or None."""
        spath = state_path(run_dir, src_col, task.seed)
        marker = spath.with_suffix(".json")
        if not resume or not marker.is_file() or not spath.is_file():
            return None
        try:
            data = json.loads(marker.read_text(encoding="utf-8"))
            if data.get("run_id") != run_id:
                return None
            rec = data["record"]
            model = load_checkpoint(run_dir / rec["checkpoint"], system).model
            opt_state = load_state(spath, system).opt_state
        except (OSError, ValueError, KeyError, TypeError, CheckpointError) as exc:
            notes.append(f"the saved source of {task.column} seed {task.seed} is not usable "
                         f"({_one_line(exc)}); training it again")
            return None
        return rec, model, opt_state

    label = f"{MODEL_LABELS.get(task.column, task.column)} seed {task.seed}"
    try:
        if task.role in ("short", "baseline"):
            st = cfg.stage if task.role == "short" else cfg.target
            model_name = task.model if task.role == "short" else "hnn"
            tc = st.train.to_train_config(st.T, task.seed, progress)
            res = run_stage(task.column, tc, lambda s0, cb: train(
                new_model(model_name, st), system, st.T, tc, desc=label, resume=s0, on_chunk=cb))
            finish(res, task.column, "short" if task.role == "short" else "target", st, "eval")
        else:
            src, tgt = cfg.source, cfg.target
            src_col = f"{task.model}_source"
            tgt_state_file = state_path(run_dir, task.column, task.seed)
            loaded = load_source(src_col)
            if loaded is not None:
                rec, src_model, src_opt = loaded
                records.append(rec)
            else:
                if resume and tgt_state_file.is_file():  # a target state without its source: start over
                    notes.append(f"no usable source for the saved target state of {task.column} seed "
                                 f"{task.seed}; training the chain again")
                    tgt_state_file.unlink()
                src_tc = src.train.to_train_config(src.T, task.seed, progress)
                res_src = run_stage(src_col, src_tc, lambda s0, cb: train(
                    new_model(task.model, src), system, src.T, src_tc,
                    desc=f"{MODEL_LABELS[task.model]} source seed {task.seed}", resume=s0, on_chunk=cb))
                finish(res_src, task.model, "source", src, "source")
                # keep the finished source (its final state carries the Adam moments the target
                # starts from) so that an interrupted target can be rebuilt exactly
                spath = state_path(run_dir, src_col, task.seed)
                unsaved[spath] = (host(res_src.state), src_tc, state_extra(src_col, records[-1]["wall_time"]))
                write_state(spath)
                write_json(spath.with_suffix(".json"), {"run_id": run_id, "record": records[-1]})
                src_model, src_opt = res_src.model, res_src.opt_state
                _hook("source_done", task, src_col, None)
                _check_interrupt()
            tgt_tc = tgt.train.to_train_config(tgt.T, task.seed, progress, freeze_gamma=not cfg.thaw)
            res_tgt = run_stage(task.column, tgt_tc, lambda s0, cb: transfer_from(
                src_model, src_opt, system, tgt.T, tgt_tc, thaw=cfg.thaw, carry_adam=cfg.carry_adam,
                desc=label, resume=s0, on_chunk=cb))
            finish(res_tgt, task.column, "target", tgt, "eval")
        output = {"records": records, "arrays": arrays, "notes": notes}
        _write_task(run_dir, task, run_id, output)
    except KeyboardInterrupt:
        for path in list(unsaved):
            write_state(path)
        raise
    for path in _task_state_files(run_dir, task):
        path.unlink(missing_ok=True)
    return output


class _x64:
    """``with _x64():`` evaluates in float64 (JAX's x64 context)."""

    def __enter__(self):
        import jax

        self._ctx = jax.enable_x64(True)
        self._ctx.__enter__()

    def __exit__(self, *exc):
        return self._ctx.__exit__(*exc)


def _worker_init() -> None:
    # Ctrl-C in a terminal reaches the whole process group: the parent process decides (it
    # stops the workers); a worker must not die with a traceback of its own
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")


def _stop_workers(pool: cf.ProcessPoolExecutor) -> None:
    """Terminate the worker processes of ``pool`` now (finished jobs are already on disk)."""
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


# ---------------------------------------------------------------------- the experiment
def check_run_dir(out: Path, overwrite: bool) -> None:
    """Refuse an existing non-empty ``out`` unless ``overwrite`` (creates nothing)."""
    out = Path(out)
    if out.exists():
        if not out.is_dir():
            raise ConfigError(f"output path exists and is not a directory: {out}")
        if any(out.iterdir()) and not overwrite:
            raise ConfigError(
                f"output directory {out} is not empty; pass --overwrite to reuse it, --resume {out} "
                "to continue an interrupted run in it, or choose another --out"
            )


def prepare_run_dir(out: Path, overwrite: bool) -> None:
    """Create ``out``; refuse an existing run unless ``overwrite`` (and never delete foreign files)."""
    check_run_dir(out, overwrite)
    (Path(out) / "models").mkdir(parents=True, exist_ok=True)


def read_run_meta(out: str | Path) -> dict[str, Any]:
    """``meta.json`` of a run directory that can be resumed (else a one-line ConfigError)."""
    out = Path(out)
    if not out.is_dir():
        raise ConfigError(f"--resume {out}: no such run directory")
    try:
        meta = json.loads((out / "meta.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"--resume {out}: not an atlasnn run directory (no meta.json)") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"--resume {out}: meta.json is not readable ({_one_line(exc)})") from None
    if not isinstance(meta, dict):
        raise ConfigError(f"--resume {out}: meta.json is not a JSON object")
    status = meta.get("status")
    if status == "complete" or (status is None and (out / "results.json").exists()):
        raise ConfigError(f"--resume {out}: the run is already complete (`atlasnn report {out}` re-renders "
                          "it; --overwrite runs it again)")
    if not isinstance(meta.get("run_id"), str) or not isinstance(meta.get("seeds"), list):
        raise ConfigError(f"--resume {out}: meta.json has no run_id or seeds (not written by a resumable "
                          "atlasnn run); start it again with --overwrite")
    return meta


def load_run_config(out: str | Path) -> tuple[ExperimentConfig, dict[str, Any]]:
    """The config and meta of a resumable run directory: ``config.toml`` as given, parsed with the
    run's ``--quick`` flag (or the recorded config when there is no ``config.toml``)."""
    import tomllib

    from atlasnn.experiments.config import parse_config

    out = Path(out)
    meta = read_run_meta(out)
    quick = bool(meta.get("quick"))
    source = meta.get("config_source") or f"{meta.get('experiment', 'config')}.toml"
    toml = out / "config.toml"
    try:
        if toml.is_file():
            data = tomllib.loads(toml.read_text(encoding="utf-8"))
        else:
            data = json.loads((out / "config.json").read_text(encoding="utf-8"))["as_given"]
            quick = False  # the recorded config is the merged one
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"--resume {out}: cannot read the run's config ({_one_line(exc)})") from None
    return parse_config(data, quick=quick, source=str(source)), meta


def resume_experiment(
    out: str | Path,
    *,
    jobs: int = 1,
    progress: bool = True,
    report: bool = True,
    log=print,
    handle_signals: bool = True,
) -> dict[str, Any]:
    """Continue an interrupted run directory (see the module docstring); returns the results."""
    cfg, meta = load_run_config(out)
    return run_experiment(
        cfg, out, seeds=tuple(meta["seeds"]), jobs=jobs, progress=progress, quick=bool(meta.get("quick")),
        report=report, log=log, resume=True, handle_signals=handle_signals,
    )


def _plain(obj: Any) -> Any:
    """A JSON round trip (tuples become lists), to compare a config with a recorded one."""
    return json.loads(json.dumps(obj, default=_json_default, allow_nan=True))


def _lr_key(cfg: ExperimentConfig, role: str) -> str:
    stage = {"short": "interval", "source": "source", "target": "target"}.get(role, "interval")
    per_stage = (cfg.raw.get(stage) or {}).get("train") if isinstance(cfg.raw.get(stage), dict) else None
    return f"{stage}.train" if isinstance(per_stage, dict) and "lr" in per_stage else "train"


def divergence_advice(cfg: ExperimentConfig, r: dict) -> str | None:
    """One line saying that a run diverged, what was kept, and what to change; None otherwise."""
    if r.get("stop_reason") != "diverged":
        return None
    key = _lr_key(cfg, r.get("role", "short"))
    who = f"{r['label']}{' source' if r.get('role') == 'source' else ''} seed {r['seed']}"
    if r.get("best_epoch", -1) >= 0:
        kept = f"kept the parameters of epoch {r['best_epoch']} (loss {r['returned_loss']:.3e})"
    else:
        kept = "no finite loss was reached; kept the initial parameters"
    lr, budget = r.get("lr"), r.get("epochs_budget")
    lr_txt = f"now {lr:g}, e.g. {lr / 10:g}" if isinstance(lr, (int, float)) else "now ?"
    line = (f"{who} diverged at epoch {r['diverged_epoch']} (non-finite loss); {kept}. "
            f"Lower {key}.lr ({lr_txt}) and, if it then learns too slowly, raise {key}.epochs (now {budget}).")
    if r.get("role") == "source":
        line += " Its target starts from the kept parameters."
    return line


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
    config_source: str | None = None,
    handle_signals: bool = True,
) -> dict[str, Any]:
    """Run every training of ``cfg`` and write the run directory ``out``; returns results.

    Nothing is written before the inputs are checked (``out`` must be new or empty unless
    ``overwrite``). ``resume=True`` continues an interrupted run in ``out`` (use
    :func:`resume_experiment`, which reads the config from ``out``). ``handle_signals``: while
    running, SIGINT and SIGTERM stop training at the end of the current chunk (main thread only).
    Raises :class:`RunInterrupted` (a KeyboardInterrupt) when interrupted.
    """
    seeds = tuple(seeds if seeds is not None else cfg.seeds)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"jobs must be an integer >= 1, got {jobs!r}")
    checkpoint_seconds()  # a bad ATLASNN_CHECKPOINT_SECONDS fails before anything is written
    out = Path(out)
    if resume:
        if overwrite:
            raise ConfigError("resume and overwrite cannot be combined: resume continues the run, overwrite starts it again")
        meta = read_run_meta(out)
        if [int(s) for s in seeds] != meta["seeds"] or bool(quick) != bool(meta.get("quick")):
            raise ConfigError(f"--resume {out}: the run was started with seeds {meta['seeds']} and "
                              f"quick={bool(meta.get('quick'))}, not seeds {list(seeds)} and quick={bool(quick)}")
    else:
        meta = None
        check_run_dir(out, overwrite)
    guard = _SignalGuard() if handle_signals else _NoGuard()
    with guard:
        return _run_experiment(cfg, out, seeds, jobs, progress, overwrite, config_text, quick, report, log,
                               meta, config_source)


class _NoGuard:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _run_experiment(cfg, out, seeds, jobs, progress, overwrite, config_text, quick, report, log, meta,
                    config_source) -> dict[str, Any]:
    from atlasnn.integrators import REFERENCE_DESCRIPTION, integrate, reference_solution
    from atlasnn import metrics

    resume = meta is not None
    started = time.time()
    system = _system(cfg)
    z0 = system.initial_state(cfg.system.z0)
    names = list(system.state_names)
    st = cfg.eval_stage
    ev = cfg.evaluation

    # ---- reference and classical integrators (deterministic, computed once)
    t_eval = eval_grid(st, ev.eval_points)
    z_ref = reference_solution(system, z0, t_eval, rtol=ev.reference_rtol, atol=ev.reference_atol)
    grids = {"eval": t_eval, "eval_ref": z_ref}
    if cfg.kind == "transfer":
        t_src = eval_grid(cfg.source, ev.eval_points and max(2, round(ev.eval_points * (cfg.source.T - cfg.source.t0) / (st.T - st.t0))))
        grids["source"] = t_src
        grids["source_ref"] = reference_solution(system, z0, t_src, rtol=ev.reference_rtol, atol=ev.reference_atol)
    with _x64():
        import jax.numpy as jnp

        energy0 = float(system.energy(jnp.asarray(z0, jnp.float64)))
        energy_ref = np.asarray(system.energy(jnp.asarray(z_ref, jnp.float64)))
    arrays: dict[str, np.ndarray] = {"t_eval": t_eval, "z_ref": z_ref, "energy_ref": energy_ref}

    integrator_rows = []
    se_steps = ev.se_steps or (st.train.n_points - 1)
    methods = [("se", "symplectic_euler", se_steps), (f"se_{ev.fine_factor}", "symplectic_euler", se_steps * ev.fine_factor)]
    methods += [(m, m, se_steps) for m in ev.integrators if m != "symplectic_euler"]
    for column, method, steps in methods:
        if not system.separable:
            log(f"skipping {method}: the Hamiltonian is not declared separable")
            continue
        t_i, z_i = integrate(method, system, z0, st.t0, st.T, steps)
        zr_i = reference_solution(system, z0, t_i, rtol=ev.reference_rtol, atol=ev.reference_atol)
        with _x64():
            e_i = np.asarray(system.energy(jnp.asarray(z_i, jnp.float64)))
        table = metrics.error_table(t_i, z_i, zr_i, names)
        per = {m: {n: table["components"][n][m] for n in names} for m in metrics.METRIC_NAMES}
        per["whole"] = table["whole"]
        per["energy_drift"] = metrics.energy_drift(e_i, energy0)
        label = "SE" if column == "se" else (f"SE-{ev.fine_factor}" if column.startswith("se_") else column)
        integrator_rows.append({"column": column, "label": label, "method": method, "steps": steps, "metrics": per})
        arrays[f"int_t_{column}"], arrays[f"int_z_{column}"] = t_i, z_i
        arrays[f"int_zref_{column}"], arrays[f"int_energy_{column}"] = zr_i, e_i

    # ---- record what is being run, before training
    tasks = plan_tasks(cfg, seeds)
    cfg_dict = dataclasses.asdict(dataclasses.replace(cfg, raw={}))
    if resume:
        try:
            recorded = json.loads((out / "config.json").read_text(encoding="utf-8"))["resolved"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ConfigError(f"--resume {out}: config.json is not readable ({_one_line(exc)})") from None
        if _plain(cfg_dict) != recorded:
            raise ConfigError(f"--resume {out}: the config now resolves differently from when the run started "
                              "(config.toml edited or atlasnn changed); start a new run instead")
        previous_wall = float(meta.get("wall_time_total") or 0.0)
        meta["status"] = "running"
        meta.setdefault("resumed", []).append(
            {"at": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)), "command": " ".join(sys.argv),
             "jobs": jobs})
        run_id = meta["run_id"]
    else:
        previous_wall = 0.0
        (out / "models").mkdir(parents=True, exist_ok=True)
        if overwrite:  # this tool's own job files from an earlier run into the same directory
            for task in tasks:
                for path in [out / TASK_DIR / f"{task_stem(task)}.json", out / TASK_DIR / f"{task_stem(task)}.npz",
                             *_task_state_files(out, task)]:
                    path.unlink(missing_ok=True)
        run_id = uuid.uuid4().hex
        if config_text is not None:
            (out / "config.toml").write_text(config_text, encoding="utf-8")
        write_json(out / "config.json", {"resolved": cfg_dict, "as_given": cfg.raw})
        meta = {"experiment": cfg.name, "quick": quick, "seeds": list(seeds), "jobs": jobs,
                "versions": versions(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)),
                "command": " ".join(sys.argv), "reference": REFERENCE_DESCRIPTION.replace("1e-12", f"{ev.reference_rtol:g}"),
                "status": "running", "run_id": run_id, "config_source": config_source, "tasks": len(tasks)}
    write_json(out / "meta.json", meta)

    def wall_total() -> float:
        return previous_wall + time.time() - started

    def stop(status: str, **more) -> None:
        meta.update(status=status, wall_time_total=wall_total(), **more)
        write_json(out / "meta.json", meta)

    # ---- the trainings
    try:
        outputs: dict[int, dict] = {}
        if resume:
            for i, task in enumerate(tasks):
                done = _load_task(out, task, run_id)
                if done is not None:
                    outputs[i] = done
            log(f"{cfg.name}: resuming {out}: {len(outputs)} of {len(tasks)} training job(s) already finished")
        todo = [i for i in range(len(tasks)) if i not in outputs]
        log(f"{cfg.name}: {len(tasks)} training job(s) ({', '.join(sorted({t.column for t in tasks}))}) "
            f"x seeds {list(seeds)}, jobs={jobs}")
        n_done = len(outputs)
        if jobs == 1 or len(todo) <= 1:
            for i in todo:
                _set_deferring(True)
                try:
                    outputs[i] = run_task(cfg, tasks[i], str(out), grids, progress, run_id=run_id, resume=resume)
                finally:
                    _set_deferring(False)
                n_done += 1
                _log_done(log, n_done, len(tasks), outputs[i], cfg)
                _check_interrupt()
        else:
            ctx = multiprocessing.get_context("spawn")
            pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init)
            futures: dict[Any, int] = {}
            try:
                for i in todo:
                    futures[pool.submit(run_task, cfg, tasks[i], str(out), grids, False,
                                        run_id=run_id, resume=resume)] = i
                for fut in cf.as_completed(futures):
                    outputs[futures[fut]] = fut.result()
                    n_done += 1
                    _log_done(log, n_done, len(tasks), outputs[futures[fut]], cfg)
            except BaseException:
                for fut in futures:
                    fut.cancel()
                _stop_workers(pool)
                raise
            finally:
                pool.shutdown(wait=True, cancel_futures=True)

        # ---- results
        ordered = [outputs[i] for i in range(len(tasks))]
        runs = [r for o in ordered for r in o["records"]]
        for o in ordered:
            arrays.update(o["arrays"])
        warnings = [w for w in (divergence_advice(cfg, r) for r in runs) if w]
        warnings += [n for o in ordered for n in o.get("notes", [])]
        baseline = cfg.baseline_column()
        results = {
            "experiment": cfg.name, "kind": cfg.kind, "description": cfg.description, "quick": quick,
            "system": system.describe(), "state_names": names, "energy0": energy0, "seeds": list(seeds),
            "tolerance": st.train.tolerance, "columns": cfg.columns(), "baseline": baseline,
            "labels": {c: MODEL_LABELS.get(c, c) for c in cfg.columns()},
            "interval": [st.t0, st.T], "source_interval": [cfg.source.t0, cfg.source.T] if cfg.source else None,
            "eval_points": int(t_eval.size), "reference": meta["reference"],
            "reference_energy_drift": metrics.energy_drift(energy_ref, energy0),
            "follows": cfg.follows, "runs": runs, "integrators": integrator_rows,
            "warnings": warnings, "wall_time_total": wall_total(),
        }
        write_npz(out / "arrays.npz", arrays)
        write_json(out / "results.json", results)
        log(f"{cfg.name}: trainings done in {results['wall_time_total']:.1f} s; results in {out}")
        if report:
            from atlasnn.render import write_report

            write_report(out)
            log(f"{cfg.name}: tables and figures written to {out}")
    except KeyboardInterrupt:
        finished = sum(1 for task in tasks if _load_task(out, task, run_id) is not None)
        stop("interrupted", finished_tasks=finished)
        raise RunInterrupted(out, finished, len(tasks)) from None
    except BaseException as exc:
        stop("failed", error=_one_line(f"{type(exc).__name__}: {exc}"))
        raise
    stop("complete", finished_tasks=len(tasks))
    for task in tasks:  # the states of finished jobs are no longer needed
        for path in _task_state_files(out, task):
            path.unlink(missing_ok=True)
    try:
        (out / STATE_DIR).rmdir()
    except OSError:  # not empty (files that are not ours) or absent
        pass
    return results


def _log_done(log, i: int, n: int, output: dict, cfg: ExperimentConfig | None = None) -> None:
    for r in output["records"]:
        if r["role"] != "source":
            log(f"  [{i}/{n}] {r['label']} seed {r['seed']}: {r['epochs']} epochs ({r['stop_reason']}), "
                f"loss {r['returned_loss']:.3e}, {r['wall_time']:.1f} s")
        if cfg is not None:
            advice = divergence_advice(cfg, r)
            if advice:
                log(f"  {advice}")
    for note in output.get("notes", []):
        log(f"  note: {note}")

"""Run an experiment config: train every model for every seed, measure, and write a run directory.

A run directory holds

    config.toml      the config file as given          config.json   the resolved config
    meta.json        versions, seeds, timings          results.json  per-run metrics and training facts
    arrays.npz       evaluation grid, reference, SE and model trajectories (for figures)
    models/          one checkpoint per trained model (with its loss and γ histories)
    tables.*, figures/   written by :mod:`atlasnn.report`

Data flows one way: config → system + models → trainer → solution → metrics → results.json →
report. Independent trainings (one per model and seed; a transfer chain source → target counts
as one) can run in parallel processes.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import json
import multiprocessing
import os
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.experiments.config import MODEL_LABELS, ExperimentConfig, Stage

RESULT_FILES = ("config.toml", "config.json", "meta.json", "results.json", "arrays.npz")


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


def write_json(path: Path, data: Any) -> None:
    """Write JSON atomically (temporary file, then rename)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, default=_json_default, allow_nan=True), encoding="utf-8")
    os.replace(tmp, path)


# ------------------------------------------------------------------------- one task
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
        "wall_time": result.wall_time, "compile_time": result.compile_time,
        "final_loss": result.final_loss, "best_loss": result.best_loss,
        "returned_loss": float(result.history.loss[result.best_epoch]) if result.best_epoch >= 0 else result.final_loss,
        "checkpoint": ckpt,
    }


def run_task(cfg: ExperimentConfig, task: Task, run_dir: str, grids: dict[str, np.ndarray], progress: bool) -> dict:
    """Train one task, save its checkpoint(s), measure it; returns records and trajectories."""
    from atlasnn.checkpoint import save_checkpoint
    from atlasnn.model import MODEL_SCALINGS, make_model
    from atlasnn.solution import Solution
    from atlasnn.train import train
    from atlasnn.transfer import transfer

    system = cfg.system.build()
    z0 = system.initial_state(cfg.system.z0)
    energy0 = float(system.energy(np.asarray(z0, np.float32)))
    with _x64():
        import jax.numpy as jnp

        energy0 = float(system.energy(jnp.asarray(z0, jnp.float64)))
    names = list(system.state_names)
    run_dir = Path(run_dir)
    records, arrays = [], {}

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

    label = f"{MODEL_LABELS.get(task.column, task.column)} seed {task.seed}"
    if task.role == "short":
        st = cfg.stage
        res = train(new_model(task.model, st), system, st.T,
                    st.train.to_train_config(st.T, task.seed, progress), desc=label)
        finish(res, task.column, "short", st, "eval")
    elif task.role == "baseline":
        st = cfg.target
        res = train(new_model("hnn", st), system, st.T,
                    st.train.to_train_config(st.T, task.seed, progress), desc=label)
        finish(res, task.column, "target", st, "eval")
    else:
        src, tgt = cfg.source, cfg.target
        res_src = train(new_model(task.model, src), system, src.T,
                        src.train.to_train_config(src.T, task.seed, progress),
                        desc=f"{MODEL_LABELS[task.model]} source seed {task.seed}")
        finish(res_src, task.model, "source", src, "source")
        res_tgt = transfer(res_src, system, tgt.T,
                           tgt.train.to_train_config(tgt.T, task.seed, progress),
                           thaw=cfg.thaw, carry_adam=cfg.carry_adam, desc=label)
        finish(res_tgt, task.column, "target", tgt, "eval")
    return {"records": records, "arrays": arrays}


class _x64:
    """``with _x64():`` evaluates in float64 (JAX's x64 context)."""

    def __enter__(self):
        import jax

        self._ctx = jax.enable_x64(True)
        self._ctx.__enter__()

    def __exit__(self, *exc):
        return self._ctx.__exit__(*exc)


def _worker_init() -> None:
    # each worker process keeps XLA to one thread pool of its own; nothing to set up yet
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")


# ---------------------------------------------------------------------- the experiment
def prepare_run_dir(out: Path, overwrite: bool) -> None:
    """Create ``out``; refuse an existing run unless ``overwrite`` (and never delete foreign files)."""
    if out.exists():
        if not out.is_dir():
            raise ConfigError(f"output path exists and is not a directory: {out}")
        if any(out.iterdir()) and not overwrite:
            raise ConfigError(f"output directory {out} is not empty; pass --overwrite to reuse it or choose another --out")
    (out / "models").mkdir(parents=True, exist_ok=True)


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
) -> dict[str, Any]:
    """Run every training of ``cfg`` and write the run directory ``out``; returns results."""
    from atlasnn.integrators import REFERENCE_DESCRIPTION, integrate, reference_solution
    from atlasnn import metrics

    seeds = tuple(seeds if seeds is not None else cfg.seeds)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"jobs must be an integer >= 1, got {jobs!r}")
    out = Path(out)
    prepare_run_dir(out, overwrite)
    started = time.time()
    system = cfg.system.build()
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
    if config_text is not None:
        (out / "config.toml").write_text(config_text, encoding="utf-8")
    cfg_dict = dataclasses.asdict(dataclasses.replace(cfg, raw={}))
    write_json(out / "config.json", {"resolved": cfg_dict, "as_given": cfg.raw})
    meta = {"experiment": cfg.name, "quick": quick, "seeds": list(seeds), "jobs": jobs,
            "versions": versions(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)),
            "command": " ".join(sys.argv), "reference": REFERENCE_DESCRIPTION.replace("1e-12", f"{ev.reference_rtol:g}")}
    write_json(out / "meta.json", meta)

    # ---- the trainings
    tasks = plan_tasks(cfg, seeds)
    log(f"{cfg.name}: {len(tasks)} training job(s) ({', '.join(sorted({t.column for t in tasks}))}) "
        f"x seeds {list(seeds)}, jobs={jobs}")
    outputs: list[dict] = []
    if jobs == 1:
        for i, task in enumerate(tasks):
            outputs.append(run_task(cfg, task, str(out), grids, progress))
            _log_done(log, i + 1, len(tasks), outputs[-1])
    else:
        ctx = multiprocessing.get_context("spawn")
        with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init) as pool:
            futures = {pool.submit(run_task, cfg, task, str(out), grids, False): i for i, task in enumerate(tasks)}
            done_out: dict[int, dict] = {}
            for n, fut in enumerate(cf.as_completed(futures)):
                done_out[futures[fut]] = fut.result()
                _log_done(log, n + 1, len(tasks), done_out[futures[fut]])
            outputs = [done_out[i] for i in range(len(tasks))]

    runs = [r for o in outputs for r in o["records"]]
    for o in outputs:
        arrays.update(o["arrays"])
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
        "wall_time_total": time.time() - started,
    }
    np.savez(out / "arrays.npz", **arrays)
    write_json(out / "results.json", results)
    meta["wall_time_total"] = results["wall_time_total"]
    write_json(out / "meta.json", meta)
    log(f"{cfg.name}: trainings done in {results['wall_time_total']:.1f} s; results in {out}")
    if report:
        from atlasnn.render import write_report

        write_report(out)
        log(f"{cfg.name}: tables and figures written to {out}")
    return results


def _log_done(log, i: int, n: int, output: dict) -> None:
    for r in output["records"]:
        if r["role"] == "source":
            continue
        log(f"  [{i}/{n}] {r['label']} seed {r['seed']}: {r['epochs']} epochs ({r['stop_reason']}), "
            f"loss {r['returned_loss']:.3e}, {r['wall_time']:.1f} s")

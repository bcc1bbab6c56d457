"""The training schemes of a run, one table: what each trains, names, checks and how it trains.

A scheme turns the models of a config into table columns and trains one task of them (a batch of
seeds): ``short`` (every model on the experiment's one interval), ``baseline`` (an HNN from scratch
on a transfer experiment's target), ``transfer`` (source → target, γ frozen or thawed) and
``march`` (time-marching on the experiment's interval) and ``solve`` (the float64 collocation
solver, nothing trained). Each is one :class:`Scheme` subclass and
one :data:`SCHEMES` entry; the planner, the memory check, the task runner and the labels all go
through this table instead of testing scheme names.

A trainer receives the task's run (:class:`atlasnn.experiments._task.TaskRun`: the system, the
grids, resume states, saving and measuring) and calls its ``finish``/``finish_march`` per seed.
"""

from __future__ import annotations

import abc
import json
from typing import Any, ClassVar, final

import jax

from atlasnn.checkpoint import load_checkpoint, load_state
from atlasnn.errors import CheckpointError
from atlasnn.experiments._signals import check_interrupt
from atlasnn.experiments._store import one_line, source_state_path, state_path, write_json
from atlasnn.limits import check_training_memory
from atlasnn.nn import make_model, model_kind
from atlasnn.solver import solve_batch
from atlasnn.training import TrainState, march, march_batch, train_batch, transfer_batch

__all__ = ["Scheme", "SCHEMES", "active_schemes", "table_columns", "baseline_column", "column_labels", "column_label"]


def _hook(event: str, task: Any, column: str, state: Any) -> None:
    """A seam for tests: called per seed after every chunk of epochs (``"chunk"``, with the host
    copy of that seed's TrainState), when a transfer source is done (``"source_done"``) and after
    every finished window of a march (``"window"``, with its MarchProgress)."""


def host_state(state) -> TrainState:
    """A training state copied to the host (what is kept and saved between chunks)."""
    return TrainState(jax.device_get(state.model), jax.device_get(state.opt_state),
                      jax.device_get(state.track), int(state.epoch), state.history)


def source_name(model: str) -> str:
    """The name a transfer source's state and checkpoint carry (``atlas_exp_source``)."""
    return f"{model}_source"


class Scheme(abc.ABC):
    """One way of training a model of a config (see the module docstring)."""

    #: the scheme's name: a plan entry's ``role`` and this table's key
    name: ClassVar[str]
    #: the word its columns' labels add to the model's ("" for none): "ATLAS-NN (exp, transfer)"
    word: ClassVar[str]
    #: the ``role`` of the record that fills its table column ("short", "target" or "march")
    record_role: ClassVar[str]

    @abc.abstractmethod
    def models(self, cfg) -> list[str]:
        """The models of ``cfg`` this scheme trains (none when it does not apply)."""

    @abc.abstractmethod
    def column(self, model: str) -> str:
        """The table column of ``model`` trained by this scheme."""

    def label(self, model: str) -> str:
        """The display label of ``model``'s column: "ATLAS-NN (exp, time-marching)"."""
        return model_kind(model).label_with(self.word)

    @abc.abstractmethod
    def stages(self, cfg) -> list[tuple[str, Any]]:
        """(config table, stage) of every interval one training of it trains on, in order."""

    def extra_states(self, model: str) -> tuple[str, ...]:
        """Names of states a training keeps besides its column's (a transfer's finished source)."""
        return ()

    def batch_limit(self, cfg) -> int | None:
        """The most seeds one program can train together (None: no limit)."""
        return None

    def network(self, cfg) -> tuple[int, int]:
        """(width, depth) of its networks."""
        return cfg.width, cfg.depth

    def points(self, cfg) -> list[tuple[str, int]]:
        """(config key, collocation points K) of each of its trainings, for the memory check."""
        out = []
        for table, st in self.stages(cfg):
            own = "n_points" in ((cfg.raw.get(table) or {}).get("train") or {})
            out.append((f"{table}.train.n_points" if own else "train.n_points", st.train.n_points))
        return out

    def epoch_work(self, cfg) -> float:
        """K · width² of its largest training: the size of one epoch, roughly."""
        return max(k for _, k in self.points(cfg)) * float(self.network(cfg)[0]) ** 2

    def check_memory(self, cfg, n_seeds: int, state_dim: int) -> None:
        """Refuse, as one line naming the key, trainings that will not fit in memory."""
        width, depth = self.network(cfg)
        for key, k in self.points(cfg):
            check_training_memory(k, width, depth, state_dim, 1, key=key)
            if n_seeds > 1:  # one seed fits; the batch is what to lower
                check_training_memory(k, width, depth, state_dim, n_seeds, key="execution.seed_batch",
                                      value=n_seeds, advice="one seed fits: lower execution.seed_batch (or --seed-batch)")

    @abc.abstractmethod
    def train(self, run) -> None:
        """Train the task of ``run`` (its seeds as one batch) and finish every seed."""


def _train_alone(run, stage, model_name: str, role: str) -> None:
    """Every seed of the task's column from scratch on ``stage``."""
    task, seeds = run.task, list(run.task.seeds)
    tcs = run.configs(stage, seeds)
    models = run.new_models(model_name, stage, seeds)
    results = run.stage(task.column, seeds, tcs, lambda s0, cb: train_batch(
        models, run.system, stage.T, tcs, resumes=s0, desc=run.label(task.column, seeds), on_chunk=cb))
    for seed, res in zip(seeds, results):
        run.finish(res, task.column, role, stage, "eval", seed)


@final
class Short(Scheme):
    """Every model on the experiment's one interval (the paper's Tables 2 and 4)."""

    name, word, record_role = "short", "", "short"

    def models(self, cfg):
        return list(cfg.models) if cfg.kind == "short" else []

    def column(self, model):
        return model

    def stages(self, cfg):
        return [("interval", cfg.stage)]

    def train(self, run):
        _train_alone(run, run.cfg.stage, run.task.model, "short")


@final
class Baseline(Scheme):
    """The paper's baseline of a transfer experiment: an HNN from scratch on the target."""

    name, word, record_role = "baseline", "baseline", "target"

    def models(self, cfg):
        return ["hnn"] if cfg.kind == "transfer" and cfg.baseline else []

    def column(self, model):
        return f"{model}_baseline"

    def stages(self, cfg):
        return [("target", cfg.target)]

    def train(self, run):
        _train_alone(run, run.cfg.target, run.task.model, "target")


def _load_source(run, seed: int):
    """A finished source of this run (record, returned model, final Adam state), or None."""
    spath = source_state_path(run.run_dir, run.task.model, seed)
    marker = spath.with_suffix(".json")
    if not run.resume or not marker.is_file() or not spath.is_file():
        return None
    try:
        data = json.loads(marker.read_text(encoding="utf-8"))
        if data.get("run_id") != run.run_id:
            return None
        rec = data["record"]
        model = load_checkpoint(run.run_dir / rec["checkpoint"], run.system).model
        opt_state = load_state(spath, run.system).opt_state
    except (OSError, ValueError, KeyError, TypeError, CheckpointError) as exc:
        run.note(seed, f"the saved source of {run.task.column} seed {seed} is not usable ({one_line(exc)}); "
                       "training it again")
        return None
    return rec, model, opt_state


def _train_sources(run, seeds: list[int]) -> dict[int, tuple]:
    """Train the sources of ``seeds``; keep each finished one for an interrupted target."""
    task, src = run.task, run.cfg.source
    src_col = source_name(task.model)
    for s in seeds:  # a target state without its source: that chain starts over
        target_state = state_path(run.run_dir, task.column, s)
        if run.resume and target_state.is_file():
            run.note(s, f"no usable source for the saved target state of {task.column} seed {s}; "
                        "training the chain again")
            target_state.unlink()
    tcs = run.configs(src, seeds)
    models = run.new_models(task.model, src, seeds)
    results = run.stage(src_col, seeds, tcs, lambda s0, cb: train_batch(
        models, run.system, src.T, tcs, resumes=s0, on_chunk=cb,
        desc=f"{run.label(task.model, seeds)} source"))
    done = {}
    for seed, tc, res in zip(seeds, tcs, results):
        rec = run.finish(res, task.model, "source", src, "source", seed)
        spath = source_state_path(run.run_dir, task.model, seed)
        run.keep(spath, host_state(res.state), tc, src_col, seed, rec.wall_time)
        run.write_state(spath)
        write_json(spath.with_suffix(".json"), {"run_id": run.run_id, "record": rec.as_dict()})
        done[seed] = (res.model, res.opt_state)
    for seed in seeds:
        _hook("source_done", task.one(seed), src_col, None)
    check_interrupt()
    return done


@final
class Transfer(Scheme):
    """The paper's transfer: source (γ learned) → target (γ frozen or thawed, Adam carried)."""

    name, word, record_role = "transfer", "transfer", "target"

    def models(self, cfg):
        return list(cfg.models) if cfg.kind == "transfer" else []

    def column(self, model):
        return f"{model}_transfer"

    def stages(self, cfg):
        return [("source", cfg.source), ("target", cfg.target)]

    def extra_states(self, model):
        return (source_name(model),)

    def train(self, run):
        task, cfg, seeds = run.task, run.cfg, list(run.task.seeds)
        sources: dict[int, tuple] = {}
        for s in seeds:
            loaded = _load_source(run, s)
            if loaded is not None:
                rec, model, opt = loaded
                run.out[s]["records"].append(rec)
                sources[s] = (model, opt)
        missing = [s for s in seeds if s not in sources]
        if missing:
            sources.update(_train_sources(run, missing))
        tgt = cfg.target
        tcs = run.configs(tgt, seeds, freeze_gamma=not cfg.thaw)
        if cfg.lr_from_source:  # the release's target ran at the source's lr (its Adam state carried it)
            tcs = [tc.replace(lr=cfg.source.train.lr) for tc in tcs]
        results = run.stage(task.column, seeds, tcs, lambda s0, cb: transfer_batch(
            [sources[s][0] for s in seeds], [sources[s][1] for s in seeds], run.system, tgt.T, tcs,
            thaw=cfg.thaw, carry_adam=cfg.carry_adam, desc=run.label(task.column, seeds), resumes=s0, on_chunk=cb))
        for seed, res in zip(seeds, results):
            run.finish(res, task.column, "target", tgt, "eval", seed)


@final
class March(Scheme):
    """Time-marching on the experiment's interval: every window trains the task's seeds as one
    batch (:func:`atlasnn.training.march_batch`)."""

    name, word, record_role = "march", "time-marching", "march"

    def models(self, cfg):
        return list(cfg.march.models) if cfg.march is not None else []

    def column(self, model):
        return f"{model}_march"

    def stages(self, cfg):
        return [("march", cfg.eval_stage)]

    def network(self, cfg):
        return cfg.march.width, cfg.march.depth

    def points(self, cfg):
        return [("march.train.n_points", cfg.march.scheme.train.n_points)]

    def batch_limit(self, cfg) -> int | None:
        """Adaptive windows differ per seed: their seeds train one at a time."""
        return 1 if cfg.march.scheme.adaptive else None

    def train(self, run):
        task, cfg, seeds = run.task, run.cfg, list(run.task.seeds)
        m, st = cfg.march, cfg.eval_stage
        models = [make_model(run.z0, scaling=task.model, width=m.width, depth=m.depth, t0=st.t0,
                             gamma=cfg.gamma_init.get(task.model), activation=m.activation,
                             first_layer_scale=m.first_layer_scale, seed=s) for s in seeds]

        def seeded(tc, s):
            return None if tc is None else tc.replace(seed=s, progress=run.progress)

        schemes = [m.scheme.replace(train=seeded(m.scheme.train, s), first=seeded(m.scheme.first, s)) for s in seeds]
        paths = [state_path(run.run_dir, task.column, s) for s in seeds]
        if m.scheme.adaptive:  # every seed gets windows of its own: one after the other
            for seed, path, model, scheme in zip(seeds, paths, models, schemes):
                saved = run.load_march([path], [seed])
                sol = march(model, run.system, st.T, scheme, on_chunk=lambda states: check_interrupt(),
                            resume=None if saved is None else saved[0],
                            on_progress=lambda p, keep=run.march_saver([path], [seed]): keep([p]))
                run.finish_march(sol, scheme, st, seed)
            return
        solutions = march_batch(models, run.system, st.T, schemes, on_chunk=lambda states: check_interrupt(),
                                resume=run.load_march(paths, seeds), on_progress=run.march_saver(paths, seeds))
        for seed, sol, scheme in zip(seeds, solutions, schemes):
            run.finish_march(sol, scheme, st, seed)


@final
class Solve(Scheme):
    """The solver of :func:`atlasnn.solve` ([solve]: the Gauss collocation by default), nothing
    trained: the task's seeds marched by one compiled program (a Collocation solver draws its
    random features from each seed; the Gauss collocation is deterministic, so it is solved once
    and every seed records that one solution)."""

    name, word, record_role = "solve", "", "solve"

    def models(self, cfg):
        return [cfg.solve.solver.name] if cfg.solve is not None else []

    def column(self, model):
        return model

    def label(self, model):
        return {"gauss": "Gauss collocation (float64)", "collocation": "Collocation (float64)"}.get(model, model)

    def stages(self, cfg):
        return [("solve", cfg.eval_stage)]

    def points(self, cfg):
        return []

    def epoch_work(self, cfg) -> float:
        return 0.0  # no epochs: a batch of seeds is one small program

    def check_memory(self, cfg, n_seeds, state_dim):
        return None  # a window's system is small: far below any limit

    def train(self, run):
        solver, st, seeds = run.cfg.solve.solver, run.cfg.eval_stage, list(run.task.seeds)
        if hasattr(solver, "seed"):
            sols = solve_batch(run.system, [run.z0] * len(seeds), (st.t0, st.T), solver=solver, seeds=seeds)
        else:
            sols = solve_batch(run.system, [run.z0], (st.t0, st.T), solver=solver) * len(seeds)
        check_interrupt()
        for seed, sol in zip(seeds, sols):
            run.finish_solve(sol, st, seed)


#: name -> scheme, in table order (a transfer run: baseline, transfers, marches, the solver).
SCHEMES: dict[str, Scheme] = {s.name: s for s in (Baseline(), Short(), Transfer(), March(), Solve())}


def active_schemes(cfg) -> list[Scheme]:
    """The schemes ``cfg`` runs, in table order (its ``schemes`` key, default all)."""
    chosen = getattr(cfg, "schemes", None)
    return [s for s in SCHEMES.values() if chosen is None or s.name in chosen]


def column_label(model: str, scheme: str) -> str:
    """The display label of ``model`` trained by ``scheme``: "ATLAS-NN (exp, time-marching)"."""
    return SCHEMES[scheme].label(model)


def table_columns(cfg) -> list[str]:
    """Table columns: SE, then every scheme's models (transfer: baseline HNN, the transferred
    models, the marched ones, the solver)."""
    return ["se"] + [s.column(m) for s in active_schemes(cfg) for m in s.models(cfg)]


def column_labels(cfg) -> dict[str, str]:
    """column -> label of every table column of ``cfg``."""
    out = {"se": "SE"}
    for s in active_schemes(cfg):
        out.update({s.column(m): s.label(m) for m in s.models(cfg)})
    return out


def baseline_column(cfg) -> str:
    """The column improvements are measured against: the (baseline) HNN when there is one,
    else the first network column."""
    networks = table_columns(cfg)[1:]
    for preferred in ("hnn_baseline", "hnn", "hnn_transfer"):
        if preferred in networks:
            return preferred
    return networks[0]

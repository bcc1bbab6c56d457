"""Running bundle and inverse experiments: every seed, the records, the figures, a summary.

A bundle run trains one bundle per seed, saves it (``models/bundle_seedS.npz``), measures it on a
held-out set of members (drawn with ``test_seed``, the same for every seed) against DOP853
references, and times a 10⁵-member × 100-time evaluation. An inverse run fits the unknowns per
seed with each method of ``[fit] methods`` on the same data (synthetic data: a new noise draw per
seed) and records estimate, standard error, error against the truth and time. Both write
``results.json``, ``summary.md`` and ``figures/``.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from atlasnn.checkpoint import save_bundle, save_flowmap
from atlasnn.errors import AtlasError
from atlasnn.evaluation import reference_members
from atlasnn.experiments._family_seeds import (
    check_resumable_family,
    check_same_problem,
    finish_partial,
    in_process,
    jsonable,
    run_seeds,
    start_partial,
)
from atlasnn.experiments._store import check_run_dir
from atlasnn.experiments.config import parse_family, read_config
from atlasnn.experiments.config._family import FamilyConfig
from atlasnn.fileio import write_json, write_text
from atlasnn.inverse import FitResult, check_shooting_inputs, fit, judge_fit, predict_fit, synthetic_observations
from atlasnn.observations import Observations, load_observations
import atlasnn.report as report  # its figure functions load matplotlib when first used
from atlasnn.solutions import window_edges
from atlasnn.solver import solve_bundle
from atlasnn.training import train_bundle
from atlasnn.version import __version__

__all__ = ["run_family", "load_resumable_family", "rewrite_family_summary", "EVAL_MEMBERS", "EVAL_TIMES"]

#: the evaluation-cost measurement: members × times
EVAL_MEMBERS, EVAL_TIMES = 100_000, 100


def run_family(cfg: FamilyConfig, out: str | Path, *, overwrite: bool = False, log: Callable[[str], None] = print,
               config_text: str | None = None, progress: bool = True, resume: bool = False, jobs: int = 1,
               scheduler: str | None = None) -> dict[str, Any]:
    """Run a bundle or inverse experiment into ``out``; returns the results dict. ``progress``:
    the lines said while a phase goes (a bundle's epochs and windows, "fitting …") are printed
    when the seeds run in this process; the results' lines are printed either way. The seeds run
    as tasks of the run's executor (``jobs`` local processes, or the Dask ``scheduler``'s
    workers), each kept in ``out/partial/`` as it finishes; ``resume``: continue a run in ``out``
    that was interrupted, from the seeds it kept (``cfg`` must resolve as the one it ran, or the
    resume is refused: :func:`load_resumable_family` reads it from the run's own copy)."""
    out = Path(out)
    if resume:
        check_same_problem(out, _problem(cfg))
    else:
        check_run_dir(out, overwrite)
    system = cfg.system.build()
    if cfg.kind == "inverse":  # bad input is refused before anything is written or run
        obs, t0 = _observations(cfg, system, cfg.seeds[0])
        check_shooting_inputs(system, obs, cfg.unknowns, t0=t0, segments=cfg.fit.segments)
    out.mkdir(parents=True, exist_ok=True)
    if not resume:
        if config_text is not None:
            write_text(out / "config.toml", config_text)
        start_partial(out, cfg.source, cfg.quick, cfg.seeds, _problem(cfg))
    say = print if progress and in_process(jobs, scheduler) else _silent
    runner = _run_bundle if cfg.kind == "bundle" else _run_inverse
    results = runner(cfg, system, out, log, say, {"jobs": jobs, "scheduler": scheduler})
    results.update({"kind": cfg.kind, "name": cfg.name, "description": cfg.description, "quick": cfg.quick,
                    "atlasnn_version": __version__, "system": system.describe()})
    write_json(out / "results.json", results)
    write_text(out / "summary.md", _summary(results))
    finish_partial(out)
    log(f"wrote {out / 'results.json'} and {out / 'summary.md'}")
    return results


def _problem(cfg: FamilyConfig) -> Any:
    """What a run's seeds compute, as JSON: the resolved config without where it was read from
    (an observation file by its absolute path)."""
    problem = jsonable(dataclasses.asdict(dataclasses.replace(cfg, source="")))
    if problem.get("observations") and problem["observations"].get("file"):
        problem["observations"]["file"] = str(Path(problem["observations"]["file"]).resolve())
    return problem


def load_resumable_family(out: str | Path, log: Callable[[str], None] = print) -> FamilyConfig:
    """The config of the unfinished bundle or inverse run in ``out``, as it was started: the run's
    own copy ``config.toml`` (paths in it relative to the original file's folder), its --quick
    flag and its seeds. A changed original is ignored, with a note; a changed copy is refused
    by :func:`run_family`."""
    out = Path(out)
    started = check_resumable_family(out)
    original, copy = Path(started.get("config", "config.toml")), out / "config.toml"
    read = copy if copy.is_file() else original
    cfg = parse_family(read_config(read), source=str(original), quick=bool(started.get("quick")))
    try:
        changed = read == copy and original.is_file() and original.read_bytes() != copy.read_bytes()
    except OSError:
        changed = False
    if changed:
        log(f"note: {original} changed since the run started; the run resumes with its own copy {copy}")
    return dataclasses.replace(cfg, seeds=tuple(started["seeds"]))


# ------------------------------------------------------------------------------ bundles
def _max_err(pred: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(members, times): the max over state components of |ẑ − z_ref|."""
    return np.max(np.abs(pred - ref), axis=-1)


def _silent(_line: str) -> None:
    """The progress log of a run with progress off."""


def _run_bundle(cfg: FamilyConfig, system, out: Path, log, say, executor: dict) -> dict[str, Any]:
    st = cfg.bundle
    box = st.box(system)
    z_test, l_test = box.draw(np.random.default_rng(st.test_seed), st.test_members)
    t_test = np.linspace(box.t0, box.T, st.test_times)
    start = time.perf_counter()
    ref = reference_members(system, box, z_test, l_test, t_test)
    ref_time = time.perf_counter() - start
    log(f"{cfg.name}: references of {st.test_members} held-out members in {ref_time:.1f} s")
    (out / "models").mkdir(exist_ok=True)
    work = functools.partial(_bundle_seed, cfg, (t_test, z_test, l_test, ref), out, say)
    outputs = run_seeds(cfg.seeds, work, out, cfg.name, log, **executor)
    seeds = {str(s): o["record"] for s, o in outputs.items()}
    errors = {s: np.asarray(o["errors"]) for s, o in outputs.items()}
    labels = [*(f"{n}(0)" for n in system.state_names), *box.param_names]
    inputs = np.concatenate([z_test, l_test], axis=1)
    varying = [i for i in range(inputs.shape[1]) if np.ptp(inputs[:, i]) > 0]
    order = sorted(varying, key=lambda i: -np.ptp(inputs[:, i]) / max(np.abs(inputs[:, i]).max(), 1e-300))
    first = cfg.seeds[0]
    figs = [*report.plot_bundle_map(inputs[:, order[:2]], [labels[i] for i in order[:2]], errors[first].max(axis=1),
                             out / "figures" / "bundle_map", f"seed {first}: held-out max error per member"),
            *report.plot_bundle_errors(t_test, errors, out / "figures" / "bundle_errors", edges=_edges(st, box))]
    medians = [v["test"]["median"] for v in seeds.values()]
    worsts = [v["test"]["worst"] for v in seeds.values()]
    return {"box": box.describe(), "settings": jsonable(dataclasses.asdict(st)), "seeds": seeds,
            "test_members": st.test_members, "test_times": st.test_times, "reference_seconds": ref_time,
            "eval_members": EVAL_MEMBERS, "eval_times": EVAL_TIMES,
            "overall": {"median_of_medians": float(np.median(medians)), "worst_median": float(max(medians)),
                        "worst_of_worst": float(max(worsts)),
                        "train_time_median": float(np.median([v["train_time"] for v in seeds.values()])),
                        "eval_seconds_max": float(max(v["eval_seconds"] for v in seeds.values()))},
            "figures": [str(p.relative_to(out)) for p in figs]}


def _bundle_seed(cfg: FamilyConfig, test, out: Path, say, seed: int) -> dict[str, Any]:
    """Train (or solve), save and measure one seed's bundle: its record, its held-out errors and
    the line that reports them (a seed task: it may run in another process)."""
    st = cfg.bundle
    system = cfg.system.build()
    box = st.box(system)
    t_test, z_test, l_test, ref = test
    z_eval, l_eval = box.draw(np.random.default_rng(st.test_seed + 1), EVAL_MEMBERS)
    timed = (np.linspace(box.t0, box.T, EVAL_TIMES), z_eval, l_eval)

    def progress(k, epoch, loss):
        if epoch % max(st.epochs // 2, 1) == 0 or epoch == st.epochs:
            say(f"  seed {seed} window {k + 1}/{st.windows}: epoch {epoch}, loss {loss:.3g}")

    def window_done(k, loss, seconds):
        say(f"  seed {seed} window {k + 1}/{st.windows} done: loss {loss:.3g}, {seconds:.0f} s so far")

    if st.method == "flowmap":
        sol = solve_bundle(system, box, st.flowmap, seed=seed, progress=say)
        save_flowmap(out / "models" / f"flowmap_seed{seed}.npz", sol, extra={"seed": seed, "config": cfg.name})
        training = {"train_time": sol.info["seconds"], "compile_time": 0.0,
                    "final_loss": [sol.info["residual_rms"]], "lm_loss": [], "lm_stop": [], "retried": [],
                    "flowmap": sol.info}
    else:
        trained = train_bundle(system, box, st.train_config(), scaling=st.model, width=st.width, depth=st.depth,
                               seed=seed, progress=progress, on_window=window_done)
        sol = trained.solution
        save_bundle(out / "models" / f"bundle_seed{seed}.npz", sol, extra={"seed": seed, "config": cfg.name})
        training = {"train_time": trained.train_time, "compile_time": trained.compile_time,
                    "final_loss": [float(a[-1]) if a.size else None for a in trained.adam_loss],
                    "lm_loss": [float(a[-1]) if a.size else None for a in trained.lm_loss],
                    "lm_stop": trained.lm_stop, "retried": trained.retried}
    err = _max_err(sol(t_test, z_test, l_test), ref)
    per_member = err.max(axis=1)
    timings = []
    for _ in range(2):
        s = time.perf_counter()
        sol(*timed)
        timings.append(time.perf_counter() - s)
    start_values = sol(np.asarray([box.t0]), z_test, l_test)[:, 0]
    exact = float(np.abs(start_values - z_test.astype(start_values.dtype)).max())
    record = {
        **training,
        "test": {"median": float(np.median(per_member)), "worst": float(per_member.max()),
                 "p90": float(np.quantile(per_member, 0.9)), "per_member": per_member.tolist()},
        "eval_seconds_first": timings[0], "eval_seconds": timings[1], "initial_state_error": exact,
    }
    line = (f"  seed {seed}: {'solved' if st.method == 'flowmap' else 'trained'} in {record['train_time']:.1f} s; "
            f"held-out max error median {np.median(per_member):.3g}, worst {per_member.max():.3g}; "
            f"{EVAL_MEMBERS} members x {EVAL_TIMES} times in {timings[1]:.2f} s")
    return {"record": record, "errors": err.tolist(), "lines": [line]}


def _edges(st, box) -> list[float]:
    """The window edges the figures mark (a flow map's windows are too many to draw)."""
    return [] if st.method == "flowmap" else list(window_edges(box.t0, box.T, st.windows))


# ------------------------------------------------------------------------------ inverse
def _observations(cfg: FamilyConfig, system, seed: int) -> tuple[Observations, float]:
    ob = cfg.observations
    if ob.file is not None:
        return load_observations(ob.file), ob.t0
    times = np.sort(np.random.default_rng(ob.times_seed).uniform(ob.t0, ob.T, ob.n))
    return synthetic_observations(system, system.initial_state(), times, list(ob.names), ob.noise, seed,
                                  t0=ob.t0), ob.t0


def _truth(cfg: FamilyConfig, system) -> dict[str, float] | None:
    if cfg.observations.file is not None:
        return None
    z0 = system.initial_state()
    return {u.name: (float(z0[system.state_names.index(u.component)]) if u.is_initial_state
                     else float(system.params[u.name])) for u in cfg.unknowns}


def _record(result, method: str, seed: int, training: float, truth: dict | None) -> dict[str, Any]:
    rec = {**result.as_dict(), "fit_method": result.method, "seed": seed, "method": method,
           "training_seconds": training, "total_seconds": result.wall_time + training}
    if truth is not None:
        err = np.asarray([result.value(n) - truth[n] for n in result.names])
        sigma = np.where(np.isfinite(result.std), result.std, np.inf)
        rec["error"] = err.tolist()
        rec["rel_error"] = (err / np.maximum(np.abs([truth[n] for n in result.names]), 1e-300)).tolist()
        rec["covered_2sigma"] = bool(np.all(np.abs(err) <= 2 * sigma))
        rec["confident_wrong"] = bool(result.trusted and np.any(np.abs(err) > 4 * sigma))
    return rec


def _fit_line(seed: int, method: str, result, rec: dict) -> str:
    line = f"  seed {seed} {method}: " + ", ".join(f"{n} = {v:.6g} ± {s:.2g}" for n, v, s in
                                                   zip(result.names, result.estimate, result.std))
    line += f" in {rec['total_seconds']:.2f} s"
    if "error" in rec:
        line += f" (error {', '.join(f'{e:.2g}' for e in rec['error'])})"
    return line + ("" if result.trusted else f" — UNTRUSTED: {result.notes[-1]}")


def _fit_seed(cfg: FamilyConfig, truth, say, seed: int) -> dict[str, Any]:
    """Every method on one seed's data, each through :func:`atlasnn.inverse.fit` (a seed task: it
    may run in another process): the records (a method that fails is a record saying so, and the
    others go on), the data's description and the lines that report them; every fit is
    cross-checked against the better of the two searches (shooting's multistart, the collocation fit)."""
    system = cfg.system.build()
    obs, t0 = _observations(cfg, system, seed)
    fits, records, lines = {}, [], []
    log = lines.append
    for way in cfg.fit.method_objects():
        method = way.name
        say(f"  seed {seed} {method}: fitting ({way.describe(cfg.unknowns)})…")
        try:
            result = fit(system, obs, cfg.unknowns, method=way, t0=t0, seed=seed)
            fits[method] = (result, float(result.search.get("training_seconds", 0.0)))
        except AtlasError as exc:
            records.append({"seed": seed, "method": method, "failed": str(exc), "trusted": False,
                            "names": [u.name for u in cfg.unknowns]})
            log(f"  seed {seed} {method}: FAILED — {exc}")
    for method, (result, training) in fits.items():
        # each fit against the best other trusted fit of the two searches, shooting's multistart and
        # the collocation fit (the rules are idempotent: a fit already judged gains no repeated note)
        others = [fits[m][0] for m in ("shooting", "collocation") if m in fits and m != method and fits[m][0].trusted]
        better = min(others, key=lambda f: f.noise_estimate) if others else None
        judge_fit(result, cfg.unknowns, system=system, observations=obs, better=better)
        rec = _record(result, method, seed, training, truth)
        records.append(rec)
        log(_fit_line(seed, method, result, rec))
    return {"records": records, "observations": obs.describe(), "lines": lines}


def _run_inverse(cfg: FamilyConfig, system, out: Path, log, say, executor: dict) -> dict[str, Any]:
    truth = _truth(cfg, system)
    outputs = run_seeds(cfg.seeds, functools.partial(_fit_seed, cfg, truth, say), out, cfg.name, log, **executor)
    records = [r for o in outputs.values() for r in o["records"]]
    seeds = {str(s): {"observations": o["observations"]} for s, o in outputs.items()}
    first = cfg.seeds[0]
    first_obs = _observations(cfg, system, first)
    # the first seed's fits, read back from its records (they may come from another process)
    curves = {r["method"]: FitResult.from_dict({**r, "method": r["fit_method"]})
              for r in outputs[first]["records"] if "failed" not in r}
    notes: list[str] = []
    figs = _inverse_figures(cfg, system, out, records, truth, first_obs, curves, notes)
    for note in notes:
        log(f"  note: {note}")
    done = [r for r in records if "failed" not in r]
    return {"truth": truth, "unknowns": [u.__dict__ for u in cfg.unknowns], "records": records, "seeds": seeds,
            "methods": list(cfg.fit.methods), "figures": [str(p.relative_to(out)) for p in figs], "notes": notes,
            "overall": _inverse_overall(done, list(cfg.fit.methods))}


def _inverse_figures(cfg, system, out: Path, records, truth, first_obs, curves, notes: list[str]) -> list[Path]:
    """The estimates per unknown and the first seed's fitted trajectories; a figure that cannot be
    drawn (e.g. an orbit that cannot be integrated at a wrong estimate) is a note, not a failure."""
    figs: list[Path] = []
    done = [r for r in records if "failed" not in r]
    for j, u in enumerate(cfg.unknowns):
        rows = [{"seed": r["seed"], "method": r["method"], "estimate": r["estimate"][j], "std": r["std"][j],
                 "trusted": r.get("trusted", True)} for r in done]
        try:
            figs += report.plot_estimates(rows, u.name, None if truth is None else truth[u.name],
                                   out / "figures" / f"estimates_{u.name.replace('.', '_')}")
        except Exception as exc:  # noqa: BLE001 - the fits are kept whatever a figure does
            notes.append(f"figure estimates_{u.name} not drawn: {exc}")
    obs, t0 = first_obs
    t = np.linspace(t0, float(obs.t[-1]), 400)
    cols = obs.indices(system.state_names)
    traj = {}
    for m, r in curves.items():
        try:
            traj[m] = predict_fit(system, r, None, t)[:, cols]
        except AtlasError as exc:
            notes.append(f"the {m} fit's trajectory is not drawn: {exc}")
    try:
        figs += report.plot_fit_trajectory(obs.t, obs.values, obs.names, t, traj, out / "figures" / "fit_trajectory")
    except Exception as exc:  # noqa: BLE001
        notes.append(f"figure fit_trajectory not drawn: {exc}")
    return figs


def _inverse_overall(records, methods) -> dict[str, Any]:
    out = {}
    for m in methods:
        rs = [r for r in records if r["method"] == m]
        if not rs:  # the method failed on every seed: its records say why
            continue
        est = np.asarray([r["estimate"] for r in rs], float)
        row = {"seconds_median": float(np.median([r["total_seconds"] for r in rs])),
               "seconds_max": float(max(r["total_seconds"] for r in rs)),
               "estimate_mean": est.mean(axis=0).tolist(),
               "estimate_sd_over_seeds": (est.std(axis=0, ddof=1) if len(rs) > 1 else est[0] * np.nan).tolist(),
               "std_median": np.median([r["std"] for r in rs], axis=0).tolist()}
        if rs and "rel_error" in rs[0]:
            rel = np.abs(np.asarray([r["rel_error"] for r in rs]))
            row.update({"rel_error_median": float(np.median(rel)), "rel_error_max": float(rel.max()),
                        "covered_2sigma": int(sum(r["covered_2sigma"] for r in rs)), "n": len(rs)})
        out[m] = row
    return out


# ------------------------------------------------------------------------------ summary
def rewrite_family_summary(out: str | Path) -> Path:
    """Recompute an inverse run's per-method overview from its records and rewrite summary.md
    (``atlasnn report DIR`` on a bundle or inverse run)."""
    out = Path(out)
    results = json.loads((out / "results.json").read_text())
    if results.get("kind") == "inverse":
        results["overall"] = _inverse_overall([r for r in results["records"] if "failed" not in r], results["methods"])
        write_json(out / "results.json", results)
    write_text(out / "summary.md", _summary(results))
    return out / "summary.md"


def _summary(results: dict[str, Any]) -> str:
    lines = [f"# {results['name']}", "", results.get("description", ""), ""]
    if results.get("quick"):
        lines += ["**Quick run (--quick): budgets capped; the numbers are a smoke test, not results.**", ""]
    if results["kind"] == "bundle":
        # a flow map states its own error estimate (no reference): shown beside the measured one
        estimated = all("estimated_error" in v.get("flowmap", {}) for v in results["seeds"].values())
        lines += ["| seed | train s | held-out median max err | worst | " + ("estimated worst (no reference) | " if
                  estimated else "") + "1e5 x 100 eval s | ẑ(t0) − z0 |", "|---|---|---|---|" + "---|" * (3 if estimated else 2)]
        for s, v in results["seeds"].items():
            est = f" {v['flowmap']['estimated_error']:.3g} |" if estimated else ""
            lines.append(f"| {s} | {v['train_time']:.1f} | {v['test']['median']:.3g} | {v['test']['worst']:.3g} |{est} "
                         f"{v['eval_seconds']:.2f} | {v['initial_state_error']:.1g} |")
        o = results["overall"]
        lines += ["", f"Median of the seeds' medians {o['median_of_medians']:.3g}; worst seed median "
                  f"{o['worst_median']:.3g}; worst member over all seeds {o['worst_of_worst']:.3g} "
                  f"({results['test_members']} held-out members, {results['test_times']} times, against DOP853 "
                  "at 1e-12)."]
    else:
        names = [u["name"] for u in results["unknowns"]]
        head = "| seed | method | " + " | ".join(f"{n} ± σ" for n in names) + " | rel. error | within 2σ | trusted | s |"
        lines += [head, "|" + "---|" * (6 + len(names))]
        for r in results["records"]:
            if "failed" in r:
                lines.append(f"| {r['seed']} | {r['method']} | " + " | ".join("—" for _ in names)
                             + " | — | — | **failed** | — |")
                continue
            est = " | ".join(f"{e:.6g} ± {s:.2g}" for e, s in zip(r["estimate"], r["std"]))
            # observations from a file have no truth: no error to show
            rel = ", ".join(f"{abs(e):.2g}" for e in r["rel_error"]) if "rel_error" in r else "— (no truth)"
            trusted = "yes" if r.get("trusted", True) else "**no**"
            lines.append(f"| {r['seed']} | {r['method']} | {est} | {rel} | {r.get('covered_2sigma', '—')} | "
                         f"{trusted} | {r['total_seconds']:.2f} |")
        warned = [r for r in results["records"] if "failed" in r or not r.get("trusted", True)]
        if warned:
            lines += ["", "Not to be trusted (the estimate or its σ), and why:", ""]
            for r in warned:
                why = r["failed"] if "failed" in r else "; ".join(r.get("notes") or ["(no reason recorded)"])
                lines.append(f"- seed {r['seed']} {r['method']}: {why}")
        lines += ["", "| method | mean estimate | sd over seeds | median σ (Gauss–Newton) | within 2σ | median s |",
                  "|---|---|---|---|---|---|"]
        for m, o in results["overall"].items():
            fmt = lambda v: ", ".join(f"{x:.3g}" if np.isfinite(x) else "—" for x in v)  # noqa: E731  (one seed: no sd)
            lines.append(f"| {m} | {', '.join(f'{x:.6g}' for x in o['estimate_mean'])} | "
                         f"{fmt(o['estimate_sd_over_seeds'])} | {fmt(o['std_median'])} | "
                         + (f"{o['covered_2sigma']}/{o['n']}" if "covered_2sigma" in o else "— (no truth)")
                         + f" | {o['seconds_median']:.2f} |")
    if results.get("notes"):
        lines += ["", "Notes:", ""] + [f"- {n}" for n in results["notes"]]
    return "\n".join(lines) + "\n"

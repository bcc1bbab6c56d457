"""Measuring a run: the reference on its grids, the classical integrators of its table, work–precision.

Everything here is deterministic and runs in float64 (the reference solver and the integrators
always do; energies of predicted states are evaluated in float64 too).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from atlasnn.evaluation import TrainingRecord, blow_up_index, error_metrics, integrate, reference_solutions
from atlasnn.evaluation import workprecision as wp
from atlasnn.checkpoint import load_checkpoint, load_piecewise
from atlasnn.experiments.config import ExperimentConfig
from atlasnn.experiments._plan import eval_grid


def reference_grids(cfg: ExperimentConfig, system, z0: np.ndarray,
                    also: list[np.ndarray] = ()) -> tuple[dict[str, np.ndarray], list[np.ndarray]]:
    """The evaluation grid of the table (``eval``; target interval for transfer) and, for a
    transfer experiment, of the source interval (``source``, as many points per unit time), each
    with the reference solution on it (``eval_ref``, ``source_ref``); and the reference on each
    grid of ``also`` (the integrators' own). One DOP853 solve per interval serves every grid on it."""
    st, ev = cfg.eval_stage, cfg.evaluation
    grids = {"eval": eval_grid(st, ev.eval_points)}
    if cfg.kind == "transfer":
        src = cfg.source
        points = ev.eval_points and max(2, round(ev.eval_points * (src.T - src.t0) / (st.T - st.t0)))
        grids["source"] = eval_grid(src, points)
    names = list(grids)
    refs = reference_solutions(system, z0, [grids[k] for k in names] + list(also),
                               rtol=ev.reference_rtol, atol=ev.reference_atol)
    grids.update({f"{k}_ref": z for k, z in zip(names, refs)})
    return grids, refs[len(names):]


def _quiet_metrics(t, z, z_ref, names, energy, e0) -> dict:
    """error_metrics without NumPy's overflow warnings: a blown-up integrator's errors are inf or
    NaN by design (reported n/a, with the time it blew up)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return error_metrics(t, z, z_ref, names, energy, e0)


def integrator_runs(cfg: ExperimentConfig, system, z0: np.ndarray,
                    log: Callable[[str], None]) -> list[tuple[str, str, int, np.ndarray, np.ndarray]]:
    """The classical integrators of the table, run: SE with K − 1 steps, the fine SE, and any
    extra ones the config names, as (column, method, steps, t, z).

    A Hamiltonian not declared separable gets none of them, and one line saying so."""
    st, ev = cfg.eval_stage, cfg.evaluation
    steps = ev.se_steps or (st.train.n_points - 1)
    methods = [("se", "symplectic_euler", steps),
               (f"se_{ev.fine_factor}", "symplectic_euler", steps * ev.fine_factor)]
    methods += [(m, m, steps) for m in ev.integrators if m != "symplectic_euler"]
    if not system.separable:
        log(f"skipping the classical integrators ({', '.join(sorted({m for _, m, _ in methods}))}): "
            "the Hamiltonian is not declared separable")
        return []
    return [(column, method, n, *integrate(method, system, z0, st.t0, st.T, n)) for column, method, n in methods]


def integrator_rows(cfg: ExperimentConfig, system, runs, refs: list[np.ndarray], e0: float,
                    log: Callable[[str], None]) -> tuple[list[dict], dict[str, np.ndarray]]:
    """The metrics (rows) and trajectories (arrays for the figures) of :func:`integrator_runs`'
    runs against the reference on their grids (``refs``, in the same order)."""
    st, ev = cfg.eval_stage, cfg.evaluation
    names = list(system.state_names)
    rows, arrays = [], {}
    for (column, method, n, t, z), z_ref in zip(runs, refs):
        energy = system.energy64(z)
        label = "SE" if column == "se" else (f"SE-{ev.fine_factor}" if column.startswith("se_") else column)
        bad = blow_up_index(z, z_ref)
        blew_up = None if bad is None else float(t[bad])
        if blew_up is not None:
            log(f"{label} ({method}, {n} steps) blew up at t = {blew_up:.4g}: its step {(st.T - st.t0) / n:.3g} is "
                "too large for this system (more steps: evaluation.se_steps)")
        rows.append({"column": column, "label": label, "method": method, "steps": n, "blew_up_at": blew_up,
                     "metrics": _quiet_metrics(t, z, z_ref, names, energy, e0)})
        arrays.update({f"int_t_{column}": t, f"int_z_{column}": z, f"int_zref_{column}": z_ref,
                       f"int_energy_{column}": energy})
    return rows, arrays


def work_precision(cfg: ExperimentConfig, system, z0: np.ndarray, grids: dict[str, np.ndarray], runs: list[dict],
                   run_dir, log: Callable[[str], None]) -> dict[str, Any]:
    """The run's work–precision comparison (:mod:`atlasnn.evaluation._workprecision`): the classical methods
    measured now on the table's grid, every tabulated training as a point (its training wall time
    and its errors on that grid), the time to evaluate one solution per network column at 10⁴
    times, and one line per training saying which classical setting is as accurate, at what cost."""
    t, z_ref = grids["eval"], grids["eval_ref"]
    names = list(system.state_names)
    log(f"{cfg.name}: measuring the classical methods' cost against accuracy (work–precision)")
    points = wp.dop853_points(system, z0, t, z_ref)
    if system.separable:
        points = wp.symplectic_points(system, z0, t, z_ref) + points
    evaluation = {}
    records = [TrainingRecord.from_dict(r) for r in runs]
    source_wall = {(r.model, r.seed): r.wall_time for r in records if r.role == "source"}
    for r in (r for r in records if r.in_table):
        # a transfer's cost: its source and its target (a time-marched or baseline column has no source)
        wall = r.wall_time + (source_wall.get((r.model, r.seed), 0.0) if r.role == "target" else 0.0)
        points.append(wp.WorkPoint(r.label, f"seed {r.seed}", wall, max(r.metric("max_abs", n) for n in names),
                                   r.metric("l2_discrete", names[0]), r.metric("energy_drift"), kind="network"))
        if r.label not in evaluation:
            path = Path(run_dir) / r.checkpoint
            sol = load_piecewise(path) if r.march is not None else load_checkpoint(path).solution(outside="allow")
            evaluation[r.label] = wp.evaluation_seconds(sol, float(t[0]), float(t[-1]))
    return {"points": wp.to_json(points), "verdicts": wp.verdicts(points),
            "verdicts_l2": wp.verdicts(points, "l2_first"), "evaluation_seconds_1e4": evaluation,
            "first_state": names[0], "grid_points": int(t.size),
            "note": "classical: one solve, after compilation, median of repeats; networks: training wall time per "
                    "seed as the run measured it (its --jobs and batching; a transfer's source included), "
                    "compilation excluded"}

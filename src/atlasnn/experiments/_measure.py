"""Measuring: the reference solution, the classical integrators, and a trained solution's errors.

Everything here is deterministic and runs in float64 (the reference solver and the integrators
always do; energies of predicted states are evaluated in float64 too).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from atlasnn.evaluation import _metrics as metrics
from atlasnn.experiments.config._config import ExperimentConfig
from atlasnn.experiments._plan import eval_grid


class _x64:
    """``with _x64():`` evaluates in float64 (JAX's x64 context)."""

    def __enter__(self):
        import jax

        self._ctx = jax.enable_x64(True)
        self._ctx.__enter__()

    def __exit__(self, *exc):
        return self._ctx.__exit__(*exc)


def energies(system, z: np.ndarray) -> np.ndarray:
    """H(z) in float64 for states z of shape (..., 2d)."""
    import jax.numpy as jnp

    with _x64():
        return np.asarray(system.energy(jnp.asarray(z, jnp.float64)))


def energy0(system, z0: np.ndarray) -> float:
    """E0 = H(z0) in float64."""
    return float(energies(system, z0))


def error_metrics(t: np.ndarray, z: np.ndarray, z_ref: np.ndarray, names, energy: np.ndarray,
                  e0: float) -> dict[str, Any]:
    """Per-state metrics (``metric → {state: value}``), whole-state metrics and the energy drift."""
    table = metrics.error_table(t, z, z_ref, names)
    per = {m: {n: table["components"][n][m] for n in names} for m in metrics.METRIC_NAMES}
    per["whole"] = table["whole"]
    per["energy_drift"] = metrics.energy_drift(energy, e0)
    return per


def measure_solution(solution, t: np.ndarray, z_ref: np.ndarray, names, e0: float):
    """(metrics, ẑ on t, H(ẑ) on t) of a trained solution against the reference on grid t."""
    z = solution(t).astype(np.float64)
    energy = solution.energy(t)
    return error_metrics(t, z, z_ref, names, energy, e0), z, energy


def reference_grids(cfg: ExperimentConfig, system, z0: np.ndarray) -> dict[str, np.ndarray]:
    """The evaluation grid of the table (``eval``; target interval for transfer) and, for a
    transfer experiment, of the source interval (``source``, as many points per unit time), each
    with the reference solution on it (``eval_ref``, ``source_ref``)."""
    from atlasnn.evaluation._integrators import reference_solution

    st, ev = cfg.eval_stage, cfg.evaluation

    def ref(t):
        return reference_solution(system, z0, t, rtol=ev.reference_rtol, atol=ev.reference_atol)

    t_eval = eval_grid(st, ev.eval_points)
    grids = {"eval": t_eval, "eval_ref": ref(t_eval)}
    if cfg.kind == "transfer":
        src = cfg.source
        points = ev.eval_points and max(2, round(ev.eval_points * (src.T - src.t0) / (st.T - st.t0)))
        grids["source"] = eval_grid(src, points)
        grids["source_ref"] = ref(grids["source"])
    return grids


def integrator_rows(cfg: ExperimentConfig, system, z0: np.ndarray, e0: float,
                    log: Callable[[str], None]) -> tuple[list[dict], dict[str, np.ndarray]]:
    """The classical integrators of the table: SE with K − 1 steps, the fine SE, and any extra
    ones the config names; their metrics (rows) and trajectories (arrays for the figures).

    A Hamiltonian not declared separable gets none of them, and one line saying so."""
    from atlasnn.evaluation._integrators import integrate, reference_solution

    st, ev = cfg.eval_stage, cfg.evaluation
    names = list(system.state_names)
    steps = ev.se_steps or (st.train.n_points - 1)
    methods = [("se", "symplectic_euler", steps),
               (f"se_{ev.fine_factor}", "symplectic_euler", steps * ev.fine_factor)]
    methods += [(m, m, steps) for m in ev.integrators if m != "symplectic_euler"]
    if not system.separable:
        log(f"skipping the classical integrators ({', '.join(sorted({m for _, m, _ in methods}))}): "
            "the Hamiltonian is not declared separable")
        return [], {}
    rows, arrays = [], {}
    for column, method, n in methods:
        t, z = integrate(method, system, z0, st.t0, st.T, n)
        z_ref = reference_solution(system, z0, t, rtol=ev.reference_rtol, atol=ev.reference_atol)
        energy = energies(system, z)
        label = "SE" if column == "se" else (f"SE-{ev.fine_factor}" if column.startswith("se_") else column)
        rows.append({"column": column, "label": label, "method": method, "steps": n,
                     "metrics": error_metrics(t, z, z_ref, names, energy, e0)})
        arrays.update({f"int_t_{column}": t, f"int_z_{column}": z, f"int_zref_{column}": z_ref,
                       f"int_energy_{column}": energy})
    return rows, arrays


def work_precision(cfg: ExperimentConfig, system, z0: np.ndarray, grids: dict[str, np.ndarray], runs: list[dict],
                   run_dir, log: Callable[[str], None]) -> dict[str, Any]:
    """The run's work–precision comparison (:mod:`atlasnn.evaluation._workprecision`): the classical methods
    measured now on the table's grid, every tabulated training as a point (its training wall time
    and its errors on that grid), the time to evaluate one solution per network column at 10⁴
    times, and one line per training saying which classical setting is as accurate, at what cost."""
    from pathlib import Path

    from atlasnn.evaluation import _workprecision as wp
    from atlasnn.checkpoint._single import load_checkpoint, load_piecewise

    t, z_ref = grids["eval"], grids["eval_ref"]
    names = list(system.state_names)
    log(f"{cfg.name}: measuring the classical methods' cost against accuracy (work–precision)")
    points = wp.dop853_points(system, z0, t, z_ref)
    if system.separable:
        points = wp.symplectic_points(system, z0, t, z_ref) + points
    evaluation = {}
    source_wall = {(r["model"], r["seed"]): float(r["wall_time"]) for r in runs if r.get("role") == "source"}
    for r in runs:
        if r.get("role") not in ("short", "target", "march"):
            continue
        m = r["metrics"]
        wall = float(r["wall_time"])
        if r["column"].endswith("_transfer"):  # a transfer's cost is its source's and its target's
            wall += source_wall.get((r["model"], r["seed"]), 0.0)
        points.append(wp.WorkPoint(r["label"], f"seed {r['seed']}", wall,
                                   max(float(m["max_abs"][n]) for n in names), float(m["l2_discrete"][names[0]]),
                                   float(m["energy_drift"]), kind="network"))
        if r["label"] not in evaluation:
            path = Path(run_dir) / r["checkpoint"]
            sol = load_piecewise(path) if r["role"] == "march" else load_checkpoint(path).solution(outside="allow")
            evaluation[r["label"]] = wp.evaluation_seconds(sol, float(t[0]), float(t[-1]))
    return {"points": wp.to_json(points), "verdicts": wp.verdicts(points),
            "verdicts_l2": wp.verdicts(points, "l2_first"), "evaluation_seconds_1e4": evaluation,
            "first_state": names[0], "grid_points": int(t.size),
            "note": "classical: one solve, after compilation, median of repeats; networks: training wall time per "
                    "seed as the run measured it (its --jobs and batching; a transfer's source included), "
                    "compilation excluded"}

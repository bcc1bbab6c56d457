"""Measuring: the reference solution, the classical integrators, and a trained solution's errors.

Everything here is deterministic and runs in float64 (the reference solver and the integrators
always do; energies of predicted states are evaluated in float64 too).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from atlasnn import metrics
from atlasnn.experiments.config import ExperimentConfig
from atlasnn.experiments.plan import eval_grid


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
    from atlasnn.integrators import reference_solution

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
    from atlasnn.integrators import integrate, reference_solution

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

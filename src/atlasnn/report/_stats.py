"""A finished run's ``results.json`` as statistics over seeds (NumPy only: no training, no JAX).

* :func:`load_results` — read a ``results.json`` (path) into a dict (a dict passes through);
* :func:`load_paper` — the paper's numbers (``atlasnn/data/paper_results.json``, transcribed
  from the paper's four results tables): one experiment, or all of them;
* :func:`summarize` — per column, per metric and state: per-seed values, median/min/max/n;
  signed improvement vs the baseline column paired by seed; training statistics and γ; whether
  the run was a quick run and the per-model verdicts of the runs' quality checks.

:mod:`atlasnn.report._tables` turns these into tables.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from importlib import resources
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from atlasnn.report._caveats import column_verdicts
from atlasnn.errors import ConfigError
from atlasnn.evaluation import METRICS, TrainingRecord, state_metric_names
from atlasnn.nn import MODELS

__all__ = ["load_results", "load_paper", "summarize", "column_label", "STATE_METRICS", "SCALAR_METRICS"]

PAPER_FILE = "paper_results.json"

#: the per-state metrics a run may carry, in table order (the registry of atlasnn.evaluation)
STATE_METRICS = state_metric_names()
#: scalar metrics
SCALAR_METRICS = tuple(m.name for m in METRICS.values() if not m.per_state)



# ============================================================================ loading
def load_results(results: Any) -> dict:
    """``results`` as a dict: a mapping is returned as is, a path is read as JSON."""
    if isinstance(results, Mapping):
        return dict(results)
    if isinstance(results, (str, Path)):
        p = Path(results)
        if p.is_dir():
            p = p / "results.json"
        try:
            text = p.read_text(encoding="utf-8")
        except OSError as e:
            raise ConfigError(f"cannot read results file {str(p)!r}: {e.strerror or e}") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise ConfigError(f"results file {str(p)!r} is not valid JSON: {e.msg} at line {e.lineno}") from None
        if not isinstance(data, dict):
            raise ConfigError(f"results file {str(p)!r} must hold a JSON object, got {type(data).__name__}")
        return data
    raise ConfigError(f"results must be a dict or a path to results.json, got {type(results).__name__}")


def load_paper(name: str | None = None) -> dict:
    """The paper's numbers (``atlasnn/data/paper_results.json``).

    With ``name`` (e.g. ``"oscillator-short"``) the entry of that experiment; without, the whole
    file (keys ``source``, ``note``, ``experiments``).
    """
    text = resources.files("atlasnn").joinpath("data", PAPER_FILE).read_text(encoding="utf-8")
    data = json.loads(text)
    if name is None:
        return data
    exps = data["experiments"]
    if name not in exps:
        raise ConfigError(f"the paper has no experiment {name!r}; it has {sorted(exps)}")
    return exps[name]


def _resolve_paper(results: dict, paper: Any) -> dict | None:
    if paper is False:
        return None
    if paper is None:
        name = results.get("paper_experiment") or results.get("experiment")
        data = load_paper()
        return data["experiments"].get(name) if isinstance(name, str) else None
    if isinstance(paper, str):
        return load_paper(paper)
    if isinstance(paper, Mapping):
        if "experiments" in paper:
            return paper["experiments"].get(results.get("experiment"))
        return dict(paper)
    raise ConfigError(f"paper must be None, False, an experiment name or a dict, got {type(paper).__name__}")


# ============================================================================ validation
def _validate(results: dict) -> dict:
    for key in ("experiment", "kind", "state_names", "columns", "baseline"):
        if key not in results:
            raise ConfigError(f"results.json has no {key!r} field")
    if results["kind"] not in ("short", "transfer"):
        raise ConfigError(f"results kind must be 'short' or 'transfer', got {results['kind']!r}")
    cols = results["columns"]
    if not isinstance(cols, list) or not cols or not all(isinstance(c, str) for c in cols):
        raise ConfigError(f"results columns must be a non-empty list of names, got {cols!r}")
    if len(set(cols)) != len(cols):
        raise ConfigError(f"results columns must be distinct, got {cols!r}")
    if results["baseline"] not in cols:
        raise ConfigError(f"results baseline {results['baseline']!r} is not one of the columns {cols}")
    states = results["state_names"]
    if not isinstance(states, list) or not states or not all(isinstance(s, str) for s in states):
        raise ConfigError(f"results state_names must be a non-empty list of names, got {states!r}")
    for what in ("runs", "integrators"):
        v = results.get(what, [])
        if v is None:
            v = []
        if not isinstance(v, list) or not all(isinstance(r, Mapping) for r in v):
            raise ConfigError(f"results {what} must be a list of objects")
    seen = set()
    for i, r in enumerate(results.get("runs") or []):
        if "column" not in r:
            raise ConfigError(f"results runs[{i}] has no 'column' field")
        key = (r["column"], r.get("seed"), r.get("role", "short"))
        if key in seen:
            raise ConfigError(f"results runs[{i}] repeats column {key[0]!r} seed {key[1]!r} role {key[2]!r}")
        seen.add(key)
    return results


# ============================================================================ statistics
def _f(x: Any) -> float | None:
    """A float, or None for missing / non-numeric."""
    if x is None or isinstance(x, bool):
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v


def _stats(values: Sequence[Any], seeds: Sequence[Any] | None = None) -> dict:
    """values (floats or None) -> per-seed values, median/min/max over the finite ones, n."""
    vals = [_f(v) for v in values]
    fin = np.array([v for v in vals if v is not None and math.isfinite(v)], dtype=np.float64)
    out = {
        "seeds": list(seeds) if seeds is not None else [None] * len(vals),
        "values": vals,
        "n": int(fin.size),
        "n_nonfinite": int(sum(1 for v in vals if v is not None and not math.isfinite(v))),
        "median": float(np.median(fin)) if fin.size else None,
        "min": float(fin.min()) if fin.size else None,
        "max": float(fin.max()) if fin.size else None,
    }
    return out


def _signed_improvement(base: float | None, model: float | None) -> float | None:
    if base is None or model is None or not (math.isfinite(base) and math.isfinite(model)) or base == 0:
        return None
    return (base - model) / base * 100.0


def _paired_improvement(base_by_seed: dict, model_by_seed: dict) -> dict:
    """Improvement per seed, pairing each model seed with the same seed's baseline."""
    seeds, vals, beats = [], [], 0
    for s, m in model_by_seed.items():
        if s not in base_by_seed:
            continue
        imp = _signed_improvement(base_by_seed[s], m)
        if imp is None:
            continue
        seeds.append(s)
        vals.append(imp)
        beats += int(m < base_by_seed[s])
    st = _stats(vals, seeds)
    st["beats"] = beats
    # improvement of the medians (a single-number summary in the paper's style)
    bm = [v for v in base_by_seed.values() if v is not None and math.isfinite(v)]
    mm = [v for v in model_by_seed.values() if v is not None and math.isfinite(v)]
    st["of_medians"] = _signed_improvement(float(np.median(bm)), float(np.median(mm))) if bm and mm else None
    return st


def _metric_value(metrics: Mapping | None, metric: str, state: str | None) -> float | None:
    if not isinstance(metrics, Mapping) or metric not in metrics:
        return None
    v = metrics[metric]
    if state is None:
        if isinstance(v, Mapping):
            return None
        return _f(v)
    if isinstance(v, Mapping):
        return _f(v.get(state))
    return None


def _source_target(source_col: str, table_cols: Sequence[str]) -> str:
    """The table column a source run feeds (``atlas_exp`` -> ``atlas_exp_transfer``)."""
    for cand in (source_col + "_transfer", source_col):
        if cand in table_cols:
            return cand
    return source_col


def _training_stats(runs: list[TrainingRecord]) -> dict:
    seeds = [r.seed for r in runs]
    tol = [r.tolerance_met for r in runs]
    tol_known = [bool(t) for t in tol if t is not None]
    gamma_params = list(dict.fromkeys(p for r in runs for p in r.gamma))
    return {
        "n_runs": len(runs),
        "seeds": seeds,
        "epochs": _stats([r.epochs for r in runs], seeds),
        "tolerance_met": {"k": int(sum(tol_known)), "n": len(tol_known), "values": tol},
        "stop_reasons": dict(Counter(str(r.stop_reason) for r in runs if r.stop_reason is not None)),
        "wall_time": _stats([r.wall_time for r in runs], seeds),
        "final_loss": _stats([r.final_loss for r in runs], seeds),
        # +inf: no epoch of the best-parameter window was reached (a tolerance stop), not a bad loss
        "best_loss": _stats([None if _f(r.best_loss) == math.inf else r.best_loss for r in runs], seeds),
        "gamma": {p: _stats([r.gamma.get(p) for r in runs], seeds) for p in gamma_params},
        "checkpoints": [r.checkpoint for r in runs],
    }


def column_label(results: Mapping, column: str) -> str:
    """A column's display label: as the run recorded it (``labels``), else the registered model's
    label for a bare model name, else the column name itself."""
    recorded = (results.get("labels") or {}).get(column)
    if recorded:
        return str(recorded)
    return MODELS[column].label if column in MODELS else column


def summarize(results: Any) -> dict:
    """Statistics of a finished run, per table column.

    Returns a dict with ``experiment``, ``kind``, ``state_names``, ``seeds``, ``n_seeds``,
    ``tolerance``, ``columns``, ``baseline``, ``labels``, ``models`` (the columns that get an
    improvement: neither the baseline nor an integrator), and

    * ``columns_summary[col]``: ``label``, ``is_integrator``, ``method``/``steps`` (integrators),
      ``metrics[metric][state]`` (per-state metrics) or ``metrics["energy_drift"]`` (scalar) —
      each a stats dict ``{"seeds", "values", "median", "min", "max", "n", "n_nonfinite"}``;
      ``improvement[metric][state]`` (or ``improvement["energy_drift"]``, and
      ``improvement["epochs"]``) — the same stats over the per-seed signed improvements
      (E_base − E_model)/E_base·100 paired by seed, plus ``beats`` (seeds where the model's
      value is below the baseline's; n = pairs) and ``of_medians``;
      ``training`` (networks only): ``epochs``, ``tolerance_met`` {k, n}, ``stop_reasons``,
      ``wall_time``, ``final_loss``, ``best_loss``, ``gamma[param]`` stats.
    * ``sources[col]`` (transfer): the training stats of the source runs, with ``target_column``.
    """
    res = _validate(load_results(results))
    cols: list[str] = list(res["columns"])
    states: list[str] = list(res["state_names"])
    base_col: str = res["baseline"]
    runs = [TrainingRecord.from_dict(r) for r in res.get("runs") or []]
    integ = list(res.get("integrators") or [])
    labels = {c: column_label(res, c) for c in cols}

    integ_cols = {e.get("column") for e in integ}
    table_runs = {c: [r for r in runs if r.column == c and r.in_table] for c in cols}
    models = [c for c in cols if c != base_col and c not in integ_cols]

    # the metric names present anywhere
    present_state, present_scalar = [], []
    for metrics in [*(r.metrics for r in runs), *(e.get("metrics") or {} for e in integ)]:
        for k, v in metrics.items():
            if isinstance(v, Mapping):
                if k not in present_state:
                    present_state.append(k)
            elif k not in present_scalar:
                present_scalar.append(k)
    state_metrics = [m for m in STATE_METRICS if m in present_state] + [m for m in present_state if m not in STATE_METRICS]
    scalar_metrics = [m for m in SCALAR_METRICS if m in present_scalar] + [m for m in present_scalar if m not in SCALAR_METRICS]

    def by_seed(col: str, metric: str, state: str | None) -> dict:
        if col in integ_cols:
            e = next(e for e in integ if e.get("column") == col)
            return {None: _metric_value(e.get("metrics"), metric, state)}
        return {r.seed: _metric_value(r.metrics, metric, state) for r in table_runs[col]}

    def epochs_by_seed(col: str) -> dict:
        return {r.seed: _f(r.epochs) for r in table_runs[col]}

    col_summ: dict[str, dict] = {}
    for c in cols:
        is_int = c in integ_cols
        entry: dict[str, Any] = {"label": labels[c], "is_integrator": is_int, "metrics": {}, "improvement": {}}
        if is_int:
            e = next(e for e in integ if e.get("column") == c)
            entry["method"] = e.get("method")
            entry["steps"] = e.get("steps")
        for m in state_metrics:
            entry["metrics"][m] = {}
            for s in states:
                d = by_seed(c, m, s)
                entry["metrics"][m][s] = _stats(list(d.values()), list(d.keys()))
        for m in scalar_metrics:
            d = by_seed(c, m, None)
            entry["metrics"][m] = _stats(list(d.values()), list(d.keys()))
        if c in models:
            for m in state_metrics:
                entry["improvement"][m] = {s: _paired_improvement(by_seed(base_col, m, s), by_seed(c, m, s)) for s in states}
            for m in scalar_metrics:
                entry["improvement"][m] = _paired_improvement(by_seed(base_col, m, None), by_seed(c, m, None))
            entry["improvement"]["epochs"] = _paired_improvement(epochs_by_seed(base_col), epochs_by_seed(c))
        if not is_int:
            entry["training"] = _training_stats(table_runs[c])
        col_summ[c] = entry

    sources: dict[str, dict] = {}
    for r in runs:
        if r.role == "source":
            sources.setdefault(r.column, []).append(r)
    src_summ = {}
    for sc, rs in sources.items():
        st = _training_stats(rs)
        st["target_column"] = _source_target(sc, cols)
        src_summ[sc] = st

    seeds = res.get("seeds")
    if seeds is None:
        seeds = sorted({r.seed for r in runs if r.seed is not None}, key=lambda s: (str(type(s)), s))
    return {
        "experiment": res["experiment"],
        "kind": res["kind"],
        "state_names": states,
        "seeds": list(seeds),
        "n_seeds": len(seeds),
        "tolerance": res.get("tolerance"),
        "columns": cols,
        "baseline": base_col,
        "labels": labels,
        "models": models,
        "integrators": [
            {"column": e.get("column"), "method": e.get("method"), "steps": e.get("steps"),
             "blew_up_at": e.get("blew_up_at")} for e in integ
        ],
        "state_metrics": state_metrics,
        "scalar_metrics": scalar_metrics,
        "columns_summary": col_summ,
        "sources": src_summ,
        "quick": bool(res.get("quick")),
        "profile": res.get("profile"),
        "verdicts": column_verdicts(res),
    }

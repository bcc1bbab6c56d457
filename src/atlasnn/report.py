"""Tables from a finished run's ``results.json`` (NumPy only: no training, no JAX).

The runner writes ``results.json``; this module turns it into the paper's table layout, with our
numbers as the median and [min–max] across seeds and the paper's printed value beside each
(``atlasnn/data/paper_results.json``, transcribed from the paper's four results tables).

Public functions:

* :func:`load_results` — read a ``results.json`` (path) into a dict (a dict passes through);
* :func:`load_paper` — the transcribed paper numbers (one experiment, or all of them);
* :func:`summarize` — per column, per metric and state: per-seed values, median/min/max/n;
  signed improvement vs the baseline column paired by seed; training statistics and γ;
* :func:`render_tables` — Markdown, CSV, LaTeX and JSON text of the tables;
* :func:`write_tables` — ``tables.md``, ``tables.csv``, ``tables.tex``, ``summary.json``.

``python -m atlasnn.report results.json [--out DIR] [--no-paper]`` prints the Markdown (and
writes the four files with ``--out``).

L2 definitions (SPEC §5). The rows labelled "L2" hold the release's discrete form
sqrt(Σ_i err(t_i)²), not scaled by Δt — the form the paper's tables actually contain; the rows
labelled "L2∫" hold the paper's written definition (∫|err|² dt)^{1/2}, for which the paper has no
tabulated value. Improvement is signed: (E_base − E_model)/E_base·100 (negative = worse).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
from collections import Counter
from importlib import resources
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from atlasnn.caveats import QUICK_BANNER, column_verdicts, verdict_detail, verdict_status_text
from atlasnn.errors import ConfigError
from atlasnn.labels import MODEL_LABELS

__all__ = [
    "load_results",
    "load_paper",
    "summarize",
    "render_tables",
    "write_tables",
    "format_number",
    "format_percent",
    "DEFAULT_LABELS",
    "main",
]

PAPER_FILE = "paper_results.json"

DEFAULT_LABELS = MODEL_LABELS

#: the per-state metrics a run may carry (metric name in results.json -> short row prefix)
STATE_METRICS = ("l2_discrete", "mse", "l2_integral", "max_abs")
#: scalar metrics
SCALAR_METRICS = ("energy_drift",)

_DEFINITIONS = {
    "l2_discrete": "L2, release's discrete form sqrt(sum_i err(t_i)^2), not scaled by dt (the form in the paper's tables)",
    "mse": "MSE = mean_i err(t_i)^2",
    "l2_integral": "L2, paper's integral definition (int |err|^2 dt)^(1/2), trapezoid rule (no paper value)",
    "max_abs": "max_i |err(t_i)|",
    "energy_drift": "energy drift max_i |H(t_i) - E0| / |E0|",
    "epochs": "training epochs run (target task for transfer)",
}

_TABLE_ROLES = ("short", "target")


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


def _training_stats(runs: list[dict]) -> dict:
    seeds = [r.get("seed") for r in runs]
    tol = [r.get("tolerance_met") for r in runs]
    tol_known = [bool(t) for t in tol if t is not None]
    gamma_params: list[str] = []
    for r in runs:
        for p in (r.get("gamma") or {}):
            if p not in gamma_params:
                gamma_params.append(p)
    return {
        "n_runs": len(runs),
        "seeds": seeds,
        "epochs": _stats([r.get("epochs") for r in runs], seeds),
        "tolerance_met": {"k": int(sum(tol_known)), "n": len(tol_known), "values": tol},
        "stop_reasons": dict(Counter(str(r["stop_reason"]) for r in runs if r.get("stop_reason") is not None)),
        "wall_time": _stats([r.get("wall_time") for r in runs], seeds),
        "final_loss": _stats([r.get("final_loss") for r in runs], seeds),
        "best_loss": _stats([r.get("best_loss") for r in runs], seeds),
        "gamma": {p: _stats([(r.get("gamma") or {}).get(p) for r in runs], seeds) for p in gamma_params},
        "checkpoints": [r.get("checkpoint") for r in runs],
    }


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
    runs = list(res.get("runs") or [])
    integ = list(res.get("integrators") or [])
    labels = {c: (res.get("labels") or {}).get(c, DEFAULT_LABELS.get(c, c)) for c in cols}

    integ_cols = {e.get("column") for e in integ}
    table_runs = {c: [r for r in runs if r.get("column") == c and r.get("role", "short") in _TABLE_ROLES]
                  for c in cols}
    models = [c for c in cols if c != base_col and c not in integ_cols]

    # the metric names present anywhere
    present_state, present_scalar = [], []
    for r in [*runs, *integ]:
        for k, v in (r.get("metrics") or {}).items():
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
        return {r.get("seed"): _metric_value(r.get("metrics"), metric, state) for r in table_runs[col]}

    def epochs_by_seed(col: str) -> dict:
        return {r.get("seed"): _f(r.get("epochs")) for r in table_runs[col]}

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
        if r.get("role") == "source":
            sources.setdefault(r["column"], []).append(r)
    src_summ = {}
    for sc, rs in sources.items():
        st = _training_stats(rs)
        st["target_column"] = _source_target(sc, cols)
        src_summ[sc] = st

    seeds = res.get("seeds")
    if seeds is None:
        seeds = sorted({r.get("seed") for r in runs if r.get("seed") is not None}, key=lambda s: (str(type(s)), s))
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
            {"column": e.get("column"), "method": e.get("method"), "steps": e.get("steps")} for e in integ
        ],
        "state_metrics": state_metrics,
        "scalar_metrics": scalar_metrics,
        "columns_summary": col_summ,
        "sources": src_summ,
        "quick": bool(res.get("quick")),
        "verdicts": column_verdicts(res),
    }


# ============================================================================ formatting
def format_number(v: Any) -> str:
    """Like the paper: 3 significant digits; plain for 1 <= |v| < 1000, else ``4.31e-3``."""
    x = _f(v)
    if x is None:
        return "n/a"
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if x == 0:
        return "0"
    a = abs(x)
    if 1 <= a < 1000:
        s = f"{x:.3g}"
        if "e" not in s:
            # keep trailing zeros to 3 significant digits (1.10, 27.0)
            digits = 3 - (int(math.floor(math.log10(abs(float(s))))) + 1)
            return f"{float(s):.{max(digits, 0)}f}"
    mant, exp = f"{x:.2e}".split("e")
    return f"{mant}e{int(exp)}"


def _finite_text(v: Any, render) -> str:
    """``render(x)`` for a finite number, ``n/a`` for a missing or non-finite one."""
    x = _f(v)
    if x is None or not math.isfinite(x):
        return "n/a"
    return render(x)


def format_percent(v: Any) -> str:
    """``63.32%`` (two decimals, signed when negative), ``n/a`` when missing."""
    return _finite_text(v, lambda x: f"{x:.2f}%")


def _format_count(v: Any) -> str:
    return _finite_text(v, lambda x: str(int(x)) if x == int(x) else f"{x:.1f}")


def _format_param(v: Any) -> str:
    return _finite_text(v, lambda x: f"{x:.4g}")


def _format_seconds(v: Any) -> str:
    return _finite_text(v, lambda x: f"{x:.3g}" if x < 1000 else f"{x:.0f}")


def _latex_number(s: str) -> str:
    """``4.31e-3`` -> ``$4.31\\times10^{-3}$``."""
    if s in ("n/a", "nan", "inf", "-inf", "--"):
        return "--" if s == "n/a" else s
    if "e" in s:
        mant, exp = s.split("e")
        return f"${mant}\\times10^{{{exp}}}$"
    return f"${s}$"


def _latex_escape(s: str) -> str:
    out = []
    for ch in str(s):
        if ch in "&%$#_{}":
            out.append("\\" + ch)
        elif ch == "~":
            out.append("\\textasciitilde{}")
        elif ch == "^":
            out.append("\\textasciicircum{}")
        elif ch == "\\":
            out.append("\\textbackslash{}")
        else:
            out.append(ch)
    return "".join(out)


def _latex_state(s: str) -> str:
    if len(s) == 2 and s[0] in "pq" and s[1].isalpha():
        return f"{s[0]}_{s[1]}"
    return _latex_escape(s).replace("\\_", "\\_")


# ============================================================================ table model
def _rows_spec(summary: dict) -> list[dict]:
    """The rows of the main table: (key, metric, state, labels, paper key)."""
    rows = []
    states = summary["state_names"]
    for metric, short, md_name, tex_name in (
        ("l2_discrete", "l2", "L2", "L^2"),
        ("mse", "mse", "MSE", "\\mathrm{MSE}"),
        ("l2_integral", "l2int", "L2∫ (paper's integral def.)", "L^2_{\\int}"),
    ):
        for s in states:
            rows.append({
                "key": f"{short}_{s}",
                "metric": metric,
                "state": s,
                "label": f"{md_name}({s})" if metric != "l2_integral" else f"L2∫({s}) [integral def.]",
                "latex": f"${tex_name}({_latex_state(s)})$",
                "paper_key": f"{short}_{s}" if metric in ("l2_discrete", "mse") else None,
                "definition": _DEFINITIONS[metric],
            })
    rows.append({
        "key": "energy_drift", "metric": "energy_drift", "state": None,
        "label": "Energy drift (max rel.)", "latex": "Energy drift",
        "paper_key": None, "definition": _DEFINITIONS["energy_drift"],
    })
    if summary["kind"] == "transfer":
        rows.append({
            "key": "epochs", "metric": "epochs", "state": None, "label": "Epochs",
            "latex": "Epochs", "paper_key": "epochs", "definition": _DEFINITIONS["epochs"],
        })
    return rows


def _cell_stats(summary: dict, col: str, row: dict) -> dict | None:
    cs = summary["columns_summary"][col]
    if row["metric"] == "epochs":
        return None if cs["is_integrator"] else cs["training"]["epochs"]
    m = cs["metrics"].get(row["metric"])
    if m is None:
        return None
    return m if row["state"] is None else m.get(row["state"])


def _cell_improvement(summary: dict, col: str, row: dict) -> dict | None:
    imp = summary["columns_summary"][col]["improvement"]
    v = imp.get(row["metric"])
    if v is None:
        return None
    return v if row["state"] is None else v.get(row["state"])


def _paper_value(paper: dict | None, row: dict, col: str) -> float | None:
    if paper is None or row["paper_key"] is None:
        return None
    if row["paper_key"] == "epochs":
        return _f((paper.get("epochs") or {}).get(col))
    return _f((paper.get("rows") or {}).get(row["paper_key"], {}).get(col))


def _paper_improvement(paper: dict | None, row: dict, col: str) -> float | None:
    if paper is None or row["paper_key"] is None:
        return None
    if row["paper_key"] == "epochs":
        return _f((paper.get("epochs_improvement") or {}).get(col))
    return _f((paper.get("improvement") or {}).get(row["paper_key"], {}).get(col))


def _build(results: Any, paper: Any) -> tuple[dict, dict | None, list[dict], list[dict]]:
    res = load_results(results)
    summary = summarize(res)
    pap = _resolve_paper(res, paper)
    rows = []
    for spec in _rows_spec(summary):
        cells = {}
        for c in summary["columns"]:
            st = _cell_stats(summary, c, spec)
            imp = _cell_improvement(summary, c, spec) if c in summary["models"] else None
            cells[c] = {
                "stats": st,
                "paper": _paper_value(pap, spec, c),
                "improvement": imp,
                "paper_improvement": _paper_improvement(pap, spec, c) if c in summary["models"] else None,
            }
        rows.append({**spec, "cells": cells})
    training = _training_rows(summary, pap)
    return summary, pap, rows, training


def _paper_gamma(paper: dict | None, col: str) -> dict:
    if paper is None:
        return {}
    return dict((paper.get("gamma") or {}).get(col) or {})


def _training_rows(summary: dict, paper: dict | None) -> list[dict]:
    """One entry per network column: γ (ours vs paper), epochs, tolerance, wall time, losses."""
    out = []
    src_by_target = {s["target_column"]: (name, s) for name, s in summary["sources"].items()}
    for c in summary["columns"]:
        cs = summary["columns_summary"][c]
        if cs["is_integrator"]:
            continue
        tr = cs["training"]
        gamma = dict(tr["gamma"])
        gamma_from = "table runs"
        src = src_by_target.get(c)
        if not gamma and src is not None and src[1]["gamma"]:
            gamma = dict(src[1]["gamma"])
            gamma_from = "source runs"
        pg = _paper_gamma(paper, c)
        params = list(gamma) + [p for p in pg if p not in gamma]
        out.append({
            "column": c,
            "label": cs["label"],
            "gamma": {p: gamma.get(p) for p in params},
            "gamma_from": gamma_from if gamma else None,
            "paper_gamma": pg,
            "epochs": tr["epochs"],
            "paper_epochs": _f((paper.get("epochs") or {}).get(c)) if paper else None,
            "tolerance_met": tr["tolerance_met"],
            "stop_reasons": tr["stop_reasons"],
            "wall_time": tr["wall_time"],
            "final_loss": tr["final_loss"],
            "best_loss": tr["best_loss"],
            "source": src[1] if src is not None else None,
            "source_column": src[0] if src is not None else None,
        })
    return out


# ============================================================================ text of cells
def _range_text(st: dict | None, fmt, sep: str = "–") -> str:
    if st is None or st["median"] is None:
        return "n/a"
    s = fmt(st["median"])
    if st["n"] > 1 and fmt(st["min"]) != fmt(st["max"]):
        s += f" [{fmt(st['min'])}{sep}{fmt(st['max'])}]"
    if st.get("n_nonfinite"):
        s += f" ({st['n_nonfinite']} non-finite)"
    return s


def _value_fmt(row: dict):
    return _format_count if row["metric"] == "epochs" else format_number


def _md_value_cell(row: dict, cell: dict) -> str:
    fmt = _value_fmt(row)
    s = _range_text(cell["stats"], fmt)
    if cell["paper"] is not None:
        s += f" (paper {fmt(cell['paper'])})"
    return s


def _md_imp_cell(cell: dict) -> str:
    imp = cell["improvement"]
    s = _range_text(imp, format_percent)
    if imp is not None and imp["n"]:
        s += f", better in {imp['beats']}/{imp['n']}"
    if cell["paper_improvement"] is not None:
        s += f" (paper {format_percent(cell['paper_improvement'])})"
    return s


def _tex_range(st: dict | None, fmt, tex) -> str:
    if st is None or st["median"] is None:
        return "--"
    s = tex(fmt(st["median"]))
    if st["n"] > 1 and fmt(st["min"]) != fmt(st["max"]):
        s += f" {{\\tiny[{tex(fmt(st['min']))}, {tex(fmt(st['max']))}]}}"
    if st.get("n_nonfinite"):
        s += f" {{\\tiny({st['n_nonfinite']} non-finite)}}"
    return s


def _tex_pct(s: str) -> str:
    return "--" if s == "n/a" else s.replace("%", "\\%")


def _tex_value_cell(row: dict, cell: dict) -> str:
    fmt = _value_fmt(row)
    s = _tex_range(cell["stats"], fmt, _latex_number)
    if cell["paper"] is not None:
        s += f" {{\\tiny(paper {_latex_number(fmt(cell['paper']))})}}"
    return s


def _tex_imp_cell(cell: dict) -> str:
    imp = cell["improvement"]
    s = _tex_range(imp, format_percent, _tex_pct)
    if imp is not None and imp["n"]:
        s += f" {{\\tiny {imp['beats']}/{imp['n']}}}"
    if cell["paper_improvement"] is not None:
        s += f" {{\\tiny(paper {_tex_pct(format_percent(cell['paper_improvement']))})}}"
    return s


def _gamma_text(gamma: dict, fmt_range: bool = True) -> str:
    parts = []
    for p, st in gamma.items():
        if st is None or st.get("median") is None:
            continue
        parts.append(f"{p}={_range_text(st, _format_param)}")
    return ", ".join(parts) if parts else "–"


def _format_paper_param(v: Any) -> str:
    """A paper γ as printed (up to 6 significant digits: 0.26074, 1.1375)."""
    x = _f(v)
    return "n/a" if x is None else f"{x:.6g}"


def _paper_gamma_text(pg: dict) -> str:
    return ", ".join(f"{p}={_format_paper_param(v)}" for p, v in pg.items()) if pg else "–"


def _tol_text(t: dict) -> str:
    return f"{t['k']}/{t['n']}" if t["n"] else "–"


def _stop_text(d: dict) -> str:
    return ", ".join(f"{k}×{v}" for k, v in d.items()) if d else "–"


# ============================================================================ headers
def _header_lines(summary: dict, paper: dict | None) -> list[str]:
    base_label = summary["labels"][summary["baseline"]]
    seeds = summary["seeds"]
    lines = [f"{QUICK_BANNER}. Paper values are shown for reference only: they come from the full budget."] \
        if summary.get("quick") else []
    lines += [
        f"Experiment {summary['experiment']} ({summary['kind']})"
        + (f", compared with the paper's table {paper.get('table')} (one training run per model)" if paper else "")
        + ("." if paper else ". No paper values (not one of the paper's experiments, or left out)."),
        f"Seeds: {len(seeds)} ({', '.join(str(s) for s in seeds)}). Each network cell: median [min–max] across seeds; "
        "integrators (SE) are deterministic: one value.",
        "Rows 'L2(·)': the release's discrete form sqrt(Σ_i err(t_i)²), not scaled by Δt — the form the paper's "
        "tables contain" + (" (paper values beside ours)" if paper else "") + ". Rows 'L2∫(·)': the paper's written definition "
        "(∫|err|² dt)^½, trapezoid rule — no paper value. MSE = mean_i err(t_i)². "
        "Energy drift = max_i |H(t_i) − E0|/|E0|.",
        f"Improvement = signed (E_base − E_model)/E_base·100 against {base_label}, computed per seed against the same "
        "seed's baseline, then median [min–max]; 'better in k/n' counts the seeds where the model beats the baseline. "
        "Negative = worse than the baseline.",
    ]
    tol = summary.get("tolerance")
    tol_line = f"Loss tolerance: {tol:g}." if isinstance(tol, (int, float)) else "No loss tolerance (epoch budget only)."
    if summary["integrators"]:
        tol_line += " Integrators: " + "; ".join(
            f"{summary['labels'].get(e['column'], e['column'])} = {e.get('method')} with {e.get('steps')} steps"
            for e in summary["integrators"]
        ) + "."
    if summary["kind"] == "transfer":
        tol_line += " Epochs row: target-task epochs; its improvement is (epochs_base − epochs_model)/epochs_base·100."
    lines.append(tol_line)
    return lines


def _latex_caption(summary: dict, paper: dict | None) -> str:
    """The header lines of :func:`_header_lines`, written in LaTeX (ASCII only)."""
    esc = _latex_escape
    seeds = summary["seeds"]
    base_label = esc(summary["labels"][summary["baseline"]])
    parts = ["\\textbf{" + esc(_ascii(QUICK_BANNER)) + ".} Paper values for reference only (full budget)."] \
        if summary.get("quick") else []
    parts += [
        f"Experiment {esc(summary['experiment'])} ({summary['kind']})"
        + (f", compared with the paper's table {esc(str(paper.get('table')))} (one training run per model, "
           "values in parentheses)." if paper else "; no paper values."),
        f"{len(seeds)} seeds ({esc(', '.join(str(s) for s in seeds))}): each network cell is the median "
        "[min, max] across seeds; integrators are deterministic (one value).",
        "$L^2$ rows: the release's discrete form $(\\sum_i \\mathrm{err}(t_i)^2)^{1/2}$, not scaled by "
        "$\\Delta t$, the form the paper's tables contain; $L^2_{\\int}$ rows: the paper's definition "
        "$(\\int |\\mathrm{err}|^2\\,dt)^{1/2}$ (trapezoid rule), no paper value; "
        "$\\mathrm{MSE} = \\mathrm{mean}_i\\, \\mathrm{err}(t_i)^2$; energy drift $= \\max_i |H(t_i)-E_0|/|E_0|$.",
        f"Improvement: signed $(E_\\mathrm{{base}}-E_\\mathrm{{model}})/E_\\mathrm{{base}}\\cdot 100$ against "
        f"{base_label}, per seed against the same seed's baseline, then median [min, max]; $k/n$: seeds where the "
        "model beats the baseline; negative means worse.",
    ]
    tol = summary.get("tolerance")
    parts.append(f"Loss tolerance {_latex_number(format_number(tol))}." if isinstance(tol, (int, float)) else "No loss tolerance (epoch budget only).")
    for e in summary["integrators"]:
        parts.append(f"{esc(summary['labels'].get(e['column'], e['column']))}: {esc(str(e.get('method')))}, "
                     f"{esc(str(e.get('steps')))} steps.")
    if summary["kind"] == "transfer":
        parts.append("Epochs: target task; improvement $(\\mathrm{epochs}_\\mathrm{base}-\\mathrm{epochs}_\\mathrm{model})"
                     "/\\mathrm{epochs}_\\mathrm{base}\\cdot 100$.")
    return " ".join(parts)


def _table_columns(summary: dict) -> list[tuple[str, str, str]]:
    """(kind, column, header) for the main table: value columns, each model followed by its improvement."""
    out = []
    for c in summary["columns"]:
        out.append(("value", c, summary["labels"][c]))
        if c in summary["models"]:
            out.append(("imp", c, "Improvement"))
    return out


def _verdict_marks(summary: dict) -> dict[str, int]:
    """Footnote numbers for the columns with a verdict other than ok, in column order."""
    verdicts = summary.get("verdicts") or {}
    bad = [c for c in summary["columns"] if c in verdicts and verdicts[c]["notes"]]
    return {c: i + 1 for i, c in enumerate(bad)}


_ASCII = {"≤": "<=", "≥": ">=", "×": "x", "−": "-", "–": "-", "—": "-", "·": "*", "→": "->", "γ": "gamma",
          "α": "alpha", "β": "beta", "Δ": "Delta", "≈": "~", "⚠": "!"}


def _ascii(text: str) -> str:
    """Text for pdflatex: common symbols spelled out, anything else non-ASCII replaced by '?'."""
    return "".join(_ASCII.get(ch, ch) for ch in str(text)).encode("ascii", "replace").decode("ascii")


# ============================================================================ renderers
def _md(s: str) -> str:
    """A Markdown table cell: no raw pipes."""
    return str(s).replace("|", "\\|")


def _markdown(summary, paper, rows, training) -> str:
    quick = "QUICK RUN — " if summary.get("quick") else ""
    lines = [f"# {quick}{summary['experiment']}: errors against the reference", ""]
    lines += [f"- {h}" for h in _header_lines(summary, paper)]
    lines.append("")
    tcols = _table_columns(summary)
    marks = _verdict_marks(summary)
    lines.append("| Error | " + " | ".join(_md(h + (f" ⚠{marks[c]}" if kind == "value" and c in marks else ""))
                                          for kind, c, h in tcols) + " |")
    lines.append("|---|" + "|".join("---" for _ in tcols) + "|")
    for r in rows:
        cells = []
        for kind, c, _ in tcols:
            cell = r["cells"][c]
            if kind == "value":
                cells.append("N/A" if (r["metric"] == "epochs" and summary["columns_summary"][c]["is_integrator"])
                             else _md_value_cell(r, cell))
            else:
                cells.append(_md_imp_cell(cell))
        lines.append(f"| {_md(r['label'])} | " + " | ".join(_md(c) for c in cells) + " |")
    if marks:
        lines.append("")
        for c, k in marks.items():
            v = summary["verdicts"][c]
            lines.append(f"- ⚠{k} {summary['labels'][c]}: {verdict_status_text(v)} — {verdict_detail(v)}")
    lines += ["", f"## {quick}{summary['experiment']}: training", ""]
    transfer = summary["kind"] == "transfer"
    head = ["Model", "γ (ours)", "γ (paper)", "Epochs", "Tolerance met", "Stop", "Wall time [s]",
            "Final loss", "Best loss"]
    if transfer:
        head += ["Source epochs", "Source tolerance met", "Source wall time [s]", "Source final loss"]
    verdicts = summary.get("verdicts") or {}
    if verdicts:
        head.append("Verdict")
    lines.append("- γ: median [min–max] across seeds (for transfer models: learned in the source task, frozen in the "
                 "target task). Epochs, wall time and losses: median [min–max]; tolerance met: seeds meeting it / seeds.")
    lines.append("")
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "|".join("---" for _ in head) + "|")
    for t in training:
        ep = _range_text(t["epochs"], _format_count)
        if t["paper_epochs"] is not None:
            ep += f" (paper {_format_count(t['paper_epochs'])})"
        cells = [t["label"], _gamma_text(t["gamma"]), _paper_gamma_text(t["paper_gamma"]), ep,
                 _tol_text(t["tolerance_met"]), _stop_text(t["stop_reasons"]),
                 _range_text(t["wall_time"], _format_seconds), _range_text(t["final_loss"], format_number),
                 _range_text(t["best_loss"], format_number)]
        if transfer:
            s = t["source"]
            cells += ([_range_text(s["epochs"], _format_count), _tol_text(s["tolerance_met"]),
                       _range_text(s["wall_time"], _format_seconds), _range_text(s["final_loss"], format_number)]
                      if s else ["–"] * 4)
        if verdicts:
            cells.append(verdict_status_text(verdicts[t["column"]]) if t["column"] in verdicts else "–")
        lines.append("| " + " | ".join(_md(c) for c in cells) + " |")
    return "\n".join(lines) + "\n"


CSV_FIELDS = [
    "table", "row", "metric", "state", "definition", "column", "label",
    "ours_median", "ours_min", "ours_max", "n", "paper",
    "improvement_median", "improvement_min", "improvement_max", "better_k", "pairs_n", "paper_improvement",
    "text",
]


def _num(v: Any) -> str:
    x = _f(v)
    return "" if x is None else repr(x)


def _csv(summary, paper, rows, training) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, lineterminator="\n")
    w.writeheader()
    if summary.get("quick"):
        w.writerow({"table": "note", "row": "quick_run", "definition": "results.json has quick = true",
                    "text": QUICK_BANNER})
    for r in rows:
        for c in summary["columns"]:
            cell = r["cells"][c]
            st, imp = cell["stats"], cell["improvement"]
            w.writerow({
                "table": "errors", "row": r["key"], "metric": r["metric"], "state": r["state"] or "",
                "definition": r["definition"], "column": c, "label": summary["labels"][c],
                "ours_median": _num(st and st["median"]), "ours_min": _num(st and st["min"]),
                "ours_max": _num(st and st["max"]), "n": st["n"] if st else 0, "paper": _num(cell["paper"]),
                "improvement_median": _num(imp and imp["median"]), "improvement_min": _num(imp and imp["min"]),
                "improvement_max": _num(imp and imp["max"]), "better_k": imp["beats"] if imp else "",
                "pairs_n": imp["n"] if imp else "", "paper_improvement": _num(cell["paper_improvement"]),
                "text": _md_value_cell(r, cell) + ("; " + _md_imp_cell(cell) if imp is not None else ""),
            })
    for t in training:
        def put(key, st, definition, paper_v=None, text=None):
            w.writerow({
                "table": "training", "row": key, "metric": key, "state": "", "definition": definition,
                "column": t["column"], "label": t["label"],
                "ours_median": _num(st and st.get("median")), "ours_min": _num(st and st.get("min")),
                "ours_max": _num(st and st.get("max")), "n": st["n"] if st else 0, "paper": _num(paper_v),
                "improvement_median": "", "improvement_min": "", "improvement_max": "", "better_k": "",
                "pairs_n": "", "paper_improvement": "", "text": text if text is not None else "",
            })
        for p, st in t["gamma"].items():
            put(f"gamma_{p}", st, f"learned time-scaling parameter {p} ({t['gamma_from'] or 'paper only'})",
                t["paper_gamma"].get(p), _range_text(st, _format_param) if st else "n/a")
        put("epochs", t["epochs"], "epochs run", t["paper_epochs"], _range_text(t["epochs"], _format_count))
        tm = t["tolerance_met"]
        put("tolerance_met", {"median": tm["k"], "min": None, "max": None, "n": tm["n"]},
            "seeds that met the loss tolerance (ours_median = k of n)", None, _tol_text(tm))
        put("wall_time", t["wall_time"], "wall time per model [s]", None, _range_text(t["wall_time"], _format_seconds))
        put("final_loss", t["final_loss"], "final training loss", None, _range_text(t["final_loss"], format_number))
        put("best_loss", t["best_loss"], "best training loss", None, _range_text(t["best_loss"], format_number))
        v = (summary.get("verdicts") or {}).get(t["column"])
        if v is not None:
            put("verdict", {"median": v["n"] - len(v["notes"]), "min": None, "max": None, "n": v["n"]},
                "verdicts of the runs' quality checks (ours_median = trainings ok of n)", None,
                verdict_status_text(v) + (f" — {verdict_detail(v)}" if v["notes"] else ""))
        if summary["kind"] == "transfer" and t["source"] is not None:
            s = t["source"]
            put("source_epochs", s["epochs"], f"source task ({t['source_column']}) epochs", None,
                _range_text(s["epochs"], _format_count))
            sm = s["tolerance_met"]
            put("source_tolerance_met", {"median": sm["k"], "min": None, "max": None, "n": sm["n"]},
                "source seeds that met the tolerance (ours_median = k of n)", None, _tol_text(sm))
            put("source_wall_time", s["wall_time"], "source task wall time [s]", None,
                _range_text(s["wall_time"], _format_seconds))
            put("source_final_loss", s["final_loss"], "source task final loss", None,
                _range_text(s["final_loss"], format_number))
    return buf.getvalue()


def _latex(summary, paper, rows, training) -> str:
    tcols = _table_columns(summary)
    exp = summary["experiment"]
    cap = _latex_caption(summary, paper)
    marks = _verdict_marks(summary)
    for c, k in marks.items():
        v = summary["verdicts"][c]
        cap += _latex_escape(_ascii(f" (!{k}) {summary['labels'][c]}: {verdict_status_text(v)} - {verdict_detail(v)}."))
    out = [
        f"% generated by atlasnn.report from results.json of {exp}; needs \\usepackage{{booktabs}}",
        "\\begin{table}[ht]",
        "\\centering",
        "\\scriptsize",
        "\\setlength{\\tabcolsep}{3pt}",
        "\\begin{tabular}{" + "l" * (len(tcols) + 1) + "}",
        "\\toprule",
        "Error & " + " & ".join(_latex_escape(h) + (f"\\textsuperscript{{(!{marks[c]})}}" if kind == "value" and c in marks
                                                    else "") for kind, c, h in tcols) + " \\\\",
        "\\midrule",
    ]
    prev_metric = None
    for r in rows:
        if prev_metric is not None and r["metric"] != prev_metric:
            out.append("\\midrule")
        prev_metric = r["metric"]
        cells = []
        for kind, c, _ in tcols:
            cell = r["cells"][c]
            if kind == "value":
                cells.append("N/A" if (r["metric"] == "epochs" and summary["columns_summary"][c]["is_integrator"])
                             else _tex_value_cell(r, cell))
            else:
                cells.append(_tex_imp_cell(cell))
        out.append(f"{r['latex']} & " + " & ".join(cells) + " \\\\")
    out += [
        "\\bottomrule",
        "\\end{tabular}",
        f"\\caption{{{cap}}}",
        f"\\label{{tab:atlasnn-{exp}}}",
        "\\end{table}",
        "",
    ]
    transfer = summary["kind"] == "transfer"
    head = ["Model", "$\\gamma$ (ours)", "$\\gamma$ (paper)", "Epochs", "Tol.\\ met", "Wall time [s]",
            "Final loss", "Best loss"]
    if transfer:
        head += ["Source epochs", "Source tol.\\ met"]
    out += [
        "\\begin{table}[ht]",
        "\\centering",
        "\\scriptsize",
        "\\begin{tabular}{" + "l" * len(head) + "}",
        "\\toprule",
        " & ".join(head) + " \\\\",
        "\\midrule",
    ]
    greek = {"alpha": "\\alpha", "beta": "\\beta", "m": "m"}
    for t in training:
        g = ", ".join(f"${greek.get(p, _latex_escape(p))}={_range_text(st, _format_param, sep='$--$')}$"
                      for p, st in t["gamma"].items() if st is not None and st.get("median") is not None) or "--"
        g = g.replace("[", "\\,[").replace("]", "]")
        pg = ", ".join(f"${greek.get(p, _latex_escape(p))}={_format_paper_param(v)}$" for p, v in t["paper_gamma"].items()) or "--"
        ep = _tex_range(t["epochs"], _format_count, lambda s: s if s != "n/a" else "--")
        if t["paper_epochs"] is not None:
            ep += f" {{\\tiny(paper {_format_count(t['paper_epochs'])})}}"
        cells = [_latex_escape(t["label"]), g, pg, ep, _tol_text(t["tolerance_met"]).replace("–", "--"),
                 _tex_range(t["wall_time"], _format_seconds, lambda s: s),
                 _tex_range(t["final_loss"], format_number, _latex_number),
                 _tex_range(t["best_loss"], format_number, _latex_number)]
        if transfer:
            s = t["source"]
            cells += ([_tex_range(s["epochs"], _format_count, lambda x: x), _tol_text(s["tolerance_met"]).replace("–", "--")]
                      if s else ["--", "--"])
        out.append(" & ".join(cells) + " \\\\")
    out += [
        "\\bottomrule",
        "\\end{tabular}",
        f"\\caption{{{_latex_escape(exp)}: learned time-scaling parameters (median [min, max] across seeds; "
        "transfer models: learned in the source task, frozen in the target task), epochs, seeds meeting the loss "
        "tolerance, wall time per model and training losses.}",
        f"\\label{{tab:atlasnn-{exp}-training}}",
        "\\end{table}",
        "",
    ]
    return "\n".join(out)


def _jsonable(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def _json(summary, paper, rows, training) -> str:
    doc = {
        "experiment": summary["experiment"],
        "kind": summary["kind"],
        "quick": bool(summary.get("quick")),
        "header": _header_lines(summary, paper),
        "paper_table": paper.get("table") if paper else None,
        "table": {
            "columns": [{"kind": k, "column": c, "header": h} for k, c, h in _table_columns(summary)],
            "rows": [
                {
                    "key": r["key"], "metric": r["metric"], "state": r["state"], "label": r["label"],
                    "definition": r["definition"],
                    "cells": {
                        c: {
                            "median": cell["stats"]["median"] if cell["stats"] else None,
                            "min": cell["stats"]["min"] if cell["stats"] else None,
                            "max": cell["stats"]["max"] if cell["stats"] else None,
                            "n": cell["stats"]["n"] if cell["stats"] else 0,
                            "paper": cell["paper"],
                            "improvement": (
                                {k: cell["improvement"][k] for k in ("median", "min", "max", "n", "beats", "of_medians")}
                                if cell["improvement"] else None
                            ),
                            "paper_improvement": cell["paper_improvement"],
                        }
                        for c, cell in r["cells"].items()
                    },
                }
                for r in rows
            ],
        },
        "training": training,
        "summary": summary,
        "paper": paper,
    }
    return json.dumps(_jsonable(doc), indent=2, allow_nan=False) + "\n"


def render_tables(results: Any, paper: Any = None) -> dict[str, str]:
    """The tables of a finished run as text: keys ``markdown``, ``csv``, ``latex``, ``json``.

    ``paper``: None (default) looks the experiment up in the bundled paper numbers (no paper
    values if the experiment is not one of the paper's four); False leaves them out; a name
    picks that paper experiment; a dict is used as the paper entry (or the whole paper file).
    """
    summary, pap, rows, training = _build(results, paper)
    return {
        "markdown": _markdown(summary, pap, rows, training),
        "csv": _csv(summary, pap, rows, training),
        "latex": _latex(summary, pap, rows, training),
        "json": _json(summary, pap, rows, training),
    }


def write_tables(results: Any, out_dir: str | Path, paper: Any = None) -> list[Path]:
    """Write ``tables.md``, ``tables.csv``, ``tables.tex`` and ``summary.json`` into ``out_dir``."""
    texts = render_tables(results, paper)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, key in (("tables.md", "markdown"), ("tables.csv", "csv"), ("tables.tex", "latex"), ("summary.json", "json")):
        p = out / name
        p.write_text(texts[key], encoding="utf-8")
        paths.append(p)
    return paths


def main(argv: Iterable[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m atlasnn.report", description="Tables from a run's results.json")
    ap.add_argument("results", help="results.json (or the run directory holding it)")
    ap.add_argument("--out", help="write tables.md, tables.csv, tables.tex, summary.json here")
    ap.add_argument("--no-paper", action="store_true", help="leave the paper's values out")
    a = ap.parse_args(None if argv is None else list(argv))
    paper = False if a.no_paper else None
    try:
        res = load_results(a.results)
        if a.out:
            for p in write_tables(res, a.out, paper):
                print(p, file=sys.stderr)
        sys.stdout.write(render_tables(res, paper)["markdown"])
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())

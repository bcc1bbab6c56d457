"""The text of the tables: number formats, the table model (rows, cells, paper values) and the
header lines, shared by the Markdown, CSV, LaTeX and JSON renderers of :mod:`atlasnn.report._tables`.

L2 definitions: the rows labelled "L2" hold the release's discrete form sqrt(Σ_i err(t_i)²), not
scaled by Δt — the form the paper's tables actually contain; the rows labelled "L2∫" hold the
paper's written definition (∫|err|² dt)^{1/2}, for which the paper has no tabulated value.
Improvement is signed: (E_base − E_model)/E_base·100 (negative = worse). docs/METHOD.md has
both definitions and the evaluation grids.
"""

from __future__ import annotations

import math
import re
from typing import Any

from atlasnn.errors import AtlasError
from atlasnn.evaluation import METRICS
from atlasnn.report._caveats import QUICK_BANNER
from atlasnn.report._stats import _f, _resolve_paper, load_results, summarize

__all__ = ["format_number", "format_percent", "replace_generated"]

_EPOCHS_DEFINITION = "training epochs run (target task for transfer)"


# ============================================================================ generated docs
def replace_generated(text: str, name: str, body: str, where: str = "the page") -> str:
    """``text`` with ``body`` between its ``<!-- generated:NAME -->`` and ``<!-- /generated:NAME -->``
    markers (the parts of a docs page a script writes from committed runs); an ``AtlasError``
    naming ``where`` when the markers are missing."""
    start, end = f"<!-- generated:{name} -->", f"<!-- /generated:{name} -->"
    pattern = re.compile(re.escape(start) + r".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise AtlasError(f"{where} has no {start} ... {end} markers")
    return pattern.sub(lambda _: f"{start}\n{body.strip()}\n{end}", text)


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
    for m in (m for m in METRICS.values() if m.table and m.per_state):
        for s in states:
            rows.append({
                "key": f"{m.short}_{s}",
                "metric": m.name,
                "state": s,
                "label": m.row.format(s=s),
                "latex": f"${m.latex}({_latex_state(s)})$",
                "paper_key": f"{m.short}_{s}" if m.paper else None,
                "definition": m.definition,
            })
    present = set(summary.get("scalar_metrics") or ()) | {"energy_drift"}  # rows of measures the run has
    for m in (m for m in METRICS.values() if m.table and not m.per_state and m.name in present):
        rows.append({"key": m.name, "metric": m.name, "state": None, "label": m.row, "latex": m.latex,
                     "paper_key": None, "definition": m.definition})
    if summary["kind"] == "transfer":
        rows.append({
            "key": "epochs", "metric": "epochs", "state": None, "label": "Epochs",
            "latex": "Epochs", "paper_key": "epochs", "definition": _EPOCHS_DEFINITION,
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
def _profile_text(summary: dict) -> str:
    """", profile release" for a run of a named profile (runs of older versions have none)."""
    profile = summary.get("profile")
    return f", profile {profile}" if profile not in (None, "default") else ""


def _header_lines(summary: dict, paper: dict | None) -> list[str]:
    base_label = summary["labels"][summary["baseline"]]
    seeds = summary["seeds"]
    lines = [f"{QUICK_BANNER}. Paper values are shown for reference only: they come from the full budget."] \
        if summary.get("quick") else []
    lines += [
        f"Experiment {summary['experiment']} ({summary['kind']})" + _profile_text(summary)
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
            + ("" if e.get("blew_up_at") is None else
               f" (blew up at t = {e['blew_up_at']:.4g}: its step is too large for this system; errors past "
               "that are meaningless, non-finite ones are n/a)")
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
        f"Experiment {esc(summary['experiment'])} ({summary['kind']})" + esc(_profile_text(summary))
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

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

``python -m atlasnn.report._tables results.json [--out DIR] [--no-paper]`` prints the Markdown (and
writes the four files with ``--out``).

The statistics come from :mod:`atlasnn.report._stats`, the cell texts and headers from
:mod:`atlasnn.report._text`. L2 definitions (docs/METHOD.md, section 8). The rows labelled "L2" hold the release's discrete form
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
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from atlasnn.report._caveats import QUICK_BANNER, verdict_detail, verdict_status_text
from atlasnn.errors import ConfigError
from atlasnn.report._stats import _f, load_results
from atlasnn.report._text import (
    _ascii,
    _build,
    _format_count,
    _format_param,
    _format_paper_param,
    _format_seconds,
    _gamma_text,
    _header_lines,
    _latex_caption,
    _latex_escape,
    _latex_number,
    _md_imp_cell,
    _md_value_cell,
    _paper_gamma_text,
    _range_text,
    _stop_text,
    _table_columns,
    _tex_imp_cell,
    _tex_range,
    _tex_value_cell,
    _tol_text,
    _verdict_marks,
    format_number,
)

__all__ = ["render_tables", "write_tables", "CSV_FIELDS", "main"]


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
        f"% generated by atlasnn.report._tables from results.json of {exp}; needs \\usepackage{{booktabs}}",
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
    ap = argparse.ArgumentParser(prog="python -m atlasnn.report._tables", description="Tables from a run's results.json")
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

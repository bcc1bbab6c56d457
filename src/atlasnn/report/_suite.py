"""A suite's summary: per problem and scheme, the error relative to the state's range over the seeds
(worst and median), the error estimate beside it, the verdicts, the training time and the cheapest
classical integrator as accurate as the worst seed.

Input: the run directories of a suite (``atlasnn suite``), each a finished run with results.json
(its work–precision record gives the classical methods' cost on the same grid). Output: a JSON-able
summary and its Markdown.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from atlasnn.evaluation import SYMPLECTIC, TrainingRecord, WorkPoint
from atlasnn.evaluation import workprecision as wp
from atlasnn.report._text import format_number

__all__ = ["suite_summary", "suite_markdown"]


def _median(values: list[float]) -> float | None:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.median(finite)) if finite else None


def _worst(values: list[float | None]) -> float | None:
    if any(v is None or not math.isfinite(v) for v in values):
        return math.inf if values else None
    return max(values) if values else None


def _classical(results: dict, max_abs: float | None) -> dict | None:
    """The fastest classical setting whose max error is at most ``max_abs`` (None: none measured)."""
    points = [WorkPoint(**p) for p in (results.get("work_precision") or {}).get("points", [])]
    if max_abs is None or not points:
        return None
    target = WorkPoint("target", "", 0.0, max_abs, 0.0, 0.0, kind="network")
    match = wp.cheapest_match(points, target)
    if match is None:
        return {"method": None}
    name = SYMPLECTIC.get(match.method, "DOP853" if match.method == "dop853" else match.method)
    return {"method": name, "setting": match.setting, "seconds": match.seconds, "max_error": match.max_error}


def _scheme_row(results: dict, column: str, records: list[TrainingRecord]) -> dict[str, Any]:
    rel = [r.metric("relative_max") for r in records]
    est = [r.metric("estimate_relative") for r in records]
    abs_err = [(r.metrics.get("whole") or {}).get("max_abs") for r in records]
    eff = [r.effectivity for r in records]
    status = [r.status or "n/a" for r in records]
    windows = [r.march.n_windows for r in records if r.march is not None]
    rejected = [int(r.extra["rejected"]) if r.role == "solve" else sum(a.get("outcome") == "rejected" for a in r.march.windows)
                for r in records if r.march is not None]
    worst_abs = _worst(abs_err)
    return {
        "column": column, "label": (results.get("labels") or {}).get(column, column), "seeds": [r.seed for r in records],
        "relative_max": rel, "worst": _worst(rel), "median": _median(rel),
        "estimate": est, "estimate_worst": _worst(est), "estimate_median": _median(est),
        "effectivity": eff, "verdicts": {s: status.count(s) for s in dict.fromkeys(status)},
        "false_ok": sum(1 for r, s in zip(rel, status) if s == "ok" and (r is None or r > 0.05)),
        "false_alarm": sum(1 for r, s in zip(rel, status) if s in ("suspect", "failed") and r is not None and r < 1e-3),
        "training_seconds": _median([r.wall_time for r in records]),
        "compile_seconds": _median([r.compile_time for r in records]),
        "windows": _median([float(w) for w in windows]) if windows else None,
        "rejected": int(sum(rejected)) if rejected else None,
        "classical": _classical(results, worst_abs if worst_abs is not None and math.isfinite(worst_abs) else None),
    }


def suite_summary(run_dirs: Sequence[str | Path]) -> dict[str, Any]:
    """Every problem's rows (one per scheme column of each run), in the order given."""
    problems: dict[str, dict] = {}
    for d in run_dirs:
        path = Path(d) / "results.json"
        if not path.is_file():
            continue
        res = json.loads(path.read_text(encoding="utf-8"))
        profile = res.get("profile") or "default"
        entry = problems.setdefault(res["experiment"], {"experiment": res["experiment"], "description":
                                                         res.get("description", ""), "rows": []})
        records = [TrainingRecord.from_dict(r) for r in res.get("runs") or []]
        for column in res["columns"]:
            mine = [r for r in records if r.column == column and r.in_table]
            if mine:
                row = _scheme_row(res, column, mine)
                row["scheme"] = _scheme_name(column, profile, mine[0].role)
                row["run_dir"] = str(Path(d))
                entry["rows"].append(row)
    rows = [row for p in problems.values() for row in p["rows"]]
    return {"problems": list(problems.values()),
            "totals": {"trainings": sum(len(r["seeds"]) for r in rows),
                       "false_ok": sum(r["false_ok"] for r in rows), "false_alarm": sum(r["false_alarm"] for r in rows)}}


def _scheme_name(column: str, profile: str, role: str) -> str:
    if role == "solve":  # the column is the solver's name
        kind = {"gauss": "Gauss collocation", "collocation": "random-feature collocation"}.get(column, column)
        return f"{kind}, float64 (solved, not trained)"
    if column.endswith("_march"):
        return "time-marching, fixed windows" if profile == "fixed" else "time-marching, adaptive windows"
    return "direct training"


def _cell(v: float | None) -> str:
    return "n/a" if v is None else format_number(v)


def _ratio(v: float) -> str:
    """An effectivity: two decimals near 1, powers of ten where the estimate is a flag, not a measure."""
    return f"{v:.2f}" if 1e-2 <= v < 100 else f"{v:.1e}"


def suite_markdown(summary: dict[str, Any]) -> str:
    """The summary as Markdown: one table per problem, a row per scheme."""
    lines = []
    head = ("| scheme | worst seed | median | estimate (worst) | effectivity | verdicts | training s/seed "
            "| windows (rejected) | cheapest classical as accurate |")
    for p in summary["problems"]:
        lines += [f"### {p['experiment']}", "", p["description"], "", head, "|" + "---|" * 9]
        for r in p["rows"]:
            eff = [e for e in r["effectivity"] if e is not None]
            effs = f"{_ratio(min(eff))}–{_ratio(max(eff))}" if eff else "n/a"
            verdicts = ", ".join(f"{k} {v}" for k, v in r["verdicts"].items())
            win = "" if r["windows"] is None else f"{r['windows']:.0f}" + (f" ({r['rejected']})" if r["rejected"] else "")
            c = r["classical"]
            if c is None:
                classical = "not measured"
            elif c["method"] is None:
                classical = "none measured is as accurate"
            else:
                classical = f"{c['method']} {c['setting']}: {c['seconds'] * 1e3:.2g} ms"
            lines.append(f"| {r['scheme']} | {_cell(r['worst'])} | {_cell(r['median'])} | {_cell(r['estimate_worst'])} "
                         f"| {effs} | {verdicts} | {_cell(r['training_seconds'])} | {win} | {classical} |")
        lines.append("")
    t = summary["totals"]
    lines.append(f"{t['trainings']} trainings; judged ok with a true error above 5 % of the range: {t['false_ok']}; "
                 f"judged suspect or failed with a true error below 0.1 %: {t['false_alarm']}.")
    return "\n".join(lines) + "\n"

"""What a reader must know about a run before reading its numbers (NumPy-free, no JAX).

Two caveats travel with a run's ``results.json`` and are shown by the printed summary, the
tables and the figures alike:

* a **quick run** (``"quick": true``, from ``--quick``) is a smoke test on a reduced budget, so
  its errors are not comparable with the paper's: :func:`is_quick`, :data:`QUICK_BANNER` and
  :func:`figure_title` label it;
* a **verdict** per training: a run record may carry ``"quality": {"status": "ok" | "suspect" |
  "failed", "reasons": [...], "advice": "..."}`` (filled by the runner's quality checks).
  :func:`column_verdicts` gathers them per table column (a transfer column also collects the
  verdicts of its source trainings); a run without the field contributes nothing, so a
  ``results.json`` without any verdict renders exactly as before.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

from atlasnn.evaluation import TrainingRecord

__all__ = [
    "QUICK_BANNER",
    "QUICK_TAG",
    "STATUS_ORDER",
    "is_quick",
    "figure_title",
    "run_quality",
    "column_verdicts",
    "verdict_status_text",
    "verdict_detail",
]

#: the one-line label of a quick run (tables, printed summary)
QUICK_BANNER = "QUICK RUN (smoke test, reduced budget) — not comparable with the paper"
#: the short form used in figure titles
QUICK_TAG = "QUICK RUN (reduced budget, not comparable with the paper)"
#: verdict statuses from best to worst; an unknown status ranks as "suspect"
STATUS_ORDER = ("ok", "suspect", "failed")


def is_quick(results: Mapping[str, Any]) -> bool:
    """True for a run made with ``--quick`` (``results.json`` has ``"quick": true``)."""
    return bool(results.get("quick"))


def figure_title(results: Mapping[str, Any], text: str) -> str:
    """A figure title; a quick run's gets :data:`QUICK_TAG` as a first line."""
    return f"{QUICK_TAG}\n{text}" if is_quick(results) else text


def run_quality(run: Mapping[str, Any] | TrainingRecord) -> dict | None:
    """A run record's verdict as ``{"status", "reasons", "advice"}``, or None when it has none.

    Only a mapping with a string ``status`` counts; ``reasons`` becomes a list of strings (a
    single string is one reason) and ``advice`` a string or None.
    """
    q = run.quality if isinstance(run, TrainingRecord) else run.get("quality")
    if not isinstance(q, Mapping) or not isinstance(q.get("status"), str):
        return None
    reasons = q.get("reasons") or []
    if isinstance(reasons, str):
        reasons = [reasons]
    advice = q.get("advice")
    return {
        "status": q["status"],
        "reasons": [str(r) for r in reasons if r is not None],
        "advice": str(advice) if advice else None,
    }


def _rank(status: str) -> int:
    return STATUS_ORDER.index(status) if status in STATUS_ORDER else 1


def _target_column(column: str, columns: Sequence[str]) -> str:
    """The table column a source training feeds (``atlas_exp`` -> ``atlas_exp_transfer``)."""
    for cand in (column + "_transfer", column):
        if cand in columns:
            return cand
    return column


def column_verdicts(results: Mapping[str, Any]) -> dict[str, dict]:
    """Per table column with at least one verdict: the worst status and what made it so.

    Returns ``{column: {"status", "counts", "n", "seeds_not_ok", "notes", "advice"}}`` where
    ``counts`` maps each status to the number of trainings with it, ``n`` is the number of
    trainings with a verdict, ``notes`` lists ``"seed 3: reason; reason"`` (``"source seed 3:
    ..."`` for a transfer's source) for every training whose status is not ok, and ``advice``
    the distinct advice texts of those trainings. Columns without any verdict are absent.
    """
    columns = list(results.get("columns") or [])
    out: dict[str, dict] = {}
    for r in map(TrainingRecord.from_dict, results.get("runs") or []):
        q = run_quality(r)
        if q is None:
            continue
        is_source = r.role == "source"
        col = _target_column(str(r.column), columns) if is_source else str(r.column)
        v = out.setdefault(col, {"status": "ok", "counts": {}, "n": 0, "seeds_not_ok": [], "notes": [],
                                 "advice": []})
        v["n"] += 1
        v["counts"][q["status"]] = v["counts"].get(q["status"], 0) + 1
        if _rank(q["status"]) > _rank(v["status"]) or (q["status"] not in STATUS_ORDER and v["status"] == "ok"):
            v["status"] = q["status"]
        if q["status"] != "ok":
            who = f"{'source ' if is_source else ''}seed {r.seed}"
            if r.seed not in v["seeds_not_ok"]:
                v["seeds_not_ok"].append(r.seed)
            v["notes"].append(f"{who}: {q['status']}" + (f" ({'; '.join(q['reasons'])})" if q["reasons"] else ""))
            if q["advice"] and q["advice"] not in v["advice"]:
                v["advice"].append(q["advice"])
    return out


def verdict_status_text(v: Mapping[str, Any]) -> str:
    """A compact status: ``ok``, or the non-ok counts such as ``suspect 2/5, failed 1/5``."""
    bad = [(s, k) for s, k in v["counts"].items() if s != "ok" and k]
    if not bad:
        return "ok" if v["n"] <= 1 else f"ok {v['n']}/{v['n']}"
    bad.sort(key=lambda sk: -_rank(sk[0]))
    if v["n"] == 1:
        return bad[0][0]
    return ", ".join(f"{s} {k}/{v['n']}" for s, k in bad)


def verdict_detail(v: Mapping[str, Any], max_notes: int | None = None, advice: bool = True) -> str:
    """The reasons behind a non-ok verdict, ``"seed 1: suspect (energy drift 1.07 > 0.05); ..."``.

    ``max_notes`` keeps the first few notes and says how many were left out; ``advice`` appends
    the advice texts. Empty for an all-ok column.
    """
    notes = list(v["notes"])
    if not notes:
        return ""
    shown = notes if max_notes is None else notes[:max_notes]
    text = "; ".join(shown)
    if len(shown) < len(notes):
        text += f"; +{len(notes) - len(shown)} more"
    if advice and v["advice"]:
        text += ". Advice: " + " ".join(v["advice"])
    return text

"""The printed end-of-run summary and the tables' caveats: every state component, runs without
an SE column, per-model verdicts from an optional ``quality`` field, and quick-run labels.

All inputs are synthetic results.json dicts; nothing trains.
"""

from __future__ import annotations

import copy
import csv
import io

import pytest

from atlasnn.report._caveats import QUICK_BANNER, column_verdicts, figure_title, verdict_status_text
from atlasnn.report import SUMMARY_WIDTH, summary_lines
from atlasnn.report import render_tables

SEEDS = [0, 1, 2, 3, 4]


def _chain(d: int = 3, columns=("hnn", "atlas_exp"), experiment: str = "chain") -> dict:
    """A d-particle system with no SE column (not separable): L2 of component k, seed s = (k+1)·10^-3·(s+1)."""
    states = [f"q{i + 1}" for i in range(d)] + [f"p{i + 1}" for i in range(d)]
    runs = []
    for j, col in enumerate(columns):
        for s in SEEDS:
            l2 = {name: (k + 1) * 1e-3 * (s + 1) * (j + 1) for k, name in enumerate(states)}
            runs.append({"column": col, "seed": s, "role": "short",
                         "metrics": {"l2_discrete": l2, "energy_drift": 1e-3}, "gamma": {}, "epochs": 100,
                         "stop_reason": "budget", "final_loss": 1e-5, "best_loss": 1e-5,
                         "checkpoint": f"models/{col}_seed{s}.npz"})
    return {"experiment": experiment, "kind": "short", "state_names": states, "seeds": SEEDS,
            "columns": list(columns), "baseline": columns[0], "eval_points": 1000,
            "labels": {"hnn": "HNN", "atlas_exp": "ATLAS-NN (exp)", "atlas_tanh": "ATLAS-NN (tanh)"},
            "runs": runs, "integrators": []}


def _with_quality(results: dict) -> dict:
    r = copy.deepcopy(results)
    for run in r["runs"]:
        if run["column"] == "atlas_exp":
            bad = run["seed"] in (1, 3)
            run["quality"] = {"status": "suspect" if bad else "ok",
                              "reasons": [f"energy drift 1.0{run['seed']} > 0.05"] if bad else [],
                              "advice": "Raise train.epochs." if bad else None}
    return r


# ------------------------------------------------------------------------------ summary lines
def test_summary_shows_every_component_without_an_se_column():
    lines = summary_lines(_chain(3))
    header = next(line for line in lines if line.strip().startswith("model"))
    for name in ("q1", "q2", "q3", "p1", "p2", "p3"):
        assert f"L2({name})" in header
    hnn = next(line for line in lines if line.strip().startswith("HNN"))
    # medians over seeds 1..5 × (k+1)·1e-3: component k has median 3·(k+1)·1e-3; first with its range
    assert hnn.split()[1:4] == ["3.00e-3", "[1.00e-3–5.00e-3]", "6.00e-3"]
    assert hnn.split()[-1] == "1.80e-2"  # p3: 6 × 3e-3
    assert not any(line.strip().startswith("SE") for line in lines)
    assert not any("verdict" in line or "↳" in line for line in lines)  # no quality field: no verdict slot
    assert "median over 5 seeds" in lines[0]
    assert all(len(line) <= SUMMARY_WIDTH for line in lines)


def test_summary_truncates_many_components_and_says_so():
    lines = summary_lines(_chain(8))
    assert all(len(line) <= SUMMARY_WIDTH for line in lines)
    header = next(line for line in lines if line.strip().startswith("model"))
    shown = header.count("L2(")
    assert 1 <= shown < 16
    assert f"(+{16 - shown} more components, " in lines[-1] and lines[-1].endswith("in tables.md)")


def test_summary_shows_verdicts_when_runs_carry_them():
    lines = summary_lines(_with_quality(_chain(2)))
    header = next(line for line in lines if line.strip().startswith("model"))
    assert header.rstrip().endswith("verdict")
    exp = next(line for line in lines if line.strip().startswith("ATLAS-NN (exp)"))
    assert exp.endswith("suspect 2/5")
    reasons = lines[lines.index(exp) + 1]
    assert reasons.strip().startswith("↳ seed 1: suspect (energy drift 1.01 > 0.05); seed 3: suspect")
    hnn = next(line for line in lines if line.strip().startswith("HNN"))
    assert "ok" not in hnn and "suspect" not in hnn  # HNN has no verdict: its slot stays empty


def test_summary_labels_quick_runs_and_marks_paper_values():
    r = _chain(1, columns=("hnn", "atlas_tanh", "atlas_exp"), experiment="oscillator-short")
    r["state_names"] = ["x", "p"]
    for run in r["runs"]:
        run["metrics"]["l2_discrete"] = {"x": run["metrics"]["l2_discrete"]["q1"],
                                         "p": run["metrics"]["l2_discrete"]["p1"]}
    full = summary_lines(r)
    assert not any("QUICK" in line for line in full)
    assert "paper L2(x)" in next(line for line in full if line.strip().startswith("model"))
    assert "1.17e-2" in next(line for line in full if line.strip().startswith("HNN"))  # the paper's HNN
    r["quick"] = True
    quick = summary_lines(r)
    assert QUICK_BANNER in quick[0]
    assert any("not comparable" in line and "full budget" in line for line in quick[1:])


def test_summary_points_to_the_overview(tmp_path):
    r = _chain(1)
    assert not any(line.startswith("overview:") for line in summary_lines(r, run_dir=tmp_path))
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "overview.png").write_bytes(b"png")
    assert summary_lines(r, run_dir=tmp_path)[-1] == f"overview: {tmp_path / 'figures' / 'overview.png'}"


# ------------------------------------------------------------------------------ verdicts
def test_column_verdicts_collects_sources_and_ranks_statuses():
    r = _chain(1, columns=("hnn_baseline", "atlas_exp_transfer"))
    r["kind"] = "transfer"
    for run in r["runs"]:
        run["role"] = "target"
    r["runs"].append({"column": "atlas_exp", "seed": 2, "role": "source", "metrics": {},
                      "quality": {"status": "failed", "reasons": "diverged at epoch 7", "advice": "Lower lr."}})
    r["runs"][0]["quality"] = {"status": "ok", "reasons": []}
    r["runs"][1]["quality"] = "not a dict"  # malformed: ignored
    v = column_verdicts(r)
    assert set(v) == {"hnn_baseline", "atlas_exp_transfer"}
    assert v["hnn_baseline"] == {"status": "ok", "counts": {"ok": 1}, "n": 1, "seeds_not_ok": [], "notes": [],
                                 "advice": []}
    assert v["atlas_exp_transfer"]["status"] == "failed"
    assert v["atlas_exp_transfer"]["notes"] == ["source seed 2: failed (diverged at epoch 7)"]
    assert verdict_status_text(v["atlas_exp_transfer"]) == "failed"
    assert verdict_status_text(v["hnn_baseline"]) == "ok"


def test_figure_titles_of_quick_runs():
    assert figure_title({"quick": True}, "x").startswith("QUICK RUN")
    assert figure_title({}, "x") == "x"


# ------------------------------------------------------------------------------ tables
def test_tables_mark_models_with_non_ok_verdicts():
    t = render_tables(_with_quality(_chain(2)))
    md = t["markdown"]
    head = next(line for line in md.splitlines() if line.startswith("| Error |"))
    assert "ATLAS-NN (exp) ⚠1 |" in head and "HNN ⚠" not in head
    note = next(line for line in md.splitlines() if line.startswith("- ⚠1"))
    assert "ATLAS-NN (exp): suspect 2/5" in note and "energy drift 1.03 > 0.05" in note
    assert "Advice: Raise train.epochs." in note
    train_head = next(line for line in md.splitlines() if line.startswith("| Model |"))
    assert train_head.rstrip(" |").endswith("Verdict")
    rows = list(csv.DictReader(io.StringIO(t["csv"])))
    verdict = next(x for x in rows if x["row"] == "verdict" and x["column"] == "atlas_exp")
    assert float(verdict["ours_median"]) == 3 and verdict["n"] == "5" and verdict["text"].startswith("suspect 2/5")
    tex = t["latex"]
    assert "(!1)" in tex and all(ord(ch) < 128 for ch in tex) and tex.count("{") == tex.count("}")


def test_tables_without_quality_have_no_verdicts():
    md = render_tables(_chain(2))["markdown"]
    assert "⚠" not in md and "Verdict" not in md


def test_tables_label_quick_runs():
    r = _chain(1)
    r["quick"] = True
    t = render_tables(r)
    assert t["markdown"].startswith("# QUICK RUN — chain")
    assert QUICK_BANNER in t["markdown"]
    first = next(csv.DictReader(io.StringIO(t["csv"])))
    assert first["table"] == "note" and first["text"] == QUICK_BANNER
    assert "QUICK RUN" in t["latex"] and all(ord(ch) < 128 for ch in t["latex"])
    assert '"quick": true' in t["json"]
    r["quick"] = False
    assert "QUICK" not in render_tables(r)["markdown"]


@pytest.mark.parametrize("status", ["failed", "weird"])
def test_unknown_or_failed_status_counts_as_not_ok(status):
    r = _chain(1)
    r["runs"][0]["quality"] = {"status": status, "reasons": ["why"]}
    v = column_verdicts(r)["hnn"]
    assert v["status"] == status and v["notes"] == [f"seed 0: {status} (why)"]

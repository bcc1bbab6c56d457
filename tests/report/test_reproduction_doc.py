"""The generated parts of docs/REPRODUCTION.md (scripts/reproduction_doc.py), on hand-made results."""

from __future__ import annotations

import sys
from dataclasses import asdict
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

import reproduction_doc as doc  # noqa: E402
from atlasnn.evaluation import WorkPoint  # noqa: E402


def _long_results():
    classical = [WorkPoint("stormer_verlet", "N=999", 0.002, 0.05, 0.5, 1e-3),
                 WorkPoint("stormer_verlet", "N=3996", 0.008, 0.004, 0.04, 1e-4),
                 WorkPoint("dop853", "tol=1e-08", 0.03, 1e-6, 1e-5, 1e-9)]
    net = [WorkPoint("march", f"seed {s}", 7.0 + s, err, 10 * err, 1e-4, kind="network")
           for s, err in enumerate([0.003, 0.001, 0.01])]
    return {"seeds": [0, 1, 2], "work_precision": {
        "points": [asdict(p) for p in classical + net], "first_state": "x", "grid_points": 1000,
        "evaluation_seconds_1e4": {"march": 0.004}}}


def test_the_long_time_table_judges_each_model_by_its_worst_seed():
    text = doc.long_time({"oscillator-long": {"paper": _long_results()}})
    row = next(line for line in text.splitlines() if line.startswith("| march |"))
    # median and worst of max abs error over the three seeds; training seconds median 8
    assert "1.00e-2" in row or "0.01" in row
    assert "| 8 |" in row and "4 ms" in row
    # the worst seed (0.01, 9 s) is matched by Störmer–Verlet at N=3996 (0.004 in 0.008 s)
    assert "Störmer–Verlet N=3996" in row and "1.12e+03x cheaper" in row


def test_runs_without_a_work_precision_record_give_no_long_table():
    assert doc.long_time({"oscillator-short": {"paper": {"seeds": [0]}}}) == "(no long-time run given)"


def test_generated_sections_are_replaced_and_missing_markers_are_named():
    text = "intro\n<!-- generated:long -->\nold\n<!-- /generated:long -->\nend"
    assert doc.replace_generated(text, "long", "new") == "intro\n<!-- generated:long -->\nnew\n<!-- /generated:long -->\nend"
    with pytest.raises(SystemExit, match="generated:claims"):
        doc.replace_generated(text, "claims", "x")

"""A classical baseline that overflows (a stiff oscillator, symplectic Euler at ω·Δt = 4) never
crashes a run or its report: it is drawn until it blows up, marked, and its errors are n/a."""

from __future__ import annotations

import json

import numpy as np
import pytest

from atlasnn.cli import main
from atlasnn.evaluation import blow_up_index

STIFF = """
name = "stiff"
kind = "short"
models = ["atlas_exp"]
seeds = [0]
[system]
name = "stiff"
hamiltonian = "p**2/2 + 500000*q**2"
coordinates = ["q"]
momenta = ["p"]
separable = true
z0 = [1.0, 0.0]
[interval]
T = 4.0
[train]
epochs = 40
chunk = 40
[evaluation]
eval_points = 200
se_steps = 1000
fine_factor = 10
"""


def test_blow_up_index_finds_the_first_bad_sample():
    ref = np.stack([np.cos(np.linspace(0, 6, 50)), np.sin(np.linspace(0, 6, 50))], axis=1)
    assert blow_up_index(ref + 1e-3, ref) is None
    z = ref.copy()
    z[30] = 500.0  # 250 ranges away
    z[40] = np.inf
    assert blow_up_index(z, ref) == 30
    z[30] = ref[30]
    assert blow_up_index(z, ref) == 40


@pytest.mark.slow  # 50 s, a whole run; test_blow_up_index_finds_the_first_bad_sample checks the marking (CI stays under 30 min)
def test_an_overflowing_baseline_is_marked_and_the_run_and_report_exit_zero(tmp_path, capsys):
    cfg = tmp_path / "stiff.toml"
    cfg.write_text(STIFF, encoding="utf-8")
    out = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr()
    assert "SE (symplectic_euler, 1000 steps) blew up at t = " in printed.out + printed.err
    assert "Traceback" not in printed.err and "RuntimeWarning" not in printed.err
    results = json.loads((out / "results.json").read_text())
    se = next(e for e in results["integrators"] if e["column"] == "se")
    fine = next(e for e in results["integrators"] if e["column"] != "se")
    assert 0 < se["blew_up_at"] < 0.1 and fine["blew_up_at"] is None  # SE-10 is stable (ω·Δt = 0.4)
    assert "blew up at t = " in (out / "tables.md").read_text()
    overview = out / "figures" / "overview.png"
    assert overview.stat().st_size > 10_000
    overview.unlink()
    assert main(["report", str(out)]) == 0  # the report alone draws it again
    assert overview.exists()
    assert "blew up at t = " in capsys.readouterr().out

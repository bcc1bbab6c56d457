"""A non-separable Hamiltonian end to end through the command line: run, then report.

H = (q² + 1)(p² + 1)/2 declared non-separable: no symplectic integrator can run, so the tables
have no SE column, and neither the run's summary nor `atlasnn report` may fail on that.
"""

from __future__ import annotations

import csv
import json

import pytest

from atlasnn.cli import main

CONFIG = """
name = "nonsep"
models = ["hnn", "atlas_exp"]

[system]
hamiltonian = "(q**2 + 1)*(p**2 + 1)/2"
coordinates = ["q"]
momenta = ["p"]
separable = false
z0 = [0.5, 0.0]

[network]
width = 16
depth = 2

[interval]
T = 2.0

[train]
epochs = 200
n_points = 32
chunk = 100
"""


def _no_se(run):
    md = (run / "tables.md").read_text(encoding="utf-8")
    headers = [line for line in md.splitlines() if line.startswith("| Error") or line.startswith("| Model")]
    assert headers, md
    for line in headers:
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert "SE" not in cells and not any(c.startswith("SE-") for c in cells), line
    with open(run / "tables.csv", newline="", encoding="utf-8") as f:
        columns = {row["column"] for row in csv.DictReader(f)}
    assert columns and not any(c == "se" or c.startswith("se_") for c in columns), columns
    assert "| HNN |" in md and "ATLAS-NN (exp)" in md


@pytest.mark.long
def test_non_separable_run_and_report(tmp_path, capsys):
    config = tmp_path / "nonsep.toml"
    config.write_text(CONFIG, encoding="utf-8")
    run = tmp_path / "run"
    assert main(["run", str(config), "--out", str(run), "--no-progress"]) == 0
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    assert "HNN" in out.out and "ATLAS-NN (exp)" in out.out  # the printed summary

    results = json.loads((run / "results.json").read_text(encoding="utf-8"))
    assert results["system"]["separable"] is False and results["integrators"] == []
    assert {r["column"] for r in results["runs"]} == {"hnn", "atlas_exp"}
    _no_se(run)
    figures = {p.name for p in (run / "figures").iterdir()}
    for name in ("trajectories", "errors", "energy", "loss"):
        assert f"{name}.png" in figures and f"{name}.pdf" not in figures  # PNG alone unless --pdf

    # re-render from the directory alone
    for p in (run / "figures").iterdir():
        p.unlink()
    (run / "tables.md").unlink()
    assert main(["report", str(run)]) == 0
    out = capsys.readouterr()
    assert "Traceback" not in out.err and "wrote" in out.out
    _no_se(run)
    assert (run / "figures" / "trajectories.png").is_file()

"""Files written before the package was laid out in subpackages still load: checkpoints, training
states and time-marching solutions (written by the flat-module version into tests/data/), and the
results.json of the committed runs (docs/runs/)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from atlasnn.checkpoint import load_checkpoint, load_piecewise, load_state
from atlasnn.report import load_results, render_tables, summarize

DATA = Path(__file__).parents[1] / "data"
_ALL = sorted((Path(__file__).parents[2] / "docs" / "runs").glob("*/*/results.json"))
FAMILY_RUNS = [p for p in _ALL if p.parent.parent.name == "families"]  # bundle and inverse runs
RUNS = [p for p in _ALL if p not in FAMILY_RUNS]


def test_checkpoints_written_before_the_layout_load_and_predict_the_same():
    values = np.load(DATA / "pre_layout_values.npz")
    sol = load_checkpoint(DATA / "pre_layout_model.npz").solution()
    # the same weights; evaluation is padded to a bucket of times now, so equal to float32 rounding
    np.testing.assert_allclose(sol(values["t"]), values["model"], rtol=1e-6, atol=1e-7)
    state = load_state(DATA / "pre_layout_state.npz")
    assert state.epoch == 50 and len(state.history.loss) == 50
    march = load_piecewise(DATA / "pre_layout_march.npz")
    assert march.n_windows == 2
    np.testing.assert_allclose(march(np.linspace(0, 2, 7)), values["march"], rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("path", RUNS, ids=lambda p: f"{p.parent.parent.name}/{p.parent.name}")
def test_committed_results_still_summarise(path):
    res = load_results(path)
    summary = summarize(res)
    assert set(summary["columns"]) == set(res["columns"])
    tables = render_tables(res)
    assert tables and all(isinstance(v, str) and v for v in tables.values())


@pytest.mark.parametrize("path", FAMILY_RUNS, ids=lambda p: p.parent.name)
def test_committed_family_runs_still_summarise(path, tmp_path):
    """A committed bundle or inverse run's summary is rebuilt from its results.json as committed."""
    import shutil

    from atlasnn.experiments import rewrite_family_summary

    shutil.copy(path, tmp_path / "results.json")
    text = rewrite_family_summary(tmp_path).read_text()
    assert text == (path.parent / "summary.md").read_text()

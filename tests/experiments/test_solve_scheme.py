"""The solver inside an experiment: a ``[solve]`` table adds the column of its method (``gauss`` by
default: one deterministic solution every seed records; ``collocation``: every seed its own random
features, one program), measured, estimated, judged and reported like the trained columns;
``schemes`` picks which of a config's schemes run."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from atlasnn.checkpoint import load_piecewise
from atlasnn.evaluation import reference_solution
from atlasnn.experiments import SCHEMES, run_experiment, table_columns
from atlasnn.experiments.config import builtin_config_path, load_config, parse_config
from atlasnn.experiments.config._schema import SCHEME_NAMES
from atlasnn.experiments._suite import suite_members

# the module's fixture trains for a quarter to half a minute: the long tier
pytestmark = pytest.mark.long

CONFIG = """
name = "solve-run"
models = ["atlas_exp"]
seeds = [0, 1]
schemes = ["solve"]

[system]
name = "nonlinear_oscillator"

[interval]
T = "4*pi"

[march]
models = ["atlas_exp"]

[solve]
rtol = 1e-11

[evaluation]
eval_points = 300
"""


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    out = tmp_path_factory.mktemp("solve") / "run"
    cfg = parse_config(tomllib.loads(CONFIG), source="s.toml")
    return out, cfg, run_experiment(cfg, out, progress=False, log=lambda *a: None, config_text=CONFIG)


def test_only_the_named_scheme_runs_and_its_column_is_measured(done):
    out, cfg, res = done
    assert res["columns"] == table_columns(cfg) == ["se", "gauss"]
    recs = [r for r in res["runs"] if r["column"] == "gauss"]
    assert [r["seed"] for r in recs] == [0, 1] and {r["role"] for r in recs} == {"solve"}
    for r in recs:
        assert r["metrics"]["relative_max"] <= 1e-9  # measured against the run's DOP853 reference
        assert r["estimate"]["relative_max"] <= 1e-9 and r["quality"]["status"] == "ok"
        assert r["returned_loss"] <= 1.0 and r["rtol"] == 1e-11
    # deterministic: every seed records the one solution
    assert recs[0]["edges"] == recs[1]["edges"]


@pytest.mark.slow  # 15 s; the collocation solver is deprecated (its seeds: tests/solver/test_collocation_solver.py)
def test_the_collocation_method_draws_features_per_seed(tmp_path):
    text = CONFIG.replace("[solve]\nrtol = 1e-11", '[solve]\nmethod = "collocation"\nrtol = 1e-10')
    cfg = parse_config(tomllib.loads(text), source="s.toml")
    res = run_experiment(cfg, tmp_path / "run", progress=False, log=lambda *a: None, config_text=text)
    assert res["columns"] == ["se", "collocation"]
    recs = [r for r in res["runs"] if r["column"] == "collocation"]
    assert recs[0]["edges"] != recs[1]["edges"]  # the two seeds drew different features: different windows
    assert all(r["metrics"]["relative_max"] <= 1e-8 for r in recs)


def test_the_saved_solution_is_the_measured_one_and_is_accurate_on_its_own(done):
    out, cfg, res = done
    rec = next(r for r in res["runs"] if r["column"] == "gauss" and r["seed"] == 1)
    sol = load_piecewise(out / rec["checkpoint"])
    t = np.linspace(0.0, 4 * np.pi, 777)  # not the run's grid
    ref = reference_solution(sol.system, sol.system.initial_state(None), t, rtol=1e-13, atol=1e-13)
    assert np.abs(sol(t) - ref).max() <= 1e-9 * np.ptp(ref, axis=0).max()
    assert (out / "tables.md").read_text(encoding="utf-8").count("Gauss collocation (float64)") >= 1


def test_without_schemes_every_table_runs_and_the_scheme_names_match_the_registry():
    data = tomllib.loads(CONFIG)
    del data["schemes"]
    cfg = parse_config(data, source="s.toml")
    assert table_columns(cfg) == ["se", "atlas_exp", "atlas_exp_march", "gauss"]
    assert tuple(SCHEMES) == SCHEME_NAMES


def test_every_suite_problem_and_long_experiment_has_a_solve_profile():
    for name in suite_members("hard") + ["henon-heiles-long", "oscillator-long"]:
        cfg = load_config(builtin_config_path(name), profile="solve")
        assert table_columns(cfg) == ["se", "gauss"], name
        assert cfg.solve.solver.name == "gauss" and cfg.evaluation.reference_rtol == 2.3e-14


def test_a_transfer_config_can_run_the_solver_alone_and_its_report_has_no_loss_figures(tmp_path):
    from support import TRANSFER

    text = TRANSFER.replace("seeds = [0]", 'seeds = [0]\nschemes = ["solve"]') + "\n[solve]\nrtol = 1e-10\n"
    data = tomllib.loads(text)
    data["target"]["train"]["tolerance"] = 1e-5  # the report would draw it against the trainings' losses
    cfg = parse_config(data, source="t.toml")
    res = run_experiment(cfg, tmp_path / "run", progress=False, log=lambda *a: None, config_text=text)
    assert res["columns"] == ["se", "gauss"]
    figures = {p.stem for p in (tmp_path / "run" / "figures").glob("*.png")}
    assert "trajectories" in figures and not {"loss", "target_loss_comparison"} & figures

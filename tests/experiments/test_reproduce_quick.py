"""End to end: a quick reproduction through the CLI, and the contents of what it writes."""

import csv
import json
import math

import matplotlib.image as mpimg
import numpy as np
import pytest

from atlasnn.checkpoint import load_checkpoint
from atlasnn.cli import main
from atlasnn.experiments.config import _config as config_module
from atlasnn.experiments.config import builtin_config_path

# the module's fixture trains for a quarter to half a minute: the long tier
pytestmark = pytest.mark.long


CI_QUICK = "[quick]\ntrain = { epochs = 3000, chunk = 1000 }\nevaluation = { eval_points = 2000 }\n"


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """``reproduce oscillator-short --quick`` with a 3 000-epoch [quick] table: the shipped one
    trains 20 000 epochs (about a minute, to show the method working), too long for every CI run;
    everything else is the shipped config, read through the same ``reproduce`` path."""
    shipped = builtin_config_path("oscillator-short").read_text()
    head, sep, tail = shipped.partition("\n[quick]\n")
    assert sep and "\n[" not in tail, "the [quick] table is the shipped file's last table"
    configs = tmp_path_factory.mktemp("configs")
    (configs / "oscillator-short.toml").write_text(head + "\n" + CI_QUICK)
    out = tmp_path_factory.mktemp("run") / "oscillator-short-quick"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(config_module, "builtin_config_dir", lambda: configs)
        assert main(["reproduce", "oscillator-short", "--quick", "--out", str(out), "--no-progress", "--pdf"]) == 0
    return out


def test_results_are_complete_and_finite(quick_run):
    res = json.loads((quick_run / "results.json").read_text())
    assert res["columns"] == ["se", "hnn", "atlas_tanh", "atlas_exp"]
    assert {r["column"] for r in res["runs"]} == {"hnn", "atlas_tanh", "atlas_exp"}
    for r in res["runs"]:
        for metric in ("l2_discrete", "l2_integral", "mse", "max_abs"):
            for name in ("x", "p"):
                assert math.isfinite(r["metrics"][metric][name]) and r["metrics"][metric][name] > 0
        assert r["epochs"] == 3000 and r["stop_reason"] == "budget"
        assert r["best_epoch"] >= 0.8 * 3000  # the release's best-parameter rule
    gam = {r["column"]: r["gamma"] for r in res["runs"]}
    assert gam["hnn"] == {} and set(gam["atlas_tanh"]) == {"m"} and set(gam["atlas_exp"]) == {"alpha", "beta"}
    # the reference conserves energy; SE is measured on its own K-point grid
    assert res["reference_energy_drift"] < 1e-9
    se = {i["column"]: i for i in res["integrators"]}
    assert se["se"]["steps"] == 199 and se["se_100"]["steps"] == 19900
    # SE on this grid reproduces the paper's tabulated L2(x) = 1.43 (deterministic, no training)
    assert se["se"]["metrics"]["l2_discrete"]["x"] == pytest.approx(1.43, rel=0.01)
    assert se["se_100"]["metrics"]["l2_discrete"]["x"] < se["se"]["metrics"]["l2_discrete"]["x"]


def test_tables_have_every_row_and_column(quick_run):
    md = (quick_run / "tables.md").read_text()
    for label in ("SE", "HNN", "ATLAS-NN (tanh)", "ATLAS-NN (exp)", "Improvement"):
        assert f"| {label} |" in md or f" {label} |" in md
    for row in ("L2(x)", "L2(p)", "MSE(x)", "MSE(p)", "L2∫(x)"):
        assert f"| {row}" in md
    assert "(paper 4.31e-3)" in md  # the paper's value beside ours
    rows = list(csv.DictReader((quick_run / "tables.csv").open()))
    errs = [r for r in rows if r["table"] == "errors" and r["metric"] == "l2_discrete"]
    assert {(r["state"], r["column"]) for r in errs} >= {(s, c) for s in "xp" for c in ("se", "hnn", "atlas_tanh", "atlas_exp")}
    for r in errs:
        assert float(r["ours_median"]) > 0
    tex = (quick_run / "tables.tex").read_text()
    assert tex.count("\\begin{tabular}") == tex.count("\\end{tabular}") >= 1


FIGURES = ["scaling_families", "loss", "gamma", "overview", "trajectories", "errors", "energy", "seed_spread_l2_x"]


@pytest.mark.parametrize("stem", FIGURES)
def test_figures_are_real_images(quick_run, stem):
    png = quick_run / "figures" / f"{stem}.png"
    img = mpimg.imread(png)
    assert img.shape[0] > 200 and img.shape[1] > 200
    assert float(np.std(img[..., :3])) > 0.01  # not a blank canvas
    assert (quick_run / "figures" / f"{stem}.pdf").read_bytes()[:4] == b"%PDF"


def test_checkpoints_reproduce_the_stored_predictions(quick_run):
    arrays = np.load(quick_run / "arrays.npz")
    ck = load_checkpoint(quick_run / "models" / "atlas_exp_seed0.npz")
    z = ck.solution()(arrays["t_eval"])
    np.testing.assert_array_equal(z.astype(np.float64), arrays["pred_atlas_exp_seed0"])
    assert ck.meta["extra"]["experiment"] == "oscillator-short"
    assert len(ck.history) == 3000


def test_report_rerenders_without_training(quick_run, capsys):
    before = {p.name: p.stat().st_mtime_ns for p in (quick_run / "models").iterdir()}
    (quick_run / "tables.md").unlink()
    assert main(["report", str(quick_run)]) == 0
    assert (quick_run / "tables.md").exists()
    assert {p.name: p.stat().st_mtime_ns for p in (quick_run / "models").iterdir()} == before
    out = capsys.readouterr().out
    assert "L2(x)" in out and "QUICK RUN" in out
    assert f"overview: {quick_run / 'figures' / 'overview.png'}" in out


def test_existing_run_is_not_overwritten(quick_run, capsys):
    assert main(["reproduce", "oscillator-short", "--quick", "--out", str(quick_run), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--overwrite" in err and err.count("\n") == 1


def test_user_config_for_a_system_the_package_does_not_ship(tmp_path):
    cfg = tmp_path / "pendulum.toml"
    cfg.write_text(
        'name = "pendulum"\nmodels = ["atlas_exp"]\n'
        '[system]\nhamiltonian = "p**2/2 - cos(q)"\ncoordinates = ["q"]\nmomenta = ["p"]\n'
        "separable = true\nz0 = [1.0, 0.0]\n"
        '[network]\nwidth = 16\n[interval]\nT = "2*pi"\n'
        "[train]\nepochs = 400\nlr = 5e-3\nn_points = 50\nchunk = 200\n"
        "[evaluation]\neval_points = 200\nfine_factor = 10\n"
    )
    out = tmp_path / "out"
    assert main(["run", str(cfg), "--out", str(out), "--no-progress"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["state_names"] == ["q", "p"]
    assert res["energy0"] == pytest.approx(-math.cos(1.0))
    assert res["runs"][0]["metrics"]["l2_discrete"]["q"] > 0
    assert (out / "figures" / "trajectories.png").exists()

"""The simultaneous collocation fit (:func:`atlasnn.inverse.fit_collocation`): from starts where
shooting lands in a false minimum or cannot integrate its orbit, it reaches the data's global
minimum (shooting started at the truth, an independent fit); its own σ, without the polish, agrees
with shooting's; bad settings are one line; a family run takes it as a method."""

from __future__ import annotations

import json

import numpy as np
import pytest

from atlasnn.cli import main
from atlasnn.errors import AtlasError, ConfigError
from atlasnn.experiments.config import load_family
from atlasnn.inverse import CollocationFit, fit_collocation, fit_shooting, synthetic_observations
from atlasnn.observations import Unknown
from atlasnn.systems import expression_system, henon_heiles

HH = henon_heiles(lam=0.8)
TIMES = np.sort(np.random.default_rng(7).uniform(0.0, 20.0, 50))
OBS = synthetic_observations(HH, HH.initial_state(), TIMES, ["x", "y"], 0.01, 0)


def _global(system, obs, unknowns):
    """The data's global minimum: shooting started at the truth."""
    return fit_shooting(system, obs, unknowns)


@pytest.mark.long
def test_from_a_start_where_single_shooting_is_trapped_it_reaches_the_global_minimum():
    bad = [Unknown("lam", 1.35, 0.2, 1.5)]
    assert abs(fit_shooting(HH, OBS, bad).value("lam") - 0.8) > 0.3  # single shooting: a false minimum
    best = _global(HH, OBS, [Unknown("lam", 0.8, 0.2, 1.5)])
    fit = fit_collocation(HH, OBS, bad)
    assert abs(fit.value("lam") - best.value("lam")) <= 0.5 * best.std[0]
    assert fit.trusted and fit.method == "collocation"
    # the collocation estimate itself, before the polish, was already in the global minimum's basin
    assert abs(fit.search["collocation_estimate"][0] - best.value("lam")) <= 2 * best.std[0]
    assert fit.search["windows"] >= 2 and len(fit.search["lm_steps"]) == len(CollocationFit().penalties)


@pytest.mark.slow  # 40 s; the trapped-start and parameter-with-momentum fits check the collocation fit (CI stays under 30 min)
def test_a_chaotic_record_where_shooting_cannot_integrate_from_the_start():
    hh = henon_heiles(lam=1.0)
    hh = expression_system("(px**2 + py**2)/2 + (x**2 + y**2)/2 + lam*(x**2*y - y**3/3)", ["x", "y"], ["px", "py"],
                           params={"lam": 1.0}, z0=[0.0, -0.1, 0.4788875998951459, 0.1], name="hh")
    times = np.sort(np.random.default_rng(7).uniform(0.0, 40.0, 100))
    obs = synthetic_observations(hh, hh.initial_state(), times, ["x", "y"], 0.01, 0)
    start = [Unknown("lam", 1.45, 0.5, 1.5)]
    with pytest.raises(AtlasError):  # the orbit from the start escapes before the last observation
        fit_shooting(hh, obs, start)
    best = _global(hh, obs, [Unknown("lam", 1.0, 0.5, 1.5)])
    fit = fit_collocation(hh, obs, start)
    assert abs(fit.value("lam") - best.value("lam")) <= 0.5 * best.std[0] and fit.trusted


@pytest.mark.long
def test_a_parameter_and_an_initial_momentum_together():
    unknowns = [Unknown("lam", 1.24, 0.2, 1.5), Unknown("z0.px", 0.12, 0.0, 0.6)]
    best = _global(HH, OBS, [Unknown("lam", 0.8, 0.2, 1.5), Unknown("z0.px", 0.3, 0.0, 0.6)])
    fit = fit_collocation(HH, OBS, unknowns)
    assert np.all(np.abs(fit.estimate - best.estimate) <= 0.5 * best.std)
    assert fit.names == ("lam", "z0.px")


@pytest.mark.long
def test_without_the_polish_its_own_sigma_agrees_with_shootings():
    pend = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], params={"g": 1.0}, z0=[1.0, 0.0], name="pendulum")
    times = np.sort(np.random.default_rng(7).uniform(0.0, 8.0, 40))
    obs = synthetic_observations(pend, pend.initial_state(), times, ["x"], 0.01, 0)
    best = _global(pend, obs, [Unknown("g", 1.0, 0.5, 2.0)])
    fit = fit_collocation(pend, obs, [Unknown("g", 0.6, 0.5, 2.0)], config=CollocationFit(polish=False))
    assert abs(fit.value("g") - best.value("g")) <= 0.2 * best.std[0]
    assert 0.7 <= fit.std[0] / best.std[0] <= 1.4
    assert "not polished" in fit.message


@pytest.mark.parametrize("settings, needle", [
    (dict(windows=0), "windows must be a positive integer"),
    (dict(features=0), "features must be a positive integer"),
    (dict(points=4), "points must be an integer ≥ features"),
    (dict(penalties=(1e4, 1e3)), "penalties must be positive and increasing"),
    (dict(scale=float("nan")), "scale must be a positive number"),
])
def test_bad_settings_are_one_line(settings, needle):
    with pytest.raises(ConfigError, match=needle):
        CollocationFit(**settings)


def test_bad_unknowns_are_refused_as_themselves():
    with pytest.raises(ConfigError, match="lamb"):
        fit_collocation(HH, OBS, [Unknown("lamb", 1.0, 0.2, 1.5)])


def _family(tmp_path, fit_table: str) -> str:
    cfg = tmp_path / "inv.toml"
    cfg.write_text('name = "inv"\ndescription = "d"\nseeds = [0]\n[system]\nname = "henon_heiles"\n'
                   '[observations]\nn = 30\nT = 8.0\nnames = ["x", "y"]\n[unknowns]\n'
                   'lam = { guess = 1.4, low = 0.2, high = 1.5 }\n' + fit_table, encoding="utf-8")
    return str(cfg)


@pytest.mark.long
def test_a_family_run_fits_by_collocation_and_records_it(tmp_path, capsys):
    cfg = _family(tmp_path, '[fit]\nmethods = ["collocation", "shooting"]\nstarts = 3\ncollocation_features = 12\n')
    assert main(["family", cfg, "--out", str(tmp_path / "out")]) == 0
    records = json.loads((tmp_path / "out" / "results.json").read_text())["records"]
    col = [r for r in records if r["method"] == "collocation"]
    assert len(col) == 1 and abs(col[0]["estimate"][0] - 1.0) < 5 * col[0]["std"][0]
    assert "seed 0 collocation: lam = " in capsys.readouterr().out


def test_the_fit_table_checks_the_collocation_keys(tmp_path):
    with pytest.raises(ConfigError, match="fit.collocation_windows"):
        load_family(_family(tmp_path, '[fit]\nmethods = ["collocation"]\ncollocation_windows = 0\n'))


@pytest.mark.long
def test_data_that_start_long_after_t0_anchor_the_start_at_the_initial_value():
    quartic = expression_system("p**2/2 + a*x**4/4", ["x"], ["p"], params={"a": 1.0}, z0=[1.0, 0.0], name="quartic")
    times = np.sort(np.random.default_rng(0).uniform(5.0, 15.0, 30))  # nothing observed on [0, 5)
    obs = synthetic_observations(quartic, quartic.initial_state(), times, ["x"], 0.01, 0)
    best = _global(quartic, obs, [Unknown("a", 1.0, 0.2, 5.0)])
    fit = fit_collocation(quartic, obs, [Unknown("a", 2.6, 0.2, 5.0)])
    assert abs(fit.value("a") - best.value("a")) <= 0.5 * best.std[0] and fit.trusted

"""One door for inverse fits: :func:`atlasnn.inverse.fit` with method objects; a config's
``[fit] methods`` names the same objects through one registry, and a new method is one class and
one entry."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.experiments.config import load_family
from atlasnn.inverse import (FIT_METHODS, AbstractFitMethod, BundleFit, CollocationFit, Joint, Shooting, fit, fit_shooting,
                             register_fit_method, synthetic_observations)
from atlasnn.observations import Unknown
from atlasnn.systems import henon_heiles

HH = henon_heiles(lam=0.8)
OBS = synthetic_observations(HH, HH.initial_state(), np.linspace(0.5, 10.0, 30), ["x", "y"], 0.01, 0)
LAM = [Unknown("lam", 0.9, 0.2, 1.5)]


@pytest.mark.long
def test_shooting_through_the_door_is_fit_shooting():
    direct = fit_shooting(HH, OBS, LAM)
    door = fit(HH, OBS, LAM, method=Shooting(starts=1))
    assert np.array_equal(door.estimate, direct.estimate) and np.array_equal(door.std, direct.std)


def test_the_default_method_is_the_multistart():
    result = fit(HH, OBS, LAM)
    assert result.search["starts"] == 13 and "13 starts" in result.method


@pytest.mark.long
def test_the_collocation_method_object_takes_the_doors_seed():
    a = fit(HH, OBS, LAM, method=CollocationFit(features=12), seed=3)
    assert a.method == "collocation" and abs(a.value("lam") - fit_shooting(HH, OBS, LAM).value("lam")) < 0.5 * a.std[0]


def test_a_name_instead_of_an_object_is_refused_naming_the_object():
    with pytest.raises(ConfigError, match=r"use CollocationFit\(\)"):
        fit(HH, OBS, LAM, method="collocation")


def test_the_registry_holds_the_built_in_methods_by_their_config_names():
    assert {n: c for n, c in FIT_METHODS.items() if n in ("shooting", "joint", "bundle", "collocation")} == {
        "shooting": Shooting, "joint": Joint, "bundle": BundleFit, "collocation": CollocationFit}
    with pytest.raises(ConfigError, match="AbstractFitMethod subclass"):
        register_fit_method(dict)


def _config(tmp_path, fit_table):
    path = tmp_path / "inv.toml"
    path.write_text('name = "inv"\ndescription = "d"\nseeds = [0]\n[system]\nname = "henon_heiles"\n'
                    '[observations]\nn = 30\nT = 8.0\nnames = ["x", "y"]\n[unknowns]\n'
                    'lam = { guess = 0.9, low = 0.2, high = 1.5 }\n' + fit_table, encoding="utf-8")
    return path


def test_a_configs_settings_reach_the_method_objects(tmp_path):
    cfg = load_family(_config(tmp_path, '[fit]\nmethods = ["shooting", "collocation"]\nsegments = 3\nstarts = 5\n'
                                        'collocation_features = 12\n'))
    shooting, collocation = cfg.fit.method_objects()
    assert shooting == Shooting(segments=3, starts=5)
    assert collocation == CollocationFit(features=12)


@dataclasses.dataclass(frozen=True)
class _GuessOnly(AbstractFitMethod):
    """A method of this test: shooting from the guess, under another name."""

    name = "guess-only"

    def fit(self, system, observations, unknowns, *, z0=None, t0=0.0, seed=0):
        return fit_shooting(system, observations, unknowns, z0, t0=t0)

    def describe(self, unknowns):
        return "shooting from the guess alone"


@pytest.mark.long
def test_a_new_method_is_one_class_and_one_entry_and_a_config_can_name_it(tmp_path, capsys):
    register_fit_method(_GuessOnly)
    try:
        path = _config(tmp_path, '[fit]\nmethods = ["guess-only"]\n')
        assert main(["family", str(path), "--out", str(tmp_path / "out")]) == 0
        records = json.loads((tmp_path / "out" / "results.json").read_text())["records"]
        assert [r["method"] for r in records] == ["guess-only"] and "estimate" in records[0]
        assert "fitting (shooting from the guess alone)" in capsys.readouterr().out
    finally:
        FIT_METHODS.pop("guess-only")
    with pytest.raises(ConfigError, match="fit.methods"):
        load_family(path)


def test_auto_segments_from_a_config(tmp_path):
    cfg = load_family(_config(tmp_path, '[fit]\nmethods = ["shooting"]\nsegments = "auto"\nstarts = 1\n'))
    assert cfg.fit.method_objects() == (Shooting(segments="auto", starts=1),)
    with pytest.raises(ConfigError, match="fit.segments"):
        load_family(_config(tmp_path, '[fit]\nsegments = "many"\n'))


def test_family_no_progress_prints_the_results_but_not_the_phases(tmp_path, capsys):
    path = _config(tmp_path, '[fit]\nmethods = ["shooting"]\nstarts = 1\n')
    assert main(["family", str(path), "--out", str(tmp_path / "a")]) == 0
    assert "seed 0 shooting: fitting (shooting)…" in capsys.readouterr().out
    assert main(["family", str(path), "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    quiet = capsys.readouterr().out
    assert "fitting" not in quiet and "seed 0 shooting: lam = " in quiet


def test_a_run_on_file_observations_prints_no_nan_where_there_is_no_truth(tmp_path):
    rows = "\n".join(f"{t},{x}" for t, x in zip(OBS.t, OBS.values[:, 0]))
    (tmp_path / "obs.csv").write_text("t,x\n" + rows + "\n", encoding="utf-8")
    path = tmp_path / "file.toml"
    path.write_text('name = "file"\ndescription = "d"\nseeds = [0]\n[system]\nname = "henon_heiles"\n'
                    'params = { lam = 0.8 }\n[observations]\nfile = "obs.csv"\n[unknowns]\n'
                    'lam = { guess = 0.9, low = 0.2, high = 1.5 }\n[fit]\nmethods = ["shooting"]\nstarts = 1\n',
                    encoding="utf-8")
    assert main(["family", str(path), "--out", str(tmp_path / "run"), "--no-progress"]) == 0
    summary = (tmp_path / "run" / "summary.md").read_text()
    assert "nan" not in summary and "n/a/?" not in summary and "— (no truth)" in summary


def test_an_interrupted_family_run_resumes_from_the_seeds_it_finished(tmp_path, capsys, monkeypatch):
    """Before, `family` had no --resume: an interrupted run lost every finished seed."""
    import atlasnn.experiments._family_run as family_run

    path = _config(tmp_path, '[fit]\nmethods = ["shooting"]\nstarts = 1\n').with_name("inv.toml")
    path.write_text(path.read_text().replace("seeds = [0]", "seeds = [0, 1, 2]"), encoding="utf-8")
    out = tmp_path / "run"
    real, fitted = family_run._fit_seed, []

    def interrupted_at_seed_1(cfg, truth, say, seed):
        if seed == 1:
            raise KeyboardInterrupt
        fitted.append(seed)
        return real(cfg, truth, say, seed)

    monkeypatch.setattr(family_run, "_fit_seed", interrupted_at_seed_1)
    assert main(["family", str(path), "--out", str(out), "--no-progress"]) == 130
    assert f"atlasnn family --resume {out}" in capsys.readouterr().err
    assert not (out / "results.json").exists() and (out / "partial" / "seed0.json").exists()
    kept = json.loads((out / "partial" / "seed0.json").read_text())["records"][0]["estimate"]

    monkeypatch.setattr(family_run, "_fit_seed", lambda *a: (fitted.append(a[-1]), real(*a))[1])
    assert main(["family", "--resume", str(out), "--no-progress"]) == 0
    assert fitted == [0, 1, 2]  # seed 0 was not fitted again
    records = json.loads((out / "results.json").read_text())["records"]
    assert [r["seed"] for r in records] == [0, 1, 2] and records[0]["estimate"] == kept
    assert not (out / "partial").exists() and (out / "figures" / "fit_trajectory.png").exists()
    capsys.readouterr()
    assert main(["family", "--resume", str(out)]) == 2
    assert "the run is complete (results.json is written)" in capsys.readouterr().err


@pytest.mark.slow  # 26 s, worker processes; the interrupted family run checks the same family records in one process (CI stays under 30 min)
def test_family_seeds_run_in_worker_processes_with_jobs(tmp_path, capsys):
    """`family --jobs 2`: the seeds are tasks of the local executor (two processes), the same
    estimates as in this process; before, --jobs did not exist for family runs."""
    path = _config(tmp_path, '[fit]\nmethods = ["shooting"]\nstarts = 1\n')
    path.write_text(path.read_text().replace("seeds = [0]", "seeds = [0, 1]"), encoding="utf-8")
    assert main(["family", str(path), "--out", str(tmp_path / "one"), "--no-progress"]) == 0
    assert main(["family", str(path), "--out", str(tmp_path / "two"), "--no-progress", "--jobs", "2"]) == 0
    one, two = (json.loads((tmp_path / d / "results.json").read_text())["records"] for d in ("one", "two"))
    assert [r["estimate"] for r in one] == [r["estimate"] for r in two] and len(two) == 2
    assert "seed 1 shooting: lam = " in capsys.readouterr().out  # the workers' lines, printed here

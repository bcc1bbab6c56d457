"""Inverse problems with networks: the joint fit (data + Hamilton's equations) and the bundle fit,
each against the classical shooting baseline on the same data; their config and its errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.inverse import fit_shooting, synthetic_observations
from atlasnn.experiments.config import load_family, parse_family
from atlasnn.inverse import JointConfig, bundle_box_for, fit_joint, fit_with_bundle
from atlasnn.observations import Unknown
from atlasnn.systems import expression_system
from atlasnn.training import BundleTrainConfig, train_bundle

PEND = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], {"g": 1.0}, z0=[1.0, 0.0], name="pendulum")
TIMES = np.linspace(0.2, 6.0, 30)
SMALL = JointConfig(width=24, epochs=500, lm_steps=60)


@pytest.mark.slow  # 30-60 s; the family end to end below checks the joint fit against shooting
def test_joint_fit_recovers_g_from_noise_free_data():
    obs = synthetic_observations(PEND, PEND.z0, TIMES, ["x"], 0.0, 0, t0=0.0)
    fit = fit_joint(PEND, obs, [Unknown("g", 0.6, 0.2, 3.0)], config=SMALL)
    assert abs(fit.value("g") - 1.0) < 1e-4, fit.estimate  # measured: 5e-7
    assert fit.method == "network (joint)" and fit.identifiable


@pytest.mark.slow  # over a minute on the 2-core machine: run with -m slow (CI stays under 30 min)
def test_joint_fit_agrees_with_shooting_under_noise():
    """Same data, same unknowns (g and the initial momentum): the network's estimate lies well
    within shooting's standard error of shooting's, and its own σ (the tangent Gauss–Newton
    estimate) is shooting's to 20 %."""
    obs = synthetic_observations(PEND, PEND.z0, TIMES, ["x"], 0.01, 1, t0=0.0)
    unknowns = [Unknown("g", 0.6, 0.2, 3.0), Unknown("z0.p", 0.1, -0.5, 0.5)]
    net, shoot = fit_joint(PEND, obs, unknowns, config=SMALL), fit_shooting(PEND, obs, unknowns)
    assert np.all(np.abs(net.estimate - shoot.estimate) < 0.5 * shoot.std), (net.estimate, shoot.estimate)
    np.testing.assert_allclose(net.std, shoot.std, rtol=0.2)
    assert np.all(np.abs(shoot.estimate - [1.0, 0.0]) < 3 * shoot.std)


@pytest.mark.long
def test_bundle_fit_recovers_g():
    obs = synthetic_observations(PEND, PEND.z0, TIMES[TIMES <= 3.0], ["x"], 0.0, 0, t0=0.0)
    unknowns = [Unknown("g", 0.7, 0.5, 1.5)]
    box = bundle_box_for(PEND, unknowns, None, 3.0)
    trained = train_bundle(PEND, box, BundleTrainConfig(epochs=1500, chunk=500, lm_steps=40, lm_points=128),
                           width=16, seed=0)
    fit = fit_with_bundle(trained.solution, obs, unknowns)
    assert abs(fit.value("g") - 1.0) < 5e-3, fit.estimate
    with pytest.raises(ConfigError, match="leave the bundle's range"):
        fit_with_bundle(trained.solution, obs, [Unknown("g", 0.7, 0.1, 1.5)])


BASE = {
    "name": "t", "seeds": [0],
    "system": {"hamiltonian": "p**2/2 - g*cos(x)", "coordinates": ["x"], "momenta": ["p"], "params": {"g": 1.0},
               "z0": [1.0, 0.0]},
    "observations": {"n": 20, "T": 4.0, "names": ["x"], "noise": 0.01},
    "unknowns": {"g": {"guess": 0.6, "low": 0.2, "high": 3.0}},
}


@pytest.mark.parametrize("change, match", [
    ({"unknowns": {"g": {"guess": 0.6}}}, "needs bounds: give low and high"),
    ({"unknowns": {"g": {"guess": 5.0, "low": 0.2, "high": 3.0}}}, "outside"),
    ({"unknowns": {"mu": {"low": 0.2, "high": 3.0}}}, None),  # named at run time (check_unknowns)
    ({"observations": {"n": 20, "names": ["x"]}}, "give a file, or synthetic data"),
    ({"fit": {"methods": ["magic"]}}, "fit.methods"),
    ({"observations": {"file": "x.csv", "n": 3}}, "cannot be combined with file"),
])
def test_inverse_config_errors(change, match):
    data = {**BASE, **change}
    if match is None:
        parse_family(data)
        return
    with pytest.raises(ConfigError, match=match) as info:
        parse_family(data)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("bundle, match", [
    ({"T": 4.0, "z0_rel": 0.0}, "zero width"),
    ({"T": 4.0, "ranges": {"g": [1.0, 1.0]}}, "zero width"),
    ({"z0_rel": 0.1}, "bundle.T"),
    ({"T": 4.0, "windows": 0}, "bundle.windows"),
    ({"T": 4.0, "ranges": {"k": [0.5, 1.5]}}, "'k' is not a parameter"),
])
def test_bundle_config_errors(bundle, match):
    data = {k: v for k, v in BASE.items() if k not in ("observations", "unknowns")}
    cfg_or_error = None
    with pytest.raises(ConfigError, match=match):
        cfg_or_error = parse_family({**data, "bundle": bundle})
        cfg_or_error.bundle.box(cfg_or_error.system.build())


def test_file_observations_and_too_many_unknowns(tmp_path, capsys):
    csv = tmp_path / "obs.csv"
    csv.write_text("t,x\n0.5,0.9\n1.0,0.6\n")
    toml = tmp_path / "fit.toml"
    toml.write_text('name = "f"\n[system]\nname = "nonlinear_oscillator"\n[observations]\nfile = "obs.csv"\n'
                    '[unknowns]\nlam = { guess = 1.0, low = 0.5, high = 2.0 }\n"z0.x" = { guess = 1.3, low = 1, high = 2 }\n')
    cfg = load_family(toml)
    assert cfg.observations.file == str(csv)
    assert main(["family", str(toml), "--out", str(tmp_path / "run")]) != 0
    err = capsys.readouterr().err
    assert "more unknowns than the data" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow  # two minutes; the family command's parts run in test_fit_door (an interrupted family run) and test_collocation_fit (a family run)
def test_family_command_end_to_end(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["family", "pendulum-inverse", "--quick", "--seeds", "1", "--out", str(out)]) == 0
    res = json.loads((out / "results.json").read_text())
    assert {r["method"] for r in res["records"]} == {"joint", "bundle", "collocation", "shooting"}
    shoot = next(r for r in res["records"] if r["method"] == "shooting")
    joint = next(r for r in res["records"] if r["method"] == "joint")
    assert abs(joint["estimate"][0] - shoot["estimate"][0]) < 2 * shoot["std"][0]
    col = next(r for r in res["records"] if r["method"] == "collocation")
    assert abs(col["estimate"][0] - shoot["estimate"][0]) < 0.5 * shoot["std"][0]
    assert (out / "figures" / "estimates_g.png").is_file() and (out / "summary.md").is_file()
    assert main(["family"]) == 0 and "pendulum-inverse" in capsys.readouterr().out

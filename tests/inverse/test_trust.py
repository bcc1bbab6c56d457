"""Inverse fits from bad starts, and the rules that mark a fit untrusted: the multistart finds the
global minimum where single shooting lands in a false one; an estimate at a bound, a second
minimum as good, a local minimum beside a better fit are marked; a family run keeps every fit
when a method or a figure fails, and refuses bad input before writing anything."""

from __future__ import annotations

import json

import numpy as np
import pytest

from atlasnn.cli import main
from atlasnn.errors import AtlasError, ConfigError
from atlasnn.inverse import FitResult, fit_shooting, shooting_misfit, synthetic_observations
from atlasnn.experiments import _family_run
from atlasnn.inverse import Joint, fit_multistart, judge_fit
from atlasnn.observations import Unknown
from atlasnn.systems import henon_heiles

HH = henon_heiles(lam=0.8)
TIMES = np.sort(np.random.default_rng(7).uniform(0.0, 20.0, 50))
OBS = synthetic_observations(HH, HH.initial_state(), TIMES, ["x", "y"], 0.01, 0)


@pytest.mark.long
def test_single_shooting_from_a_bad_guess_is_wrong_and_marked_the_multistart_is_right():
    bad = [Unknown("lam", 1.35, 0.2, 1.5)]
    single = fit_shooting(HH, OBS, bad)
    assert abs(single.value("lam") - 0.8) > 0.3 and not single.trusted  # a false minimum, flagged
    multi = fit_multistart(HH, OBS, bad, starts=7)
    assert abs(multi.value("lam") - 0.8) <= 2 * multi.std[0] and multi.trusted
    assert multi.search["starts"] == 7 and len(multi.search["minima"]) >= 2  # it met the false one too
    assert multi.method == "shooting (7 starts)"


def test_an_estimate_at_a_bound_is_untrusted_and_says_which():
    fit = fit_shooting(HH, OBS, [Unknown("lam", 1.0, 0.9, 1.5)])  # the truth 0.8 lies below the bounds
    fit = judge_fit(fit, [Unknown("lam", 1.0, 0.9, 1.5)])
    assert not fit.trusted and any("sits at its bound low = 0.9" in n for n in fit.notes)


def _result(estimate, noise=0.01, minima=()):
    return FitResult(names=("lam",), estimate=np.array([estimate]), std=np.array([0.001]),
                     covariance=np.eye(1) * 1e-6, noise_estimate=noise, residual_rms=noise, wall_time=0.0,
                     n_rhs=0, n_solves=0, method="shooting", success=True, message="", identifiable=True,
                     n_data=100, search={"minima": list(minima)} if minima else {})


def test_a_second_minimum_as_good_marks_the_fit_and_a_clearly_worse_one_does_not():
    unknowns = [Unknown("lam", 1.0, 0.2, 1.5)]
    rss = 0.01 ** 2 * 99
    close = [{"estimate": [0.8], "rss": rss}, {"estimate": [1.2], "rss": rss + 0.01 ** 2 * 2.0}]
    far = [{"estimate": [0.8], "rss": rss}, {"estimate": [1.2], "rss": rss + 0.01 ** 2 * 50.0}]
    assert not judge_fit(_result(0.8, minima=close), unknowns).trusted  # Δχ² = 2 < χ²₁(0.99) = 6.6
    assert judge_fit(_result(0.8, minima=far), unknowns).trusted


def test_a_fit_in_a_local_minimum_is_marked_against_a_better_fit_of_the_same_data():
    unknowns = [Unknown("lam", 0.6, 0.2, 1.5)]
    best = fit_multistart(HH, OBS, unknowns, starts=5)
    wrong = _result(1.39)
    wrong.t0 = 0.0
    judged = judge_fit(wrong, unknowns, system=HH, observations=OBS, better=best)
    assert not judged.trusted and "local minimum" in judged.notes[-1]
    assert shooting_misfit(HH, OBS, unknowns, [1.39]) > shooting_misfit(HH, OBS, unknowns, best.estimate)
    near = _result(float(best.estimate[0]))
    assert judge_fit(near, unknowns, system=HH, observations=OBS, better=best).trusted


def test_a_multistart_skips_starts_it_cannot_integrate_and_refuses_only_when_all_fail(monkeypatch):
    calls = []
    real = fit_shooting

    def flaky(system, obs, unknowns, *a, **kw):
        calls.append(unknowns[0].guess)
        if len(calls) % 2:
            raise AtlasError("shooting cannot integrate system 'hh' at the initial guess: escapes")
        return real(system, obs, unknowns, *a, **kw)

    from atlasnn.inverse import _multistart
    monkeypatch.setattr(_multistart, "fit_shooting", flaky)
    fit = fit_multistart(HH, OBS, [Unknown("lam", 0.7, 0.2, 1.5)], starts=6)
    assert fit.search["failed_starts"] == 3 and len(calls) == 6 and fit.trusted
    monkeypatch.setattr(_multistart, "fit_shooting", lambda *a, **k: (_ for _ in ()).throw(AtlasError("escapes")))
    with pytest.raises(AtlasError, match="from any of 3 starts over the bounds .*narrow the bounds"):
        fit_multistart(HH, OBS, [Unknown("lam", 0.7, 0.2, 1.5)], starts=3)
    monkeypatch.setattr(_multistart, "fit_shooting", real)
    with pytest.raises(ConfigError, match="segments=40 needs at least 80 observation times"):
        fit_multistart(HH, OBS, [Unknown("lam", 0.7, 0.2, 1.5)], segments=40, starts=3)  # not "every start failed"


INVERSE = """
name = "trust"
seeds = [0]
[system]
name = "henon_heiles"
params = { lam = 0.8 }
[observations]
n = 40
T = 12.0
names = ["x", "y"]
noise = 0.01
[unknowns]
lam = { guess = 1.45, low = 0.2, high = 1.5 }
[fit]
methods = ["joint", "shooting"]
starts = 5
epochs = 0
lm_steps = 5
"""


def test_a_family_run_keeps_every_fit_when_a_method_or_a_figure_fails(tmp_path, monkeypatch, capsys):
    toml = tmp_path / "trust.toml"
    toml.write_text(INVERSE)
    monkeypatch.setattr(Joint, "fit", lambda *a, **k: (_ for _ in ()).throw(AtlasError("joint: boom")))

    def no_orbit(*a, **k):
        raise AtlasError("predict_fit: cannot integrate")

    monkeypatch.setattr(_family_run, "predict_fit", no_orbit)
    assert main(["family", str(toml), "--out", str(tmp_path / "run")]) == 0
    res = json.loads((tmp_path / "run" / "results.json").read_text())
    failed = [r for r in res["records"] if "failed" in r]
    shot = [r for r in res["records"] if r["method"] == "shooting" and "failed" not in r]
    assert [r["method"] for r in failed] == ["joint"] and len(shot) == 1
    assert abs(shot[0]["estimate"][0] - 0.8) < 4 * shot[0]["std"][0] and shot[0]["trusted"]
    assert any("trajectory is not drawn" in n for n in res["notes"])
    summary = (tmp_path / "run" / "summary.md").read_text()
    assert "**failed**" in summary and "joint: boom" in summary
    assert "FAILED — joint: boom" in capsys.readouterr().out


def test_bad_input_is_refused_before_the_run_directory_is_written(tmp_path, capsys):
    toml = tmp_path / "bad.toml"
    toml.write_text(INVERSE.replace("n = 40", "n = 3").replace("starts = 5", "starts = 5\nsegments = 4"))
    out = tmp_path / "run"
    assert main(["family", str(toml), "--out", str(out)]) == 2
    assert "segments=4 needs at least 8 observation times" in capsys.readouterr().err
    assert not out.exists()

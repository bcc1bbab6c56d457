"""Named profiles of a config (--profile release) and the release's target learning rate."""

from __future__ import annotations

import json
import tomllib

import pytest

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.experiments.config import builtin_config_path, builtin_experiments, load_config, parse_config

from support import TRANSFER

PROFILED = TRANSFER.replace('name = "resume-transfer"', 'name = "profiled"\nprofile = "paper"') + """
[profiles.release]
description = "as the release ran it"
train = { best_rule = "release_exact" }
target = { train = { epochs = 300, tolerance = 0.0 } }
transfer = { lr_from_source = true }
follows = { lr = "release: target at the source's lr" }

[quick]
source = { train = { epochs = 120 } }
target = { train = { epochs = 150 } }
"""


@pytest.mark.long
def test_every_paper_experiment_has_a_release_profile_that_changes_something():
    paper_short = [n for n in builtin_experiments()
                   if not n.endswith("-long") and not load_config(builtin_config_path(n)).suite]
    assert len(paper_short) == 4  # oscillator and Hénon–Heiles, short and transfer (the suite is apart)
    for name in paper_short:
        paper = load_config(builtin_config_path(name))
        release = load_config(builtin_config_path(name), profile="release")
        assert (paper.profile, release.profile) == ("paper", "release")
        assert paper != release and release.follows != paper.follows
        stage = release.stage or release.target
        assert stage.train.best_rule == "release_exact"
        assert load_config(builtin_config_path(name), profile="paper") == paper


def test_release_profile_holds_the_releases_facts():
    hh = load_config(builtin_config_path("henon-heiles-transfer"), profile="release")
    assert (hh.source.train.epochs, hh.target.train.epochs) == (20000, 50000)
    assert hh.source.train.tolerance == 0.0 and hh.target.train.tolerance == 0.0  # never met: no stop
    assert hh.lr_from_source and hh.source.train.lr == 3e-3
    assert hh.gamma_init == {"atlas_tanh": {"m": 3.0}, "atlas_exp": {"alpha": 2.0, "beta": 0.5}}
    short = load_config(builtin_config_path("henon-heiles-short"), profile="release")
    assert short.stage.train.epochs == 50000 and short.gamma_init["atlas_exp"] == {"alpha": 2.0, "beta": 0.5}
    osc = load_config(builtin_config_path("oscillator-transfer"), profile="release")
    assert osc.lr_from_source and osc.source.train.lr == 8e-3
    # the paper profile keeps the paper's numbers
    assert not load_config(builtin_config_path("oscillator-transfer")).lr_from_source


def test_profiles_merge_before_quick_and_unknown_ones_are_refused():
    data = tomllib.loads(PROFILED)
    cfg = parse_config(data, profile="release", quick=True)
    assert cfg.target.train.epochs == 150 and cfg.target.train.tolerance == 0.0  # quick over release
    assert cfg.follows["lr"] == "release: target at the source's lr"
    with pytest.raises(ConfigError, match=r"has no profile 'releese' \(it has \['paper', 'release'\]"):
        parse_config(data, profile="releese")
    bad = tomllib.loads(PROFILED.replace('train = { best_rule = "release_exact" }', 'train = { best_rule = "x" }'))
    with pytest.raises(ConfigError, match="train.best_rule = 'x'"):
        parse_config(bad, profile="release")
    with pytest.raises(ConfigError, match="profiles.release.profiles"):
        parse_config({**data, "profiles": {"release": {"profiles": {}}}})


@pytest.mark.long
def test_target_trains_at_the_sources_lr_with_the_release_profile(tmp_path):
    toml = tmp_path / "p.toml"
    toml.write_text(PROFILED)
    out = tmp_path / "run"
    assert main(["run", str(toml), "--quick", "--profile", "release", "--out", str(out), "--no-progress"]) == 0
    res = json.loads((out / "results.json").read_text())
    meta = json.loads((out / "meta.json").read_text())
    assert res["profile"] == meta["profile"] == "release"
    by_role = {r["role"]: r for r in res["runs"]}
    assert by_role["source"]["lr"] == by_role["target"]["lr"] == 8e-3  # not the target's own 5e-3
    assert by_role["target"]["epochs"] == 150 and by_role["target"]["stop_reason"] == "budget"
    assert "profile release" in (out / "tables.md").read_text()
    # the paper profile trains the target at its own lr (the run applies lr_from_source as above)
    paper = load_config(toml)
    assert paper.profile == "paper" and not paper.lr_from_source and paper.target.train.lr == 5e-3


@pytest.mark.long
def test_the_default_run_directory_names_a_chosen_profile(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    toml = tmp_path / "p.toml"
    toml.write_text(PROFILED.replace("[transfer]\nbaseline = false", "[transfer]\nbaseline = false\n\n[execution]\nseed_batch = 1"))
    assert main(["run", str(toml), "--quick", "--profile", "release", "--no-progress"]) == 0
    assert (tmp_path / "runs" / "profiled-release-quick" / "results.json").is_file()
    assert main(["run", str(toml), "--profile", "nope", "--quick"]) == 2


@pytest.mark.long
def test_a_profile_run_resumes_with_its_profile(tmp_path, monkeypatch):
    from atlasnn.experiments import _schemes as schemes
    from atlasnn.experiments import RunInterrupted, resume_experiment, run_experiment

    cfg = parse_config(tomllib.loads(PROFILED), profile="release", quick=True)
    out = tmp_path / "run"

    def hook(event, task, column, state):
        if event == "source_done":
            raise KeyboardInterrupt

    monkeypatch.setattr(schemes, "_hook", hook)
    with pytest.raises(RunInterrupted):
        run_experiment(cfg, out, progress=False, report=False, log=lambda *a: None, config_text=PROFILED, quick=True)
    monkeypatch.setattr(schemes, "_hook", lambda *a: None)
    res = resume_experiment(out, progress=False, report=False, log=lambda *a: None)
    assert res["profile"] == "release"
    assert {r["role"]: r["lr"] for r in res["runs"]}["target"] == 8e-3

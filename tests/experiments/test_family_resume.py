"""Resuming an interrupted bundle or inverse run: the run's own copy of its config is what
resumes; a run whose problem changed is refused rather than mixed with the seeds it kept."""

from __future__ import annotations

import json

import pytest

from atlasnn.cli import main

import atlasnn.experiments._family_run as family_run

_TEXT = ('name = "inv"\ndescription = "d"\nseeds = [0, 1, 2]\n[system]\nname = "henon_heiles"\n'
         '[observations]\nn = 20\nT = 8.0\nnames = ["x", "y"]\n[unknowns]\n'
         'lam = { guess = 0.9, low = 0.2, high = 1.5 }\n[fit]\nmethods = ["shooting"]\nstarts = 1\n')


@pytest.fixture
def stopped(tmp_path, monkeypatch, capsys):
    """An inverse run stopped (KeyboardInterrupt) after its first seed: (its config file, its directory)."""
    path = tmp_path / "inv.toml"
    path.write_text(_TEXT, encoding="utf-8")
    out = tmp_path / "run"
    real = family_run._fit_seed

    def stop_at_seed_1(cfg, truth, say, seed):
        if seed == 1:
            raise KeyboardInterrupt
        return real(cfg, truth, say, seed)

    monkeypatch.setattr(family_run, "_fit_seed", stop_at_seed_1)
    assert main(["family", str(path), "--out", str(out), "--no-progress"]) == 130
    monkeypatch.setattr(family_run, "_fit_seed", real)
    capsys.readouterr()
    assert (out / "partial" / "seed0.json").is_file() and not (out / "partial" / "seed1.json").exists()
    return path, out


def test_an_edited_original_config_is_ignored_on_resume(stopped, capsys):
    """Before, the resume read the original file: seeds 1-2 ran T = 5 while seed 0 ran T = 8, and
    one summary showed them together."""
    path, out = stopped
    path.write_text(_TEXT.replace("T = 8.0", "T = 5.0").replace("guess = 0.9", "guess = 0.5"), encoding="utf-8")
    assert main(["family", "--resume", str(out), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert f"{path} changed since the run started" in said
    seeds = json.loads((out / "results.json").read_text())["seeds"]
    assert sorted(seeds) == ["0", "1", "2"]
    assert {tuple(s["observations"]["t_span"]) for s in seeds.values()} == {tuple(seeds["0"]["observations"]["t_span"])}
    assert all(s["observations"]["t_span"][1] > 5.0 for s in seeds.values())


def test_a_resume_with_the_original_config_gone_uses_the_runs_copy(stopped):
    path, out = stopped
    path.unlink()
    assert main(["family", "--resume", str(out), "--no-progress"]) == 0
    assert (out / "results.json").is_file()


def test_an_edited_copy_is_refused_in_one_line_and_the_kept_seed_stays(stopped, capsys):
    path, out = stopped
    copy = out / "config.toml"
    copy.write_text(copy.read_text().replace("T = 8.0", "T = 5.0"), encoding="utf-8")
    assert main(["family", "--resume", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "resolves differently" in err and "observations.T: 8.0 → 5.0" in err
    assert "--overwrite" in err and (out / "partial" / "seed0.json").is_file() and not (out / "results.json").exists()


def test_a_kept_seed_cut_short_is_run_again(stopped, capsys):
    """Before, a truncated partial/seedN.json made --resume print a JSONDecodeError traceback."""
    path, out = stopped
    kept = out / "partial" / "seed0.json"
    kept.write_text(kept.read_text()[:40], encoding="utf-8")
    assert main(["family", "--resume", str(out), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "seed 0: its kept output" in said and "running the seed again" in said
    records = json.loads((out / "results.json").read_text())["records"]
    assert [r["seed"] for r in records] == [0, 1, 2]

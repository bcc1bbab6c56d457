"""Bad experiment inputs (a deep TOML, huge keys, seed counts, windows, sweeps, overflowing
parameters) are each one line, refused before
anything is trained or written. No training runs here."""

from __future__ import annotations

from pathlib import Path

import pytest

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.evaluation import TrainingRecord
from atlasnn.experiments import divergence_advice
from atlasnn.experiments.config import load_config, parse_config
from atlasnn.fileio import MAX_TOML_DEPTH, parse_toml

BASE = """
name = "osc"
kind = "short"
models = ["atlas_exp"]
[system]
name = "nonlinear_oscillator"
z0 = [1.3, 1.0]
[interval]
T = "4*pi"
[train]
epochs = 100
"""


def _err(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err  # one line, no traceback
    return err[0]


def _write(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_deeply_nested_toml_is_one_line(tmp_path, capsys):
    path = _write(tmp_path, "a = " + "[" * 600 + "]" * 600 + "\n")
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    assert f"nested more than {MAX_TOML_DEPTH} levels" in _err(capsys)
    assert not (tmp_path / "out").exists()


def test_nesting_inside_strings_and_comments_does_not_count():
    text = 'a = "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["  # [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[\nb = [[1], [2]]\n'
    assert parse_toml(text) == {"a": "[" * 37, "b": [[1], [2]]}
    with pytest.raises(ConfigError, match="not valid TOML"):
        parse_toml("a = [", "x.toml")


def test_a_huge_unknown_key_is_not_echoed_whole(tmp_path, capsys):
    path = _write(tmp_path, BASE + "x" * 1_000_000 + " = 1\n")
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    line = _err(capsys)
    assert "unknown key" in line and "1000000 characters" in line
    assert len(line) < 1000


@pytest.mark.parametrize("seeds", ["4294967297", "10001", "0"])
def test_seed_counts_are_checked_up_front(tmp_path, capsys, seeds):
    path = _write(tmp_path, BASE)
    assert main(["run", str(path), "--seeds", seeds, "--out", str(tmp_path / "out")]) == 2
    assert f"--seeds must be between 1 and 10000, got {seeds}" in _err(capsys)
    assert not (tmp_path / "out").exists()


def test_integrate_refuses_steps_that_cannot_fit(tmp_path, capsys):
    path = _write(tmp_path, BASE)
    assert main(["integrate", str(path), "--steps", "1000000000000"]) == 2
    line = _err(capsys)
    assert line.startswith("atlasnn: error: --steps = 1000000000000: the integration of 1000000000000 steps")
    assert "lower --steps" in line


@pytest.mark.parametrize("window, count", [("1e-12", "12566370601793"), ("1e-4", "125664")])
def test_fixed_windows_beyond_max_windows_are_refused(tmp_path, window, count):
    with pytest.raises(ConfigError, match=r"march.window = .*: cuts "
                       rf"\[0, 12.5664\] into {count} windows, more than march.max_windows = 10000"):
        load_config(_write(tmp_path, BASE + f"[march]\nwindow = {window}\n"))


def test_a_sweep_of_too_many_points_is_refused(tmp_path, capsys):
    path = _write(tmp_path, BASE)
    values = ",".join(str(100 + i) for i in range(300))
    lrs = ",".join(str(0.001 * (i + 1)) for i in range(300))
    assert main(["sweep", str(path), "--set", f"train.epochs={values}", "--set", f"train.lr={lrs}",
                 "--out", str(tmp_path / "sw")]) == 2
    assert "the sweep has 90000 points (300 x 300 values), more than 1000" in _err(capsys)
    assert not (tmp_path / "sw").exists()


@pytest.mark.parametrize("lam, why", [("1e308", "is not finite"), ("1e38", "too large for float32 training")])
def test_parameters_that_overflow_are_refused_naming_them(tmp_path, lam, why):
    text = BASE.replace('z0 = [1.3, 1.0]', f'z0 = [1.3, 1.0]\nparams = {{ lam = {lam} }}')
    with pytest.raises(ConfigError, match=why) as info:
        load_config(_write(tmp_path, text))
    assert "'lam'" in str(info.value)


def _diverged(role: str, lr: float = 0.008) -> TrainingRecord:
    return TrainingRecord(column="atlas_exp", label="ATLAS-NN (exp)", model="atlas_exp", seed=0, role=role,
                          interval=(0.0, 1.0), metrics={}, gamma={}, epochs=300, stop_reason="diverged",
                          returned_loss=1.0, checkpoint=None, lr=lr, epochs_budget=40_000, best_epoch=12,
                          diverged_epoch=40)


def test_divergence_advice_blames_the_state_scale_when_it_is_large(tmp_path):
    big = parse_config({**_as_data(BASE), "system": {"name": "harmonic_oscillator", "z0": [1e5, 0.0]}})
    line = divergence_advice(big, _diverged("short"))
    assert "rescale the variables" in line and "lower learning rate will not" in line
    small = parse_config(_as_data(BASE))
    line = divergence_advice(small, _diverged("short"))
    assert "Lower train.lr (now 0.008, e.g. 0.0008)" in line and "rescale" not in line


def test_march_divergence_advice_names_the_per_window_budget():
    cfg = parse_config({**_as_data(BASE), "march": {"window": 2.0, "train": {"epochs": 1500}}})
    line = divergence_advice(cfg, _diverged("march"))
    assert "march.train.lr" in line and "(now 1500 per window)" in line and "40000" not in line


def _as_data(text: str) -> dict:
    return parse_toml(text)


def test_quick_without_a_quick_table_uses_the_default_smoke_test(tmp_path):
    text = BASE.replace("epochs = 100", "epochs = 40000") + "[march]\nwindow = 2.0\nrtol = 1e-6\n[march.train]\nepochs = 5000\n"
    cfg = load_config(_write(tmp_path, text), quick=True)
    assert cfg.stage.train.epochs == 300 and cfg.evaluation.eval_points == 200
    assert cfg.march.scheme.train.epochs == 300 and cfg.march.scheme.rtol == 1e-3
    full = load_config(_write(tmp_path, text))
    assert full.stage.train.epochs == 40000 and full.march.scheme.train.epochs == 5000


def _point(pdir: Path, outcomes) -> None:
    import json

    runs = []
    for seed, (stop, status, value) in enumerate(outcomes):
        rec = TrainingRecord(column="atlas_exp", label="ATLAS-NN (exp)", model="atlas_exp", seed=seed, role="short",
                             interval=(0.0, 1.0), metrics={"l2_discrete": {"x": value}}, gamma={}, epochs=10,
                             stop_reason=stop, returned_loss=1.0, checkpoint=None)
        rec.quality = {"status": status, "reasons": [], "advice": ""}
        runs.append(rec.as_dict())
    pdir.mkdir(parents=True)
    (pdir / "results.json").write_text(json.dumps({"state_names": ["x", "p"], "columns": ["atlas_exp"], "seeds": [0, 1, 2],
                                                   "labels": {"atlas_exp": "ATLAS-NN (exp)"}, "runs": runs}))


def test_a_diverged_sweep_point_is_marked_in_the_summary(tmp_path):
    from atlasnn.experiments._sweep import write_summary

    _point(tmp_path / "a", [("budget", "ok", 0.1), ("diverged", "failed", float("nan")), ("budget", "suspect", 0.3)])
    _point(tmp_path / "b", [("budget", "ok", 0.1), ("budget", "ok", 0.2), ("budget", "ok", 0.3)])
    spec = {"metric": "l2_discrete", "experiment": "osc", "axes": [{"key": "train.lr", "values": [1, 2]}],
            "points": [{"name": "a", "dir": "a", "set": {"train.lr": 1}}, {"name": "b", "dir": "b", "set": {"train.lr": 2}}]}
    write_summary(tmp_path, spec)
    lines = (tmp_path / "summary.md").read_text().splitlines()
    row_a = next(line for line in lines if line.startswith("| [a]"))
    row_b = next(line for line in lines if line.startswith("| [b]"))
    assert "(1 diverged; 1 failed; 1 suspect)" in row_a and "diverged" not in row_b
    csv_text = (tmp_path / "summary.csv").read_text()
    assert "atlas_exp_diverged" in csv_text.splitlines()[0]


def test_an_interrupt_inside_a_finaliser_prints_nothing():
    import subprocess
    import sys

    program = ("import gc, sys\nfrom atlasnn.cli._main import quiet_interrupts\nsys.unraisablehook = quiet_interrupts\n"
               "class Stop:\n    def __del__(self):\n        raise KeyboardInterrupt\n"
               "class Other:\n    def __del__(self):\n        raise ValueError('kept')\n"
               "Stop(); Other(); gc.collect()\n")
    out = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert out.returncode == 0
    assert "KeyboardInterrupt" not in out.stderr and "ValueError: kept" in out.stderr


def test_reproduce_help_lists_every_builtin_experiment(capsys):
    from atlasnn.experiments.config import builtin_experiments

    with pytest.raises(SystemExit):
        main(["reproduce", "--help"])
    text = " ".join(capsys.readouterr().out.split()).replace("- ", "-")
    assert len(builtin_experiments()) >= 13
    for name in builtin_experiments():
        assert name in text, name

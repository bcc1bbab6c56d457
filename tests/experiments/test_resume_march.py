"""An interrupted time-marching run keeps its finished windows: resumed, it starts at the window
where it stopped and ends bit-identical to the run never stopped (fixed and adaptive windows, in
process; and a real process stopped by SIGINT with --jobs 2)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
import tomllib
from pathlib import Path

import jax
import numpy as np
import pytest

from atlasnn.checkpoint import load_march_progress, load_piecewise
from atlasnn.experiments import RunInterrupted, resume_experiment, run_experiment
from atlasnn.experiments import _schemes as schemes
from atlasnn.experiments.config import parse_config

from support import ATLASNN

MARCH = """\
name = "resume-march"
models = []
seeds = [0]

[system]
name = "harmonic_oscillator"
z0 = [1.0, 0.0]

[interval]
T = 4.0

[evaluation]
eval_points = 40
fine_factor = 2

[march]
models = ["atlas_exp"]
{windows}
[march.network]
width = 8

[march.train]
epochs = 120
n_points = 24
chunk = 120

[march.polish]
method = "lm"
steps = 3
n_points = 24
"""
FIXED = MARCH.replace("{windows}", "window = 1.0\n")
ADAPTIVE = MARCH.replace("{windows}", "window = \"auto\"\nrtol = 1e-3\nfirst_window = 1.0\n")


def _run(text, out, **kw):
    cfg = parse_config(tomllib.loads(text), source="cfg.toml")
    return run_experiment(cfg, out, progress=False, report=False, log=lambda *a: None, config_text=text, **kw)


def _assert_same_marches(a: Path, b: Path) -> None:
    ra, rb = (json.loads((d / "results.json").read_text()) for d in (a, b))
    marches = [r for r in ra["runs"] if r["role"] == "march"]
    assert marches and [r["checkpoint"] for r in ra["runs"]] == [r["checkpoint"] for r in rb["runs"]]
    for r in marches:
        sa, sb = load_piecewise(a / r["checkpoint"]), load_piecewise(b / r["checkpoint"])
        assert np.array_equal(sa.edges, sb.edges)
        for x, y in zip(jax.tree_util.tree_leaves(sa.models), jax.tree_util.tree_leaves(sb.models)):
            assert np.array_equal(np.asarray(x), np.asarray(y)), r["checkpoint"]
    with np.load(a / "arrays.npz") as za, np.load(b / "arrays.npz") as zb:
        assert sorted(za.files) == sorted(zb.files)
        for k in za.files:
            assert np.array_equal(za[k], zb[k]), k


@pytest.mark.long
@pytest.mark.parametrize("text", [FIXED, ADAPTIVE], ids=["fixed", "adaptive"])
def test_a_march_interrupted_in_window_k_resumes_at_window_k(tmp_path, monkeypatch, text):
    reference = tmp_path / "reference"
    _run(text, reference)
    out = tmp_path / "run"

    def hook(event, task, column, progress):
        if event == "window" and progress.windows == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(schemes, "_hook", hook)
    with pytest.raises(RunInterrupted):
        _run(text, out)
    saved = load_march_progress(out / "state" / "atlas_exp_march_seed0.npz")
    assert saved.windows == 2 and saved.edges[0] == 0.0

    started = []
    monkeypatch.setattr(schemes, "_hook", lambda event, task, column, p: started.append(p.windows))
    resume_experiment(out, progress=False, report=False, log=lambda *a: None)
    assert started[0] == 3  # the first window finished after the resume is window 3
    _assert_same_marches(out, reference)
    notes = json.loads((out / "results.json").read_text())["warnings"]
    assert any("resumed after window 2" in n for n in notes)
    assert not (out / "state").exists()


def _atlasnn(args, env, **kw):
    return subprocess.Popen([*ATLASNN, *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, **kw)


@pytest.mark.slow  # over a minute on the 2-core machine: run with -m slow (CI stays under 30 min)
def test_sigint_during_a_march_with_two_jobs_then_resume(tmp_path):
    text = FIXED.replace("seeds = [0]", "seeds = [0, 1]").replace("T = 4.0", "T = 8.0").replace(
        "epochs = 120", "epochs = 400")
    cfg = tmp_path / "m.toml"
    cfg.write_text(text)
    env = dict(os.environ, ATLASNN_CHECKPOINT_SECONDS="0", PYTHONUNBUFFERED="1")
    ref = _atlasnn(["run", str(cfg), "--jobs", "2", "--seed-batch", "1", "--out", str(tmp_path / "ref"),
                    "--no-progress"], env)
    assert ref.wait(timeout=600) == 0, ref.stdout.read()
    out = tmp_path / "run"
    proc = _atlasnn(["run", str(cfg), "--jobs", "2", "--seed-batch", "1", "--out", str(out), "--no-progress"],
                    env)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not list(out.glob("state/*.npz")):
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    text_out = proc.communicate(timeout=120)[0]
    assert proc.returncode == 130, text_out
    assert "resume with" in text_out
    kept = [load_march_progress(p).windows for p in (out / "state").glob("*.npz")]
    assert kept and min(kept) >= 1
    again = _atlasnn(["run", "--resume", str(out), "--no-progress", "--jobs", "2"], env)
    assert again.wait(timeout=600) == 0, again.stdout.read()
    _assert_same_marches(out, tmp_path / "ref")

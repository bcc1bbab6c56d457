"""The runner's parts: plans with seed batches, a batch interrupted and resumed, the directory lock."""

from __future__ import annotations

import json
import os
import tomllib

import pytest

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.experiments import _schemes as schemes
from atlasnn.experiments.config import builtin_config_path, load_config, parse_config
from atlasnn.experiments._plan import (AUTO_BATCH_MAX_ACCELERATOR, AUTO_BATCH_WORK, Task, batch_size,
                                       epoch_work, plan_tasks)
from atlasnn.experiments._plan import columns_of as schemes_columns
from atlasnn.experiments import RunInterrupted, resume_experiment, run_experiment
from atlasnn.experiments._store import RunLock

from support import SHORT, _quiet, assert_same_runs


def _cfg(text=SHORT):
    return parse_config(tomllib.loads(text), source="cfg.toml")


def _run(out, **kw):
    return run_experiment(_cfg(), out, progress=False, report=False, log=_quiet, config_text=SHORT, **kw)


# ------------------------------------------------------------------------------ plans
def test_plans_cut_the_seeds_of_each_column_into_batches():
    cfg = _cfg()
    assert plan_tasks(cfg, (0, 1, 2), seed_batch=1) == [Task("short", "atlas_exp", (s,)) for s in (0, 1, 2)]
    assert plan_tasks(cfg, (0, 1, 2), seed_batch=2) == [Task("short", "atlas_exp", (0, 1)),
                                                        Task("short", "atlas_exp", (2,))]
    assert plan_tasks(cfg, (3, 4), seed_batch=8) == [Task("short", "atlas_exp", (3, 4))]
    with pytest.raises(ConfigError, match="seed_batch"):
        plan_tasks(cfg, (0,), seed_batch=0)


def test_auto_batches_small_epochs_and_keeps_every_job_busy():
    small = load_config(builtin_config_path("oscillator-short"))
    large = load_config(builtin_config_path("henon-heiles-transfer"))
    assert epoch_work(small, "short") <= AUTO_BATCH_WORK < epoch_work(large, "transfer")
    assert batch_size(small, "short", 5, 1, "auto") == 5  # three columns, one job
    assert batch_size(large, "transfer", 5, 2, "auto") == 1  # two jobs keep both cores busy
    cores = os.cpu_count() or 1
    assert batch_size(large, "transfer", 5, 1, "auto") == (2 if cores > 1 else 1)  # pairs use the idle core
    # one column and two jobs: at least two tasks
    one_column = _cfg()
    assert [len(t.seeds) for t in plan_tasks(one_column, (0, 1, 2, 3, 4), jobs=2, seed_batch="auto")] == [3, 2]


def test_auto_on_a_gpu_puts_every_seed_of_a_column_in_one_program():
    large = load_config(builtin_config_path("henon-heiles-transfer"))
    assert batch_size(large, "transfer", 5, 2, "auto", backend="gpu") == 5
    assert batch_size(large, "transfer", 5000, 1, "auto", backend="gpu") == AUTO_BATCH_MAX_ACCELERATOR
    assert batch_size(large, "transfer", 5, 1, 2, backend="gpu") == 2  # a number is kept
    sizes = [len(t.seeds) for t in plan_tasks(large, tuple(range(1030)), seed_batch="auto", backend="gpu")]
    assert sizes == [1024, 6] * len(sizes[::2])
    # time-marching windows are not batched, on any backend
    march = load_config(builtin_config_path("henon-heiles-long"))
    marching = [r for r, _ in schemes_columns(march) if schemes.SCHEMES[r].batch_limit(march) is not None]
    assert marching and all(batch_size(march, r, 5, 1, "auto", backend="gpu") == 1 for r in marching)


# --------------------------------------------------------------- batch interrupted
@pytest.mark.long
def test_a_batch_interrupted_mid_way_resumes_bit_identically(tmp_path, monkeypatch):
    ref = tmp_path / "ref"
    _run(ref, seed_batch=2)
    out = tmp_path / "run"

    def hook(event, task, column, state):
        if event == "chunk" and task.seed == 1 and state.epoch == 200:
            raise KeyboardInterrupt

    monkeypatch.setattr(schemes, "_hook", hook)
    with pytest.raises(RunInterrupted) as info:
        _run(out, seed_batch=2)
    assert (info.value.finished, info.value.total) == (0, 2)
    meta = json.loads((out / "meta.json").read_text())
    assert meta["plan"] == [{"role": "short", "model": "atlas_exp", "seeds": [0, 1]}]
    states = sorted(p.name for p in (out / "state").glob("*.npz"))
    assert states == ["atlas_exp_seed0.npz", "atlas_exp_seed1.npz"]  # both seeds of the batch

    monkeypatch.setattr(schemes, "_hook", lambda *a: None)
    results = resume_experiment(out, jobs=2, progress=False, report=False, log=_quiet)  # plan kept
    assert [r["resumed_from_epoch"] for r in results["runs"]] == [200, 200]
    assert [r["batch_size"] for r in results["runs"]] == [2, 2]
    assert assert_same_runs(out, ref) == 2


# ------------------------------------------------------------------------------ lock
def test_a_second_writer_is_refused_while_the_first_holds_the_directory(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    with RunLock(out):
        with pytest.raises(ConfigError, match="in use by another atlasnn run"):
            _run(out, seed_batch=1)
        toml = tmp_path / "c.toml"
        toml.write_text(SHORT)
        assert main(["run", str(toml), "--out", str(out), "--no-progress"]) == 2
    assert not (out / "meta.json").exists()  # the refused run wrote nothing


@pytest.mark.long
def test_the_lock_is_released_after_a_run_and_after_a_failure(tmp_path, monkeypatch):
    out = tmp_path / "run"
    _run(out, seed_batch=1)
    RunLock(out).acquire().release()  # free again

    def boom(*a, **k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr("atlasnn.experiments._local.LocalExecutor.run", boom)
    with pytest.raises(RuntimeError):
        _run(tmp_path / "other", seed_batch=1)
    RunLock(tmp_path / "other").acquire().release()
    assert json.loads((tmp_path / "other" / "meta.json").read_text())["status"] == "failed"


# ---------------------------------------------------------------- verdicts and limits
DOUBLE_WELL = """\
name = "double-well"
models = ["atlas_exp"]
seeds = [0]

[system]
hamiltonian = "p**2/2 - q**2/2 + q**4/4"
coordinates = ["q"]
momenta = ["p"]
separable = true
z0 = [0.5, 0.0]

[interval]
T = "4*pi"

[train]
epochs = 1500
lr = 5e-3
betas = [0.999, 0.9999]
n_points = 200
sigma_per_T = 0.03

[evaluation]
eval_points = 400
fine_factor = 2
"""


@pytest.mark.long
def test_a_training_that_failed_is_flagged_in_results_tables_and_output(tmp_path, capsys):
    """The issue's double well: too short a budget leaves ẑ across the separatrix (energy drift
    about 100 %): exit status 0 (results were written), but the verdict says failed, with advice."""
    toml = tmp_path / "dw.toml"
    toml.write_text(DOUBLE_WELL)
    out = tmp_path / "run"
    assert main(["run", str(toml), "--out", str(out), "--no-progress"]) == 0
    res = json.loads((out / "results.json").read_text())
    (run,) = res["runs"]
    assert run["quality"]["status"] == "failed"
    assert any("energy drift" in reason for reason in run["quality"]["reasons"])
    assert run["metrics"]["energy_drift"] > 0.1  # the verdict is right: the reference agrees
    assert any("is failed" in w and "train.epochs" in w for w in res["warnings"])
    printed = capsys.readouterr().out
    assert "failed" in printed and "ATLAS-NN (exp) seed 0 is failed" in printed
    assert "⚠" in (out / "tables.md").read_text()


def test_a_run_that_cannot_fit_in_memory_is_refused_before_anything_is_written(tmp_path, capsys):
    from atlasnn.limits import available_memory, estimate_training_memory

    room = available_memory()
    if room is None or estimate_training_memory(1_000_000, 1000, 2, 2) <= room:
        pytest.skip("this machine's available memory is unknown or larger than the test's run needs")
    toml = tmp_path / "big.toml"
    # K = 10⁶ points of a 1000-wide network: tens of GiB (atlasnn.limits), more than any CI machine
    toml.write_text(SHORT.replace("n_points = 16", "n_points = 1000000").replace("width = 8", "width = 1000"))
    out = tmp_path / "run"
    assert main(["run", str(toml), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("atlasnn: error: ") and "\n" not in err and "GiB" in err
    assert not out.exists()


QUICK_FAILING = SHORT.replace("seeds = [0, 1]", "seeds = [0]").replace("epochs = 600", "epochs = 600\ntolerance = 1e-9") \
    + "\n[quick]\ntrain.epochs = 20\n"


@pytest.mark.long
@pytest.mark.parametrize("quick", [True, False])
def test_a_quick_runs_failed_trainings_are_not_told_to_raise_the_capped_budget(tmp_path, capsys, quick):
    cfg = tmp_path / "q.toml"
    cfg.write_text(QUICK_FAILING)
    args = ["run", str(cfg), "--out", str(tmp_path / "run"), "--no-progress"] + (["--quick"] if quick else [])
    assert main(args) == 0
    printed = capsys.readouterr().out
    res = json.loads((tmp_path / "run" / "results.json").read_text())
    advice = [r["quality"]["advice"] for r in res["runs"] if r["quality"]["status"] != "ok"]
    assert advice  # 20 (or 600) epochs against a tolerance of 1e-9: judged suspect or failed
    if quick:
        assert all(a.startswith("A quick run (--quick) caps every budget") for a in advice)
        assert "raise train.epochs" not in printed and "run without --quick" in printed
    else:
        assert all("raise train.epochs" in a for a in advice)

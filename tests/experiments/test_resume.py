"""Interrupting a run and resuming it gives exactly the uninterrupted run.

(a) in process: a hook raises KeyboardInterrupt after the first chunk of the second job; the
    finished job's records and the interrupted job's state are on disk; the resumed run's loss
    histories, models and predictions equal those of an uninterrupted run bit for bit;
(b) a real process: ``python -m atlasnn.cli._main run`` gets SIGINT while training, exits with status
    130 and the resume command; resumed in a second process it gets SIGTERM; resumed a last time
    it finishes, identical to the uninterrupted run;
(c) a transfer chain interrupted in its target stage (or between source and target) resumes from
    the saved source and target states, identical to the uninterrupted chain.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from atlasnn.checkpoint import load_state
from atlasnn.cli import main
from atlasnn.experiments import _runner as runner
from atlasnn.experiments import _schemes as schemes
from atlasnn.experiments import RunInterrupted, resume_experiment, run_experiment

from support import HISTORY, SHORT, TRANSFER, _cfg, _quiet, assert_same_runs  # noqa: F401


def _run(text, out, **kw):
    # seed_batch=1: one seed per program, so that one seed can finish while another is
    # interrupted (batched runs: test_resume_batch.py)
    kw.setdefault("seed_batch", 1)
    return run_experiment(_cfg(text), out, progress=False, report=False, log=_quiet, config_text=text, **kw)


@pytest.fixture(scope="module")
def reference_short(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "short"
    _run(SHORT, out)
    return out


@pytest.fixture(scope="module")
def reference_transfer(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "transfer"
    _run(TRANSFER, out)
    return out


# ------------------------------------------------------------------------------ (a)
def test_interrupted_in_process_then_resumed_is_bit_identical(tmp_path, monkeypatch, reference_short):
    out = tmp_path / "run"

    def hook(event, task, column, state):
        if event == "chunk" and task.seed == 1 and state.epoch == 100:
            raise KeyboardInterrupt

    monkeypatch.setattr(schemes, "_hook", hook)
    with pytest.raises(RunInterrupted) as info:
        _run(SHORT, out)
    assert (info.value.finished, info.value.total) == (1, 2)
    assert isinstance(info.value, KeyboardInterrupt)
    meta = json.loads((out / "meta.json").read_text())
    assert meta["status"] == "interrupted" and meta["finished_tasks"] == 1
    # the finished job is kept, the interrupted one has its state, nothing else was written
    assert (out / "tasks" / "short_atlas_exp_seed0.json").is_file()
    assert (out / "tasks" / "short_atlas_exp_seed0.npz").is_file()
    assert (out / "models" / "atlas_exp_seed0.npz").is_file()
    assert not (out / "models" / "atlas_exp_seed1.npz").exists()
    assert not (out / "results.json").exists()
    state = load_state(out / "state" / "atlas_exp_seed1.npz")
    assert state.epoch == 100 and len(state.history) == 100

    monkeypatch.setattr(schemes, "_hook", lambda *a: None)
    results = resume_experiment(out, progress=False, report=False, log=_quiet)
    assert [r["resumed_from_epoch"] for r in results["runs"]] == [None, 100]
    assert assert_same_runs(out, reference_short) == 2
    assert json.loads((out / "meta.json").read_text())["status"] == "complete"
    assert not (out / "state").exists()
    # a complete run is not resumed again
    with pytest.raises(Exception, match="already complete"):
        resume_experiment(out, progress=False, report=False, log=_quiet)


def test_a_second_interrupt_during_the_resume_is_fine_too(tmp_path, monkeypatch, reference_short):
    out = tmp_path / "run"
    stops = iter([(0, 300), (1, 200)])
    stop = next(stops)

    def hook(event, task, column, state):
        nonlocal stop
        if event == "chunk" and (task.seed, state.epoch) == stop:
            stop = next(stops, None)
            raise KeyboardInterrupt

    monkeypatch.setattr(schemes, "_hook", hook)
    with pytest.raises(RunInterrupted):
        _run(SHORT, out)
    with pytest.raises(RunInterrupted) as info:
        resume_experiment(out, progress=False, report=False, log=_quiet)
    assert info.value.finished == 1
    monkeypatch.setattr(schemes, "_hook", lambda *a: None)
    resume_experiment(out, progress=False, report=False, log=_quiet)
    assert assert_same_runs(out, reference_short) == 2


# ------------------------------------------------------------------------------ (b)
LONG = SHORT.replace('seeds = [0, 1]', 'seeds = [0, 1, 2]').replace("epochs = 600", "epochs = 20000") \
    .replace("chunk = 100", "chunk = 500").replace('name = "resume-short"', 'name = "resume-long"')


def _start(args, env):
    # A shell may start background jobs with SIGINT ignored, and an ignored signal stays ignored
    # in a child (Python then installs no KeyboardInterrupt handler either): give the child the
    # default disposition (without a preexec_fn, which would fork this multithreaded process).
    ignored = signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    if ignored:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "atlasnn.cli._main", *args], env=env, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True,
        )
    finally:
        if ignored:
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def _wait_for(proc, condition, timeout=240.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.02)
    return False


def _newest_state(out: Path) -> float:
    files = list((out / "state").glob("*.npz")) if (out / "state").is_dir() else []
    return max((f.stat().st_mtime for f in files), default=0.0)


def _states(out: Path) -> dict[str, int]:
    return {f.name: load_state(f).epoch for f in sorted((out / "state").glob("*.npz"))}


MESSAGE = re.compile(r"^atlasnn: interrupted: (\d) of 3 trainings finished; resume with: (.*)$", re.M)


@pytest.mark.slow  # 40 s, two real processes; the in-process interrupts above check the resume bit for bit (CI stays under 30 min)
def test_sigint_and_sigterm_in_a_real_process_then_resume(tmp_path):
    toml = tmp_path / "long.toml"
    toml.write_text(LONG)
    out = tmp_path / "run"
    env = dict(os.environ, ATLASNN_CHECKPOINT_SECONDS="0")  # save the state after every chunk
    env["PYTHONPATH"] = os.pathsep.join([str(Path(runner.__file__).parents[2]), env.get("PYTHONPATH", "")])

    # 1. SIGINT while the second job trains (its state file is newer than the first job's record)
    p = _start(["run", str(toml), "--out", str(out), "--no-progress", "--seed-batch", "1"], env)
    first = out / "tasks" / "short_atlas_exp_seed0.json"
    assert _wait_for(p, lambda: first.exists() and _newest_state(out) > first.stat().st_mtime), p.communicate()
    os.kill(p.pid, signal.SIGINT)
    stdout, stderr = p.communicate(timeout=120)
    print("first process:", stdout, stderr, _states(out))
    assert p.returncode == 130, (stdout, stderr)
    assert "Traceback" not in stderr
    m = MESSAGE.search(stderr)
    assert m, stderr
    assert int(m.group(1)) in (1, 2)
    assert m.group(2) == f"atlasnn run {toml} --resume {out} --no-progress"
    assert json.loads((out / "meta.json").read_text())["status"] == "interrupted"
    assert first.exists() and any((out / "state").glob("*.npz"))

    # 2. resumed in another process, stopped by SIGTERM once it has saved a state of its own
    launched = time.time()
    p = _start(["run", str(toml), "--resume", str(out), "--no-progress"], env)
    assert _wait_for(p, lambda: _newest_state(out) > launched), p.communicate()
    os.kill(p.pid, signal.SIGTERM)
    stdout, stderr = p.communicate(timeout=120)
    print("second process:", stdout, stderr, _states(out))
    assert p.returncode == 130, (stdout, stderr)
    assert "Traceback" not in stderr and "SIGTERM received" in stderr
    assert MESSAGE.search(stderr), stderr
    assert "resuming" in stdout

    # 3. resumed in this process: done, and equal to a run that was never interrupted
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    ref = tmp_path / "ref"
    run_experiment(_cfg(LONG), ref, progress=False, report=False, log=_quiet, seed_batch=1)
    assert assert_same_runs(out, ref) == 3
    res = json.loads((out / "results.json").read_text())
    assert any(r["resumed_from_epoch"] for r in res["runs"])  # at least one job continued mid-way
    meta = json.loads((out / "meta.json").read_text())
    assert meta["status"] == "complete" and len(meta["resumed"]) == 2


# ------------------------------------------------------------------------------ (c)
@pytest.mark.parametrize("where", ["target", "between"])
def test_transfer_interrupted_then_resumed_is_bit_identical(where, tmp_path, monkeypatch, reference_transfer):
    out = tmp_path / "run"

    def hook(event, task, column, state):
        if where == "target" and event == "chunk" and column == "atlas_exp_transfer" and state.epoch == 200:
            raise KeyboardInterrupt
        if where == "between" and event == "source_done":
            raise KeyboardInterrupt

    monkeypatch.setattr(schemes, "_hook", hook)
    with pytest.raises(RunInterrupted) as info:
        _run(TRANSFER, out)
    assert (info.value.finished, info.value.total) == (0, 1)
    # the finished source: its model, final training state (Adam moments) and record are kept
    assert (out / "models" / "atlas_exp_source_seed0.npz").is_file()
    src_state = load_state(out / "state" / "atlas_exp_source_seed0.npz")
    assert src_state.epoch == 400
    assert json.loads((out / "state" / "atlas_exp_source_seed0.json").read_text())["record"]["role"] == "source"
    target_state = out / "state" / "atlas_exp_transfer_seed0.npz"
    if where == "target":
        assert load_state(target_state).epoch == 200
    else:
        assert not target_state.exists()

    monkeypatch.setattr(schemes, "_hook", lambda *a: None)
    results = resume_experiment(out, progress=False, report=False, log=_quiet)
    by_role = {r["role"]: r for r in results["runs"]}
    assert by_role["target"]["resumed_from_epoch"] == (200 if where == "target" else None)
    assert assert_same_runs(out, reference_transfer) == 2
    assert not (out / "state").exists()

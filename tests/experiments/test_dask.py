"""The Dask executor against a real ``distributed.LocalCluster`` (a scheduler and two worker
processes, one thread each, started here):

(a) a run on the cluster writes the same records, models and trajectories as a local run of the
    same plan, bit for bit;
(b) SIGINT in the coordinating process stops the tasks on the workers (they save their states),
    raises RunInterrupted, and the run resumed on the cluster equals an uninterrupted run;
(c) a worker killed (SIGKILL) while it trains: Dask runs its task again on a worker, which
    continues from the state the dead one saved; the result equals an uninterrupted run (last:
    the nanny restarts the killed worker, which then starts cold);
(d) a scheduler that cannot be reached: one line naming the address, exit status 2, nothing
    written; the executor options are checked before anything runs.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import threading
import time

import pytest

distributed = pytest.importorskip("distributed")

from atlasnn.cli import main  # noqa: E402
from atlasnn.errors import ConfigError  # noqa: E402
from atlasnn.experiments import scheduler_address  # noqa: E402
from atlasnn.experiments import RunInterrupted, resume_experiment, run_experiment  # noqa: E402

from support import SHORT, _cfg, _quiet, assert_same_runs  # noqa: E402

# 6000 epochs in chunks of 100: long enough to be caught mid-way (a few seconds per seed)
LONGER = SHORT.replace("epochs = 600", "epochs = 6000").replace('name = "resume-short"', 'name = "dask-long"')


def _run(text, out, **kw):
    kw.setdefault("seed_batch", 1)
    return run_experiment(_cfg(text), out, progress=False, report=False, log=_quiet, config_text=text, **kw)


def _warm() -> bool:
    import atlasnn.experiments._task  # noqa: F401  (JAX and the trainer, imported once)

    return True


@pytest.fixture(scope="module")
def cluster():
    """(scheduler address, a client of it); the workers save a state after every chunk."""
    mp = pytest.MonkeyPatch()
    mp.setenv("ATLASNN_CHECKPOINT_SECONDS", "0")  # inherited by the worker processes
    lc = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR)
    client = distributed.Client(lc, set_as_default=False)
    client.run(_warm)
    yield lc.scheduler_address, client
    client.close()
    lc.close()
    mp.undo()


@pytest.fixture(scope="module")
def reference(tmp_path_factory, cluster):
    """Uninterrupted local runs (this process) of SHORT and LONGER, one seed per program."""
    base = tmp_path_factory.mktemp("dask-ref")
    _run(SHORT, base / "short")
    _run(LONGER, base / "longer")
    return base


def _watch(condition, action, timeout=120.0) -> threading.Thread:
    """In a thread: once ``condition()`` holds, ``action()`` (polled every 20 ms)."""

    def loop():
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if condition():
                action()
                return
            time.sleep(0.02)

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    return thread


# ------------------------------------------------------------------------------ (a)
@pytest.mark.long
def test_a_run_on_the_cluster_equals_a_local_run(tmp_path, cluster, reference):
    address, client = cluster
    out = tmp_path / "run"
    results = _run(SHORT, out, scheduler=address)
    assert assert_same_runs(out, reference / "short") == 2
    meta = json.loads((out / "meta.json").read_text())
    assert meta["scheduler"] == address and meta["status"] == "complete"
    assert [r["resumed_from_epoch"] for r in results["runs"]] == [None, None]
    assert not (out / "state").exists() and not list(out.glob(".dask-probe-*"))


# ------------------------------------------------------------------------------ (b)
@pytest.fixture
def python_sigint():
    """Python's usual Ctrl-C handler for one test: a shell starts background jobs (e.g. a test
    suite started with `&`) with SIGINT ignored, and a run leaves an ignored signal ignored."""
    old = signal.getsignal(signal.SIGINT)
    if old is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


@pytest.mark.long
def test_sigint_stops_the_workers_and_the_run_resumes_on_the_cluster(tmp_path, capsys, cluster, reference,
                                                                       python_sigint):
    address, client = cluster
    out = tmp_path / "run"
    states = out / "state"
    watcher = _watch(lambda: states.is_dir() and any(states.glob("*.npz")),
                     lambda: os.kill(os.getpid(), signal.SIGINT))
    with pytest.raises(RunInterrupted) as info:
        _run(LONGER, out, scheduler=address)
    watcher.join()
    assert info.value.total == 2 and info.value.finished < 2
    assert json.loads((out / "meta.json").read_text())["status"] == "interrupted"
    assert "stopping" in capsys.readouterr().err
    # the tasks on the workers stopped: nothing trains into the directory any more (a state is
    # saved after every chunk of 100 epochs, a fraction of a second)
    assert not any(client.processing().values())
    saved = {f: f.stat().st_mtime_ns for f in states.glob("*.npz")}
    assert saved
    time.sleep(1.5)
    assert {f: f.stat().st_mtime_ns for f in states.glob("*.npz")} == saved

    results = resume_experiment(out, progress=False, report=False, log=_quiet, scheduler=address)
    assert any(r["resumed_from_epoch"] for r in results["runs"])
    assert assert_same_runs(out, reference / "longer") == 2
    meta = json.loads((out / "meta.json").read_text())
    assert meta["status"] == "complete" and meta["resumed"][0]["scheduler"] == address


# ------------------------------------------------------------------------------ (c)
@pytest.mark.long
def test_a_worker_killed_mid_run_and_dask_finishes_the_run(tmp_path, cluster, reference):
    address, client = cluster
    out = tmp_path / "run"
    state = out / "state" / "atlas_exp_seed1.npz"
    killed = {}

    def kill():  # the worker whose task trains seed 1, once that task saved a state
        pids = client.run(os.getpid)
        for worker, keys in client.processing().items():
            if any("-seeds1-" in str(k) for k in keys):
                killed["pid"] = pids[worker]
                os.kill(pids[worker], signal.SIGKILL)

    watcher = _watch(state.exists, kill)
    results = _run(LONGER, out, scheduler=address)
    watcher.join()
    assert "pid" in killed, "the worker training seed 1 was not found while it trained"
    with pytest.raises(ProcessLookupError):
        os.kill(killed["pid"], 0)
    # seed 1 ran again and continued from the dead worker's last state, not from epoch 0
    seed1 = next(r for r in results["runs"] if r["seed"] == 1)
    assert seed1["resumed_from_epoch"] and 0 < seed1["resumed_from_epoch"] < 6000
    assert assert_same_runs(out, reference / "longer") == 2


# ------------------------------------------------------------------------------ (d)
@pytest.mark.parametrize("address", ["tcp://127.0.0.1:1", "nonsense://nowhere", "127.0.0.1"])
def test_an_unreachable_scheduler_is_one_line_and_nothing_is_written(address, tmp_path, capsys, monkeypatch):
    import dask

    cfg = tmp_path / "cfg.toml"
    cfg.write_text(SHORT)
    out = tmp_path / "run"
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        code = main(["run", str(cfg), "--out", str(out), "--scheduler", address, "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("atlasnn: error: cannot connect to the Dask scheduler at "), err
    assert address in lines[0]
    assert not out.exists()


def test_the_environment_names_the_scheduler_and_the_option_wins(tmp_path, capsys, monkeypatch):
    import dask

    monkeypatch.setenv("ATLASNN_SCHEDULER", "tcp://127.0.0.1:1")
    assert scheduler_address() == "tcp://127.0.0.1:1"
    assert scheduler_address("tcp://elsewhere:8786") == "tcp://elsewhere:8786"
    assert scheduler_address("") is None  # an empty option: local processes
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(SHORT)
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["run", str(cfg), "--out", str(tmp_path / "run"), "--no-progress"]) == 2
    assert "tcp://127.0.0.1:1" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="jobs = 2 and the Dask scheduler tcp://127.0.0.1:1 cannot be combined"):
        _run(SHORT, tmp_path / "run", jobs=2)
    assert not (tmp_path / "run").exists()


def test_the_config_names_the_scheduler_below_the_environment(tmp_path, capsys, monkeypatch):
    import dask

    monkeypatch.delenv("ATLASNN_SCHEDULER", raising=False)
    assert scheduler_address(None, "tcp://from-config:8786") == "tcp://from-config:8786"
    monkeypatch.setenv("ATLASNN_SCHEDULER", "tcp://from-env:8786")
    assert scheduler_address(None, "tcp://from-config:8786") == "tcp://from-env:8786"
    assert scheduler_address("", "tcp://from-config:8786") is None  # the option: local processes
    monkeypatch.delenv("ATLASNN_SCHEDULER")
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(SHORT + '\n[execution]\nscheduler = "tcp://127.0.0.1:1"\n')
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["run", str(cfg), "--out", str(tmp_path / "run"), "--no-progress"]) == 2
    assert "tcp://127.0.0.1:1" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
